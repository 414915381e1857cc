"""``ringfit estimate`` — wheel load and contact patch from the one accelerometer (docs/formats.md §7).

    ringfit estimate INPUT --tyre FITTED.toml --out NAME.estimate.json [--per-revolution REVS.csv] [--plot P.png]
                     [--state [--fix NAME=VALUE ...]]

INPUT is a rolling profile ``*.profile.csv`` (its sidecar may omit ``load_n``) or a continuous
recording ``*.records.npz`` (docs/records-continuous.md) or rig file (.tdms, .mat, .csv; docs/formats.md §17).
"""

from __future__ import annotations

from pathlib import Path

from ringfit.cli._args import force_flag, integer, number


def register(sub) -> None:
    p = sub.add_parser(
        "estimate", help="estimate the wheel load and contact patch from a profile or a recording",
        description="Invert the fitted rolling model (tyre file fixed) for the vertical load that the radial "
                    "reading shows: a gradient fit of its revolution harmonics 2…k_max with a free gain, the "
                    "high-pass corner, sensor tilt and angle offset as nuisances; 95 % Laplace interval; the "
                    "contact patch of the model at that load; the classic edge-peak method beside it. For a "
                    "continuous recording the averaged profile and, with --per-revolution or --plot, every "
                    "revolution (the angle from the encoder, or from the patch passages when there is none). Writes NAME.estimate.json (docs/formats.md §7); exit 1 if the fit does not "
                    "converge (nothing written).")
    p.add_argument("input", type=Path, help="*.profile.csv (+ .json sidecar, load_n not needed) or a continuous "
                                            "*.records.npz or .tdms/.mat/.csv recording (docs/formats.md §17)")
    p.add_argument("--tyre", required=True, type=Path, help="fitted tyre TOML (ring parameters and k_tread fixed)")
    p.add_argument("--channels", "--channel-map", dest="channel_map", type=Path, default=None, metavar="MAP.toml",
                   help="a recording in a TDMS/.mat/CSV rig file: channel map naming its acceleration and encoder "
                        "channels with their axes and units (docs/formats.md §17.4)")
    p.add_argument("--out", required=True, type=Path, help="output NAME.estimate.json")
    p.add_argument("--per-revolution", type=Path, default=None, metavar="REVS.csv",
                   help="continuous recordings: write one row per revolution (load, interval, patch length, …)")
    p.add_argument("--plot", type=Path, default=None, metavar="P.png",
                   help="PNG: the fit to the profile, and for a recording the load against time with its band")
    p.add_argument("--k-tread-sd", type=number("a σ of ln k_tread in [0, 5]", lo=0.0, hi=5.0), default=None, metavar="S",
                   help="σ of ln k_tread: free the tread stiffness with this log-normal prior around the tyre "
                        "file's value and propagate it into the interval (default: the tyre file's "
                        "[ring.covariance] when it has one, every ring parameter it holds propagated, else fixed; "
                        "0.3 when the tyre file has no k_tread)")
    p.add_argument("--state", action="store_true",
                   help="also estimate the tyre's state from the radial and tangential channels: load, pressure, "
                        "slip and longitudinal force, tread depth, speed and rolling radius, with 95 %% intervals, "
                        "their correlation and what the data cannot tell apart (docs/physics.md §13, docs/formats.md "
                        "§7.1); drive/brake needs the tyre file's kx_n_per_m2, tread depth its tread_depth_mm")
    p.add_argument("--fix", action="append", default=[], metavar="NAME=VALUE",
                   help="with --state: hold one quantity at a value — load_n [N], pressure_bar [bar] (a TPMS), "
                        "slip, tread_depth_mm [mm] — or at the input's stated condition (NAME=stated); repeatable")
    p.add_argument("--harmonics", type=integer("a number of harmonics >= 8", lo=8), default=None, metavar="K",
                   help="highest revolution harmonic fitted (default 40; with --state 80, or 40 where the model's "
                        "form error shows above 40, docs/physics.md §13.4)")
    p.add_argument("--grid", type=integer("an even grid size >= 128", lo=128, hi=1 << 16), default=512, help="model grid M of the contact solve (default 512)")
    force_flag(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar, no warnings on stderr")
    p.set_defaults(run=run_estimate)


def run_estimate(args) -> int:
    import sys

    from ringfit.cli import CommandFailed
    from ringfit.errors import InputError
    from ringfit.io.files import check_output_paths
    from ringfit.io.profiles import sidecar_path

    kind = _input_kind(args.input)
    if args.harmonics is None:
        from ringfit.fit.estimate.problem import EstimateSettings as _Settings
        from ringfit.fit.estimate.state import STATE_K_MAX

        args.harmonics = STATE_K_MAX if args.state else _Settings.k_max
    if args.grid % 2:
        raise InputError(f"--grid {args.grid}: expected an even number >= 128")
    if not 8 <= args.harmonics < args.grid // 2 - 1:
        raise InputError(f"--harmonics {args.harmonics}: expected 8 … {args.grid // 2 - 2}")
    if args.per_revolution is not None and kind != "recording":
        raise InputError("--per-revolution needs a continuous recording (*.records.npz, .tdms, .mat, .csv), not a profile",
                         source=args.input)
    if args.channel_map is not None and kind != "recording":
        raise InputError("--channels applies to a recording in a TDMS, .mat or CSV file, not a profile",
                         source=args.input)
    if args.fix and not args.state:
        raise InputError("--fix holds a quantity of the state estimate: it needs --state")
    inputs = [args.input, args.tyre] + ([sidecar_path(args.input)] if kind == "profile" else []) + (
        [args.channel_map] if args.channel_map else [])
    check_output_paths([args.out, args.per_revolution, args.plot], overwrite=args.force, inputs=inputs)

    import json

    from ringfit.fit.estimate import EstimateSettings, estimate_load, estimate_recording
    from ringfit.io.files import atomic_write_text
    from ringfit.io.tyre import read_tyre, require_ring

    tyre = require_ring(read_tyre(args.tyre), "the load estimate needs the tyre's identified ring")
    _, note = tread_uncertainty(tyre, args.k_tread_sd)
    if note and not args.quiet:
        print(note)
    # the tyre's [ring.covariance] (k_trd given the rest, and the rest by linear propagation) unless --k-tread-sd
    settings = EstimateSettings(n_grid=args.grid, k_max=args.harmonics, k_tread_sd=args.k_tread_sd)
    k_in_file = "k_tread" in tyre.ring_values
    revs = None
    if kind == "profile":
        from ringfit.io.profiles import read_profile

        profile = read_profile(args.input)
        # rotation_hz against speed_kmh, judged by the profile's own patch (ringfit.io.conditions)
        from ringfit.io.conditions import check_profile_rotation

        profile, note = check_profile_rotation(profile, float(tyre.geometry.outer_radius))
        if note:
            import warnings

            warnings.warn(note, stacklevel=2)
        condition = dict(profile.condition)
        fixed = parse_fix(args.fix, profile.condition, source=args.input, laws=tyre.laws) if args.state else {}
        est = estimate_load(profile, tyre.geometry, tyre.ring, settings=settings, k_tread_in_file=k_in_file,
                            ring_covariance=tyre.covariance, laws=tyre.laws)
        if args.state:
            from ringfit.fit.estimate.state import estimate_state

            state = estimate_state(profile, tyre.geometry, tyre.ring, tyre.laws, settings=settings, fixed=fixed,
                                   omega=est.omega, omega_source=est.rotation_source, load=est,
                                   ring_covariance=tyre.covariance, k_tread_in_file=k_in_file)
    elif args.state:
        from ringfit.fit.estimate.state import estimate_recording_state
        from ringfit.io.continuous import read_continuous

        want_revs = args.per_revolution is not None or args.plot is not None
        with read_continuous(args.input, channels=args.channel_map) as rec:
            condition = dict(rec.condition)
            fixed = parse_fix(args.fix, rec.condition, source=args.input, laws=tyre.laws)
            est, state, revs = estimate_recording_state(rec, tyre.geometry, tyre.ring, tyre.laws, settings=settings,
                                                        fixed=fixed, k_tread_in_file=k_in_file,
                                                        per_revolution=want_revs, progress=not args.quiet,
                                                        ring_covariance=tyre.covariance)
    else:
        from ringfit.io.continuous import read_continuous

        want_revs = args.per_revolution is not None or args.plot is not None
        with read_continuous(args.input, channels=args.channel_map) as rec:
            condition = dict(rec.condition)
            est, revs = estimate_recording(rec, tyre.geometry, tyre.ring, settings=settings,
                                           k_tread_in_file=k_in_file, per_revolution=want_revs,
                                           progress=not args.quiet, ring_covariance=tyre.covariance,
                                           laws=tyre.laws)
    if not args.quiet:
        for flag in est.flags:
            print(f"ringfit estimate: {flag}", file=sys.stderr)
    _print_estimate(est)
    if not est.converged:
        raise CommandFailed(f"the load estimate did not converge (status {est.status}"
                            + (f"; {est.flags[-1]}" if est.flags else "") + "); nothing written")
    record = est.to_record(args.input.name)
    if args.state:
        _print_state(state, quiet=args.quiet)
        if not state.converged:
            raise CommandFailed(f"the state estimate did not converge (status {state.status}"
                                + (f"; {state.flags[-1]}" if state.flags else "") + "); nothing written")
        record["state"] = state.to_record()
        if revs is not None:
            record["state"]["per_revolution"] = revs.summary()
            print(f"per revolution: {len(revs)} revolutions, one linearised Gauss–Newton step each from the "
                  f"averaged fit; load median {record['state']['per_revolution']['load_n_median']:.0f} N")
    elif revs is not None:
        record["per_revolution"] = revs.summary()
        print(f"per revolution: {len(revs)} revolutions, {int(revs.converged.sum())} converged; load "
              f"{record['per_revolution']['load_n_min']:.0f} … {record['per_revolution']['load_n_max']:.0f} N "
              f"(median {record['per_revolution']['load_n_median']:.0f} N)"
              if revs.converged.any() else f"per revolution: {len(revs)} revolutions, none converged")
        if not revs.converged.any():
            raise CommandFailed("no revolution's fit converged; nothing written")
    # every condition the input states that the estimate also read, against the data (ringfit.io.conditions)
    from ringfit.io.conditions import stated_against_estimate

    read = state.quantities if args.state else {"load_n": {"value": est.load_n, "lo": est.lo, "hi": est.hi}}
    record["stated"] = stated_against_estimate(read, condition, source=args.input)
    for row in record["stated"]:
        if not row["consistent"]:
            print(f"WARNING: {row['sentence']}", file=sys.stderr)
    atomic_write_text(args.out, json.dumps(record, indent=2, allow_nan=False) + "\n")
    print(f"wrote {args.out}")
    if args.per_revolution is not None:
        atomic_write_text(args.per_revolution, _revolutions_csv(revs))
        print(f"wrote {args.per_revolution} ({len(revs)} rows)")
    if args.plot is not None:
        from ringfit.report.estimate_plots import estimate_figure
        from ringfit.report.figures import save_figure

        if args.state:
            from ringfit.report.estimate_plots import state_figure

            save_figure(state_figure(state, revs, title=args.input.name), args.plot)
        else:
            save_figure(estimate_figure(est, revs, title=args.input.name), args.plot)
        print(f"wrote {args.plot}")
    return 0


#: ``--fix`` names → (θ name of ringfit.fit.estimate.state, factor to SI, plausible range in the name's unit).
FIXABLE = {"load_n": ("load_n", 1.0, (200.0, 20000.0)), "pressure_bar": ("pressure_pa", 1e5, (0.3, 8.0)),
           "slip": ("slip", 1.0, (-0.3, 0.3)), "tread_depth_mm": ("tread_depth_m", 1e-3, (0.2, 30.0))}


def parse_fix(items, condition: dict, *, source=None, laws=None) -> dict:
    """``--fix NAME=VALUE`` items → ``{θ name: SI value}`` (:data:`FIXABLE`; VALUE ``stated``: the input's condition).

    **Raises** :class:`InputError` (exit 2) for an unknown name, a value that is not a number in its range, a
    ``stated`` value the input does not state, a name given twice, or a tread depth deeper than the new tread's of
    the tyre file's ``laws`` (``tread_depth_new_mm``, docs/physics.md §13.3)."""
    from ringfit.errors import InputError
    from ringfit.fit.estimate.state import new_tread_depth

    out = {}
    for item in items:
        name, sep, text = str(item).partition("=")
        name, text = name.strip(), text.strip()
        if not sep or name not in FIXABLE:
            raise InputError(f"--fix {item!r}: expected NAME=VALUE with NAME one of {', '.join(FIXABLE)}")
        key, factor, (lo, hi) = FIXABLE[name]
        if key in out:
            raise InputError(f"--fix {name} given twice")
        if text.lower() == "stated":
            if name == "slip" or condition.get(name) is None:
                raise InputError(f"--fix {name}=stated: the input states no {name}", source=source)
            value = float(condition[name])
        else:
            try:
                value = float(text)
            except ValueError:
                raise InputError(f"--fix {item!r}: {text!r} is not a number (or 'stated')") from None
        if not (lo <= value <= hi):
            raise InputError(f"--fix {name}={value:g}: outside the plausible range [{lo:g}, {hi:g}]")
        new = None if laws is None else new_tread_depth(laws)
        if name == "tread_depth_mm" and new is not None and value * factor > float(new) * (1 + 1e-9):
            raise InputError(f"--fix {name}={value:g}: deeper than the tyre file's new tread (tread_depth_new_mm = "
                             f"{1e3 * float(new):g}): wear only removes tread")
        out[key] = value * factor
    return out


def _print_state(state, *, quiet: bool = False) -> None:
    import sys

    for key, q in state.quantities.items():
        print(f"state {key} {q['value']:.5g} {q['unit']} (95 %: {q['lo']:.5g} … {q['hi']:.5g}) {q['status']}")
    if not quiet:
        for line in state.untold:
            print(f"ringfit estimate: not told apart: {line}", file=sys.stderr)
        for flag in state.flags:
            print(f"ringfit estimate: state: {flag}", file=sys.stderr)


def tread_uncertainty(tyre, k_tread_sd):
    """σ of ln k_trd the estimate propagates, and a line saying where it came from.

    ``--k-tread-sd`` wins; else the tyre file's ``[ring.covariance]`` (docs/formats.md §1.1: the
    marginal σ of ln k_trd, as identified); else ``None`` (fixed, or the estimate's default prior
    when the file has no k_trd).
    """
    if k_tread_sd is not None:
        return k_tread_sd, None
    cov = tyre.covariance
    sd = None if cov is None else cov.sd_ln("k_tread")
    if sd is None:
        return None, None
    others = [n for n in cov.names if n != "k_tread"]
    return sd, (f"k_tread {tyre.ring_values.get('k_tread', float('nan')):.4g} N/m² ± {100 * sd:.2g} % (1σ, the tyre "
                "file's [ring.covariance]) propagated into the load interval"
                + (f", with {', '.join(others)} and their correlations" if others else ""))


def _input_kind(path: Path) -> str:
    from ringfit.errors import InputError

    from ringfit.io.profiles import sidecar_path

    name = path.name.lower()
    if name.endswith(".csv") and (name.endswith(".modes.csv") or _looks_like_mode_table(path)):
        raise InputError("is a mode table (docs/formats.md §2: n, freq_hz, …); estimate reads the rolling tyre's "
                         "readings: a *.profile.csv (docs/formats.md §3) or a continuous recording (*.records.npz, "
                         ".tdms, .mat, .csv)", source=path)
    if name.endswith(".csv"):
        # a profile has its JSON sidecar (docs/formats.md §3); any other CSV is a recording (§17.3)
        return "profile" if name.endswith(".profile.csv") or sidecar_path(path).exists() else "recording"
    if name.endswith((".npz", ".tdms", ".mat")):
        return "recording"
    raise InputError("expected a *.profile.csv, a continuous *.records.npz or a .tdms/.mat/.csv recording",
                     source=path)


def _looks_like_mode_table(path: Path) -> bool:
    """A CSV whose header names a mode table's columns (``freq_hz`` and ``n``; docs/formats.md §2)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.strip() and not line.lstrip().startswith("#"):
                    cols = {c.strip().strip('"').lower() for c in line.split(",")}
                    return "freq_hz" in cols and "n" in cols
    except OSError:
        return False
    return False


def _print_estimate(est) -> None:
    p = est.patch
    print(f"load {est.load_n:.0f} N (95 %: {est.lo:.0f} … {est.hi:.0f} N); patch {p['length_mm']:.1f} mm "
          f"({p['leading_deg']:+.2f}° … {p['trailing_deg']:+.2f}°)")
    print(f"rotation {est.rotation_hz:.4g} Hz from {est.rotation_source}")
    print(f"fit: {est.status}, residual RMS {est.rms:.3g} m/s², noise {est.noise:.3g} m/s² ({est.noise_source}); "
          f"harmonics 2…{est.k_max} of the radial reading")
    f = est.feature
    feat = f"{f.load_n:.0f} N" if f.load_n == f.load_n else "not found"
    print(f"feature method (edge peaks {f.leading_deg:+.2f}° / {f.trailing_deg:+.2f}°, {f.spacing_mm:.1f} mm): {feat}")


def _revolutions_csv(revs) -> str:
    import csv
    import io

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    cols = revs.columns()
    w.writerow(list(cols))
    for i in range(len(revs)):
        w.writerow([_cell(cols[k][i]) for k in cols])
    return buf.getvalue()


def _cell(x) -> str:
    import math

    import numpy as np

    if isinstance(x, (int, np.integer)):
        return str(int(x))
    x = float(x)
    return repr(x) if math.isfinite(x) else ""
