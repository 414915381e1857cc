"""``ringfit example {records,case,cleat,profiles,rolling,identify,state} --out DIR [--format tdms|mat|csv] [--effect NAME] [--seed S --blind N --seconds T]`` — synthetic inputs with a README of their truth.

The one command of the product that imports :mod:`ringfit.synth` (the
test-data generators); see :mod:`ringfit.synth.examples`.
"""

from __future__ import annotations

from pathlib import Path

from ringfit.cli._args import force_flag, quiet_flag

KINDS = ("records", "case", "cleat", "profiles", "rolling", "identify", "state")
FORMATS = ("tdms", "mat", "csv")


def register(sub) -> None:
    p = sub.add_parser("example", help="write synthetic example inputs with a README of their truth",
                       description="Write example inputs (docs/formats.md) generated from a known truth into a "
                                   "folder, with a README.md that states the truth and the one-line commands that "
                                   "read them: records (hammer records -> ssi, frf, fit, sample, report), profiles "
                                   "(rolling profiles -> fit-rolling, roll), cleat (drum recording -> profile, "
                                   "cleat), case (case folder -> diagnose), rolling (case folder with rolling mode "
                                   "tables at 20/40/60 km/h -> diagnose, campbell), identify (case folder with every state: free, loaded at "
                                   "two loads, three profiles at known load -> identify, estimate), state (continuous recordings of the "
                                   "independent simulator at known states in calibration/ and hidden states in blind/, a "
                                   "nominal tyre.toml, the truth per revolution in truth/ -> estimate).")
    p.add_argument("kind", choices=KINDS, help="which example: " + ", ".join(KINDS))
    p.add_argument("--out", required=True, type=Path, help="folder to write into (created if missing)")
    p.add_argument("--format", dest="fmt", choices=FORMATS, default=None,
                   help="records only: also write the records as NI TDMS (impact.tdms), MATLAB v5 (impact.mat) or "
                        "CSV (impact.csv + its channel map impact.channels.toml), docs/formats.md §17")
    p.add_argument("--effect", default=None, metavar="NAME",
                   help="case only: the effect hidden in the case folder (default ground_contact), e.g. "
                        "wheel_suspension, rotation, wave_damping, none, tread_pitch")
    p.add_argument("--seed", type=int, default=None, metavar="S",
                   help="state only: random seed of the true tyre, the blind states and the noise (default 0)")
    p.add_argument("--blind", type=int, default=None, metavar="N",
                   help="state only: number of recordings at hidden states (default 6)")
    p.add_argument("--seconds", type=float, default=None, metavar="T",
                   help="state only: length of each recording in seconds (default 4)")
    force_flag(p)
    quiet_flag(p)
    p.set_defaults(run=run_example)


def run_example(args) -> int:
    from ringfit.errors import InputError
    from ringfit.synth.examples import write_example

    if args.fmt is not None and args.kind != "records":
        raise InputError(f"--format {args.fmt} applies to `ringfit example records` only")
    state = {k: getattr(args, k) for k in ("seed", "blind", "seconds") if getattr(args, k) is not None}
    if state and args.kind != "state":
        raise InputError(f"--{next(iter(state))} applies to `ringfit example state` only")
    paths = write_example(args.kind, args.out, overwrite=args.force, progress=not args.quiet, fmt=args.fmt,
                          effect=args.effect, **state)
    for p in paths:
        print(f"wrote {p}")
    print(f"see {args.out / 'README.md'} for the truth and the commands to try")
    return 0
