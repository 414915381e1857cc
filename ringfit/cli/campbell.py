"""``ringfit campbell`` — Campbell diagram of the rolling, loaded tyre; measured mode tables matched to its branches.

    ringfit campbell --tyre FITTED.toml --load 4000 --speeds 0:80:5 [--frame sensor|fixed] [--drum D]
                     --out NAME.campbell.csv [--plot C.png] [--modes T1.modes.csv ...]

Writes ``NAME.campbell.csv`` (one row per branch and speed) and, with
``--modes``, ``NAME.matched.csv`` beside it (one row per measured row), both
described in docs/formats.md ("Campbell diagram").
"""

from __future__ import annotations

from pathlib import Path

from ringfit.cli._args import drum_diameter, force_flag, integer, number


def register(sub) -> None:
    p = sub.add_parser(
        "campbell", help="Campbell diagram of the rolling, loaded tyre; match measured mode tables to its branches",
        description="Modes of the tyre rolling on a flat road or drum at each speed (ring with the tread springs "
                    "of the steady contact patch, docs/physics.md §3.7), tracked into branches, in the fixed frame "
                    "and as the co-rotating sensor sees them (lines ω + kΩ). With --modes each measured row is "
                    "matched to a branch (n, direction, frame) with its error and σ; rows no branch explains, and "
                    "rows whose speed trend or n label contradicts every branch, are named with one sentence each.")
    p.add_argument("--tyre", required=True, type=Path, help="tyre TOML (docs/formats.md §1) with fitted [ring] values")
    p.add_argument("--load", type=number("a load in N in (0, 1e6]", lo=0.0, hi=1e6, lo_open=True), default=4000.0,
                   help="vertical load Fz [N] (default 4000; tables with load_n in their sidecar use their own)")
    p.add_argument("--speeds", default="0:80:5",
                   help="speeds [km/h]: START:STOP:STEP (STOP included) or a comma list (default 0:80:5)")
    p.add_argument("--frame", choices=("sensor", "fixed"), default="fixed",
                   help="frame of the freq_hz column and of the plot: the co-rotating sensor or a fixed observer "
                        "(default fixed); measured tables use the frame in their sidecar")
    p.add_argument("--drum", type=drum_diameter(), default=None,
                   metavar="DIAMETER_M",
                   help="drum diameter [m]; omit for a flat road")
    p.add_argument("--out", required=True, type=Path, help="output NAME.campbell.csv")
    p.add_argument("--plot", type=Path, default=None, help="optional PNG: branches vs speed, measured rows overlaid")
    p.add_argument("--modes", nargs="+", type=Path, default=(), metavar="T.modes.csv",
                   help="measured mode tables (docs/formats.md §2, with their .json sidecars) to match; writes "
                        "NAME.matched.csv beside --out")
    p.add_argument("--n-max", type=integer("a whole number >= 1", lo=1), default=15, help="highest dominant order n of the branches (default 15)")
    p.add_argument("--tolerance", type=number("a relative σ in (0, 1]", lo=0.0, hi=1.0, lo_open=True), default=None,
                   help="relative σ of the model used in the matching (default: from the data, the robust scale "
                        "of the matched rows' residuals beyond their freq_std_hz; 2 %% where fewer than 4 rows match)")
    force_flag(p)
    p.set_defaults(run=run_campbell)


#: Speeds ``--speeds`` accepts [km/h] (as ``ringfit roll --speed``), and how many (each is an eigen-solve).
SPEED_RANGE_KMH = (0.0, 1000.0)
MAX_SPEEDS = 400


def parse_speeds(text: str):
    """``"0:80:5"`` (stop included) or ``"20,40,60"`` → sorted speeds [km/h]; :class:`InputError` otherwise.

    Speeds lie in :data:`SPEED_RANGE_KMH` and there are at most :data:`MAX_SPEEDS` of them (the count of a
    range is checked before it is made).
    """
    import math

    import numpy as np

    from ringfit.errors import InputError

    lo, hi = SPEED_RANGE_KMH
    try:
        if ":" in text:
            start, stop, step = (float(x) for x in text.split(":"))
            if not (math.isfinite(start) and math.isfinite(stop) and math.isfinite(step)) or not step > 0 \
                    or stop < start:
                raise ValueError
            values = (start, stop)
            count = math.floor((stop - start) / step + 0.5) + 1
        else:
            values = [float(x) for x in text.split(",") if x.strip()]
            count = len(values)
    except ValueError:
        raise InputError(f"--speeds {text!r}: expected START:STOP:STEP with STEP > 0 or a comma list of km/h") from None
    if count == 0 or not all(math.isfinite(v) and lo <= v <= hi for v in values):
        raise InputError(f"--speeds {text!r}: expected speeds in [{lo:g}, {hi:g}] km/h")
    if count > MAX_SPEEDS:
        raise InputError(f"--speeds {text!r}: {count} speeds; expected at most {MAX_SPEEDS} (one eigen-solve each): "
                         "a larger STEP")
    if ":" in text:
        speeds = np.arange(start, stop + 0.5 * step, step)
    else:
        speeds = np.array(values)
    return np.unique(speeds)


def matched_path(out: Path) -> Path:
    """``NAME.campbell.csv`` → ``NAME.matched.csv`` (else ``<stem>.matched.csv``)."""
    name = out.name
    stem = name[: -len(".campbell.csv")] if name.endswith(".campbell.csv") else out.stem
    return out.with_name(stem + ".matched.csv")


def run_campbell(args) -> int:
    from ringfit.cli import CommandFailed
    from ringfit.io.files import atomic_write_text, check_output_paths, csv_text
    from ringfit.io.modes import sidecar_path

    speeds = parse_speeds(args.speeds)
    inputs = [args.tyre, *args.modes, *(sidecar_path(m) for m in args.modes)]
    outputs = [args.out] + ([matched_path(args.out)] if args.modes else []) + ([args.plot] if args.plot else [])
    check_output_paths(outputs, overwrite=args.force, inputs=inputs)

    from ringfit.gap.campbell import MATCH_COLUMNS, match_rows_table, match_tables
    from ringfit.io.modes import check_test_condition, read_mode_table
    from ringfit.io.conditions import check_stated
    from ringfit.io.tyre import read_tyre, require_ring
    from ringfit.physics.campbell import CAMPBELL_COLUMNS, campbell_diagram

    tyre = require_ring(read_tyre(args.tyre), "the Campbell diagram's branches need the tyre's ring")
    tables = [read_mode_table(m) for m in args.modes]
    for m, t in zip(args.modes, tables):  # before the diagram's work: a sidecar whose condition cannot be modelled
        check_test_condition(t.condition, source=sidecar_path(m))
        _, notes = check_stated(t, tyre.geometry, source=sidecar_path(m), other_pressure="warn",
                                used_as="its rows are matched to branches as if measured")
        for note in notes:
            import warnings

            warnings.warn(note, stacklevel=2)
    ring, geometry = tyre.ring, tyre.geometry
    if tyre.covariance is not None:
        print("note: the branches are the nominal ring's; the tyre file's [ring.covariance] is not propagated into "
              "them (ringfit roll and estimate propagate it)")
    diagram = campbell_diagram(ring, geometry, args.load, speeds, drum_diameter_m=args.drum, n_max=args.n_max)
    if not diagram.ok.all():
        bad = ", ".join(f"{v:g}" for v in diagram.speed_kmh[~diagram.ok])
        raise CommandFailed(f"the contact solve or the eigenproblem failed at {bad} km/h (patch outside its window, "
                            "or beyond the critical speed); nothing written")
    match = None
    if tables:
        match = match_tables(tables, ring, geometry, load_n=args.load, drum_diameter_m=args.drum,
                             model_tolerance=args.tolerance, n_max=args.n_max, speeds_kmh=speeds)
    rows = diagram.rows(args.frame)
    atomic_write_text(args.out, csv_text(CAMPBELL_COLUMNS, [[r[c] for c in CAMPBELL_COLUMNS] for r in rows]))
    road = "flat road" if args.drum is None else f"drum {args.drum:g} m"
    print(f"{args.out}: {diagram.branches} branches (n ≤ {args.n_max}) × {len(speeds)} speeds "
          f"{speeds[0]:g}–{speeds[-1]:g} km/h, {args.load:g} N on a {road}; R_e = {diagram.rolling_radius_m:.4f} m, "
          f"patch {diagram.leading_deg[0]:+.2f}° … {diagram.trailing_deg[0]:+.2f}° at {speeds[0]:g} km/h")
    if match is not None:
        path = matched_path(args.out)
        atomic_write_text(path, csv_text(MATCH_COLUMNS, match_rows_table(match)))
        print(f"{path}: {match.summary()}; {match.tolerance_note}")
        for r in match.rows:
            name = Path(r["source"]).name
            print(f"  {name} row {r['row']}: {r['freq_hz']:.2f} Hz at {r['speed_kmh']:g} km/h [{r['status']}] "
                  f"{r['note']}")
    if args.plot:
        from ringfit.report.campbell_plots import plot_campbell

        plot_campbell(diagram, args.plot, frame=args.frame, match=match, overwrite=args.force)
        print(f"{args.plot}: Campbell plot")
    return 0
