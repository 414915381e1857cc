"""A warm diagnosis of a small profile case: what the profile baseline's per-run gains and angle offsets cost.

The profile baseline fits each run's gain and angle offset (the profile block's nuisances, 2P parameters for P
profiles). They act after the rolling solve, so the refits and linearisations pass only K − 2P tangents through
the solve (the engine's two-stage models), and the nulls' linearised refits of many draws share one normal
matrix per fold. Target: a warm four-profile diagnosis (wave_damping, seed 2000) within 20 s of CPU on this
machine — what it cost before the per-run nuisances (18.5 s) — and the same verdict.

Prints the first (cold: compilation, unless the compilation cache holds it) and then ``repeat`` warm diagnoses,
wall beside CPU, with the load average.

Run: ``python benchmarks/bench_gap_profile_warm.py [repeat] [--quick]`` (default 2 warm runs; ``--quick``: one).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
import _common as bc  # noqa: E402

import ringfit  # noqa: F401,E402
from ringfit.gap import diagnose  # noqa: E402
from ringfit.synth.cases import make_profile_case  # noqa: E402

TARGET_CPU_S = 20.0


def main(argv=None) -> int:
    p = bc.parser("warm profile diagnosis (per-run gains and offsets)")
    p.add_argument("repeat", nargs="?", type=bc.count(), default=2)
    args = p.parse_args(argv)
    repeat = 1 if args.quick else args.repeat
    bc.start("gap: warm diagnosis of a four-profile case (wave_damping, seed 2000)")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "case"
        make_profile_case(folder, effect="wave_damping", seed=2000)
        d, cold = bc.timed(diagnose, folder, progress=False)
        print(f"  cold: {cold.wall:.1f} s wall, {cold.cpu:.1f} s CPU; verdict {d.verdict['effect']} "
              f"(held-out shrink {d.verdict.get('heldout_shrink_pct')} %)  [{bc.loadavg()}]")
        warm = []
        for _ in range(repeat):
            d, s = bc.timed(diagnose, folder, progress=False)
            warm.append(s)
            print(f"  warm: {s.wall:.1f} s wall, {s.cpu:.1f} s CPU; verdict {d.verdict['effect']}  [{bc.loadavg()}]")
    print(bc.row("warm diagnosis", warm, f"target CPU <= {TARGET_CPU_S:g} s"))
    bc.finish()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
