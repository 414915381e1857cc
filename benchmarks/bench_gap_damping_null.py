"""False accepts of the damping part of the gap diagnosis on damping columns with no effect in them.

The damping rows (ln ζ, one level per table, docs/physics.md §6 "Damping") take their noise σ per table from
second differences along n — an estimate from a handful of rows, which chance can make several times too small.
The parametric null re-applies that rule to every draw (``ProblemMeta.noise_rule``, §6.4's audit of freedoms).
This script builds only the damping problem of each folder and diagnoses it (≈ 1 s per folder), so the rate of a
damping effect accepted on damping columns drawn uniformly in 2–8 % (no growth, no trend: no effect) can be
measured on many folders, with its 95 % interval (Clopper–Pearson) against α + 1 %.

Kinds (the folders of ``bench_gap_calibration.py``, whose damping columns are random): ``rolling-labelled``,
``rolling-half-labelled`` and ``rolling-random`` (12/13/12 rows at 20/40/60 km/h beside the source study's free
table).

Run: ``python benchmarks/bench_gap_damping_null.py [--folders N] [--kinds a,b] [--seed-offset S]`` (default 200
folders per kind).
"""

from __future__ import annotations

import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402
from bench_gap_calibration import clopper_pearson, rolling_labelled, rolling_random  # noqa: E402

KINDS = {
    "rolling-labelled": lambda out, seed: rolling_labelled(out, seed, "full"),
    "rolling-half-labelled": lambda out, seed: rolling_labelled(out, seed, "half"),
    "rolling-random": lambda out, seed: rolling_random(out, seed, (12, 13, 12)),
}


def main(folders: int, kinds, offset: int) -> None:
    from ringfit.gap.calibration import ALPHA
    from ringfit.gap.case import read_case
    from ringfit.gap.diagnosis import build_problems, diagnose_problem, resolve_effects

    bc.start(f"bench_gap_damping_null: {folders} folders per kind, kinds {', '.join(kinds)}")
    effects = resolve_effects(None)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in kinds:
            accepted, verdicts, t0, c0 = [], {}, time.perf_counter(), time.process_time()
            for i in range(folders):
                seed = offset + i
                folder = Path(tmp) / f"{kind}-{seed}"
                KINDS[kind](folder, seed)
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    prob = next(p for p in build_problems(read_case(folder), effects) if p.domain == "damping")
                    part = diagnose_problem(prob, progress=False)
                eff = part.summary["verdict"]["effects"]
                verdicts[" + ".join(eff)] = verdicts.get(" + ".join(eff), 0) + 1
                found = [e for e in eff if e not in ("none", "unexplained")]
                if found:
                    accepted.append((seed, found))
                    print(f"  {kind} seed {seed}: FALSE ACCEPT {' + '.join(found)}", flush=True)
            k = len(accepted)
            lo, hi = clopper_pearson(k, folders)
            target = ALPHA + 0.01
            rows.append((kind, folders, k, lo, hi, target, verdicts, (time.perf_counter() - t0) / folders,
                         (time.process_time() - c0) / folders))
    print("\n| damping columns | n | false accepts | rate | 95 % interval | target | verdicts | wall / CPU per folder |")
    print("|---|---|---|---|---|---|---|---|")
    for kind, n, k, lo, hi, target, verdicts, w, c in rows:
        ok = "met" if k / n <= target else "NOT met"
        print(f"| {kind} | {n} | {k} | {100 * k / n:.1f} % | {100 * lo:.1f} … {100 * hi:.1f} % | <= "
              f"{100 * target:.0f} %: {ok} | {verdicts} | {w:.2f} s / {c:.2f} s |")
    bc.finish()


if __name__ == "__main__":
    ap = bc.parser(__doc__.splitlines()[0], quick_help="5 folders of one kind (a smoke run)")
    ap.add_argument("--folders", type=bc.count("a number of folders >= 1"), default=200)
    ap.add_argument("--kinds", type=bc.choices_list(tuple(KINDS)), default=tuple(KINDS))
    ap.add_argument("--seed-offset", type=bc.count("a seed offset >= 0", 0, 10**7), default=5000)
    a = ap.parse_args()
    if a.quick:
        a.folders, a.kinds = 5, ("rolling-half-labelled",)
    main(a.folders, a.kinds, a.seed_offset)
