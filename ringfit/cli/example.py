"""``ringfit example {records,case,cleat,profiles,rolling,identify} --out DIR`` — synthetic inputs with a README of their truth.

The one command of the product that imports :mod:`ringfit.synth` (the
test-data generators); see :mod:`ringfit.synth.examples`.
"""

from __future__ import annotations

from pathlib import Path

from ringfit.cli._args import force_flag, quiet_flag

KINDS = ("records", "case", "cleat", "profiles", "rolling", "identify")


def register(sub) -> None:
    p = sub.add_parser("example", help="write synthetic example inputs with a README of their truth",
                       description="Write example inputs (docs/formats.md) generated from a known truth into a "
                                   "folder, with a README.md that states the truth and the one-line commands that "
                                   "read them: records (hammer records -> ssi, frf, fit, sample, report), profiles "
                                   "(rolling profiles -> fit-rolling, roll), cleat (drum recording -> profile, "
                                   "cleat), case (case folder -> diagnose), rolling (case folder with rolling mode "
                                   "tables at 20/40/60 km/h -> diagnose, campbell), identify (case folder with every state: free, loaded at "
                                   "two loads, three profiles at known load -> identify, estimate).")
    p.add_argument("kind", choices=KINDS, help="which example: " + ", ".join(KINDS))
    p.add_argument("--out", required=True, type=Path, help="folder to write into (created if missing)")
    force_flag(p)
    quiet_flag(p)
    p.set_defaults(run=run_example)


def run_example(args) -> int:
    from ringfit.synth.examples import write_example

    paths = write_example(args.kind, args.out, overwrite=args.force, progress=not args.quiet)
    for p in paths:
        print(f"wrote {p}")
    print(f"see {args.out / 'README.md'} for the truth and the commands to try")
    return 0
