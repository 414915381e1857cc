"""Blind validation of the gap diagnosis: generated case folders (profiles and mode tables), labels hidden.

Prints the confusion matrix (expected → verdict), the accuracy (target ≥ 95 %),
the held-out shrink error against the ideal shrink (target within 10 points)
for cases whose effect was found, and the time per case. Compiled functions
are reused across candidates and cases; the first case of each kind includes
compilation.

Ideal shrink = 1 − (true noise RMS)/(baseline held-out RMS): the fraction of
the residual that is not noise. For profile cases the true noise RMS on the
diagnosis grid comes from the hidden label; for mode-table cases (whose
generator does not keep it) the diagnosis's own noise estimate is used.

Run: ``python benchmarks/bench_gap.py [n_profile_cases] [n_modal_cases]`` (default 35 + 15).
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

import ringfit  # noqa: F401
from ringfit.gap import diagnose
from ringfit.synth.cases import MODAL_INJECTIONS, PROFILE_INJECTIONS, make_case, make_profile_case


def run(kind: str, n: int, tmp: Path, confusion: Counter, errors: list, times: list) -> None:
    injections = PROFILE_INJECTIONS if kind == "profiles" else MODAL_INJECTIONS
    make = make_profile_case if kind == "profiles" else make_case
    for i in range(n):
        effect = injections[i % len(injections)]
        folder = tmp / f"{kind}{i:03d}"
        label = make(folder, effect, seed=(2000 if kind == "profiles" else 1000) + i)
        t0 = time.perf_counter()
        d = diagnose(folder, progress=False)
        dt = time.perf_counter() - t0
        times.append((kind, dt))
        got = d.verdict["effect"]
        confusion[(label.expected_verdict, got)] += 1
        b = d.content["baseline"]
        note = ""
        if got == label.expected_verdict and got not in ("none", "unexplained"):
            cand = next(c for c in d.content["candidates"] if c["effect"] == got)
            if kind == "profiles":
                ideal = 100.0 * (1.0 - label.noise["grid_rms_ms2"] / b["heldout_rms"])
            else:
                ideal = b["ideal_shrink_pct"]
            errors.append((kind, cand["heldout_shrink_pct"] - ideal))
            note = f"shrink {cand['heldout_shrink_pct']:5.1f} ideal {ideal:5.1f}"
        print(f"{kind:8s} {i:3d} {label.expected_verdict:>15s} -> {' + '.join(d.verdict['effects']):32s} "
              f"{dt:5.1f} s {note}", flush=True)


def main(n_profiles: int = 35, n_modal: int = 15) -> None:
    print(f"CPU cores available: {os.cpu_count()}")
    confusion, errors, times = Counter(), [], []
    with tempfile.TemporaryDirectory() as tmp:
        run("profiles", n_profiles, Path(tmp), confusion, errors, times)
        run("modes", n_modal, Path(tmp), confusion, errors, times)
    n = n_profiles + n_modal
    labels = sorted({k[0] for k in confusion} | {k[1] for k in confusion})
    print("\nconfusion matrix (rows: expected, columns: verdict)")
    print(" " * 16 + "".join(f"{lab[:12]:>13s}" for lab in labels))
    for a in labels:
        print(f"{a[:15]:>15s} " + "".join(f"{confusion[(a, b)]:13d}" for b in labels))
    correct = sum(v for (a, b), v in confusion.items() if a == b)
    print(f"\naccuracy: {correct}/{n} = {100.0 * correct / n:.1f} % (target >= 95 %)")
    for kind in ("profiles", "modes"):
        e = np.abs([x for k, x in errors if k == kind])
        if e.size:
            print(f"{kind}: held-out shrink - ideal shrink [points]: mean |err| {e.mean():.1f}, max |err| "
                  f"{e.max():.1f}, within 10 points: {np.mean(e <= 10) * 100:.0f} % of {e.size} detected effects")
        t = [x for k, x in times if k == kind]
        if t:
            print(f"{kind}: time per case: first {t[0]:.1f} s (with compilation), median of the rest "
                  f"{np.median(t[1:]) if len(t) > 1 else float('nan'):.1f} s, max {max(t):.1f} s")


if __name__ == "__main__":
    args = [int(a) for a in sys.argv[1:]]
    main(*args)
