"""``ringfit diagnose FOLDER --out NAME.diagnosis.json [--report NAME.html] [--effects a,b,…]``.

Diagnoses the sim-to-real gap of a case folder (docs/formats.md §6) and writes the
JSON of docs/formats.md §5; progress goes to stderr while candidates are fitted.
"""

from __future__ import annotations

from ringfit.cli._args import force_flag, number, quiet_flag

#: Draws per null distribution unless ``--null-draws`` says otherwise (what ``campaign`` runs).
DEFAULT_NULL_DRAWS = 200


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "diagnose",
        help="sim-to-real gap diagnosis of a case folder",
        description="Where the baseline model and the measurements disagree, which unmodelled effect "
                    "explains it, and how far it shrinks on held-out data (docs/formats.md §5, §6).",
    )
    p.add_argument("folder", help="case folder: tyre.toml, free.modes.csv(+json), test tables, profiles")
    p.add_argument("--out", required=True, help="output NAME.diagnosis.json")
    p.add_argument("--report", help="also write a self-contained HTML report")
    p.add_argument("--effects", help="comma-separated candidate effects (default: all registered)")
    p.add_argument("--effect-module", action="append", default=[],
                   help="import a module (or .py file) that registers extra effects; repeatable")
    p.add_argument("--noise-freq-hz", type=number("a noise level in Hz > 0", lo=0.0, hi=1e4, lo_open=True),
                   help="frequency noise σ [Hz] instead of estimating it")
    p.add_argument("--noise-profile", type=number("a noise level in m/s² > 0", lo=0.0, hi=1e8, lo_open=True),
                   help="profile noise σ [m/s²] instead of estimating it")
    p.add_argument("--alpha", type=number("a significance level in (0, 0.5]", lo=0.0, hi=0.5, lo_open=True),
                   default=0.01, help="an accepted effect must beat chance (its null) at this level (default 0.01)")
    p.add_argument("--null-draws", type=_null_draws, default=DEFAULT_NULL_DRAWS,
                   help=f"draws per null distribution (default {DEFAULT_NULL_DRAWS}; p is resolved to 1/(draws + 1)); "
                        "0: no null, the rule's fixed bars alone decide (docs/physics.md §6.4; not recommended)")
    p.add_argument("--tyre", default=None, metavar="TYRE.toml",
                   help="baseline ring as identified or fitted before (ringfit identify / fit), used as it is with "
                        "its [ring.covariance]: one ring per tyre (default: fit free.modes.csv)")
    quiet_flag(p)
    force_flag(p)
    p.set_defaults(run=run)


def run(args) -> int:
    from pathlib import Path

    from ringfit.errors import InputError
    from ringfit.io.files import check_output_paths

    if not str(args.out).endswith(".json"):
        raise InputError("--out must end in .json (e.g. NAME.diagnosis.json)", source=args.out)
    folder = Path(args.folder)  # not a case folder: the case reader's one line (ringfit.io.case.read_case_folder)
    inputs = list(folder.glob("*")) + ([Path(args.tyre)] if args.tyre else [])
    check_output_paths([args.out, args.report], overwrite=args.force, inputs=inputs)
    baseline = None
    if args.tyre:
        from ringfit.io.tyre import read_tyre

        baseline = read_tyre(args.tyre)
        if not baseline.ring_values:
            raise InputError("has no [ring]: --tyre gives the baseline ring (ringfit identify or fit first)",
                             source=args.tyre)

    from ringfit.gap import diagnose
    from ringfit.gap.effects import load_effect_module

    for mod in args.effect_module:
        try:
            load_effect_module(mod)
        except Exception as exc:  # noqa: BLE001 - report any import failure as bad input
            raise InputError(f"cannot load effect module: {exc}", source=mod) from None
    effects = parse_effects(args.effects)
    noise = {}
    if args.noise_freq_hz is not None:
        noise["freq_hz"] = args.noise_freq_hz
    if args.noise_profile is not None:
        noise["profile_ms2"] = args.noise_profile
    print(f"ringfit diagnose: {folder}")
    diag = diagnose(folder, effects=effects, progress=not args.quiet, noise=noise or None, alpha=args.alpha,
                    null_draws=int(args.null_draws), tyre=baseline)
    diag.write(args.out, overwrite=args.force, inputs=inputs)
    if args.report:
        from ringfit.report.gap_report import write_gap_report

        write_gap_report(diag, args.report, overwrite=args.force)
    v = diag.verdict
    print(f"verdict: {' + '.join(v['effects'])}"
          + (f" (held-out shrink {v['heldout_shrink_pct']:.0f} %)" if v["effect"] not in ("none", "unexplained") else ""))
    for line in chance_lines(v):
        print(f"  {line}")
    st = (diag.content.get("baseline") or {}).get("rolling_structure")
    if st:  # the model structure the rolling rows were assigned to (docs/physics.md §6.4)
        print(f"  rolling rows assigned to {st['chosen']} (cost −2 ln L: "
              + ", ".join(f"{k} {val:.1f}" for k, val in st["cost"].items()) + ")")
    print(f"wrote {args.out}" + (f" and {args.report}" if args.report else ""))
    return 0


def chance_lines(verdict: dict) -> list[str]:
    """One line per accepted candidate tested against chance (``verdict.calibration``), each naming its
    variant, so that a fitted and a computed candidate of the same effect read apart."""
    out = []
    for c in verdict.get("calibration", []):
        text = c["sentence"].removeprefix(f"{c['effect']}: ")
        out.append(f"{c['effect']}" + (f" ({c['variant']})" if c.get("variant") else "") + f": {text}")
    return out


def parse_effects(text: str | None) -> list[str] | None:
    """``--effects a,b`` → the names (``None`` for all registered); :class:`InputError` naming ``--effects`` for
    an unknown or empty list. Shared by ``diagnose`` and ``campaign`` (checked before any work)."""
    from ringfit.errors import InputError

    if text is None:
        return None
    from ringfit.gap.effects import available

    effects = [e.strip() for e in text.split(",") if e.strip()]
    if not effects:
        raise InputError(f"{text!r}: expected comma-separated effect names; known: {', '.join(available())}",
                         source="--effects")
    unknown = [e for e in effects if e not in available()]
    if unknown:
        raise InputError(f"unknown effect(s) {unknown}; known: {', '.join(available())}", source="--effects")
    return effects


def _null_draws(text: str) -> int:
    """``--null-draws``: 0 (no null: the fixed bars of the rule stand, docs/physics.md §6.4) or 20 … 20000."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        value = None
    if value is None or not (value == 0 or 20 <= value <= 20000):
        raise argparse.ArgumentTypeError(f"expected 0 (no null) or a count of null draws, 20 … 20000; got {text!r}")
    return value
