"""Blind validation of the gap diagnosis: generated case folders (profiles and mode tables), labels hidden.

Prints, per case, what was injected and what the diagnosis said; then the
confusion matrix (expected → verdict), the accuracy (target ≥ 95 %), the
held-out shrink error against the ideal shrink (target within 10 points) for
cases whose effect was found, and the time per case. Compiled functions are
reused across candidates and cases; a first, uncounted diagnosis of a
four-speed profile folder with every candidate measures the cold start,
compilation included (the "< 20 s on 2 cores" figure).

Ideal shrink = 1 − SS_noise/SS_before (docs/formats.md §5: the shrink is
1 − SS_after/SS_before of noise-weighted sums of squares): the fraction of the
baseline's held-out residual that is not noise. The true noise comes from the
hidden label: for profile cases its RMS on the diagnosis grid (SS ratio =
(noise RMS / held-out RMS)²), for mode-table cases the realised noise of every
frequency row, weighted and Huber-transformed as the diagnosis weights its
held-out residuals. The measured shrink is the verdict's (the accepted chain
against the baseline).

The generator varies what a self-fitting benchmark would hold fixed: the truth's
grid (M = 1024 … 4096 harmonics), the number of recorded angles (360 … 2048),
noise colour (white, pink, red, band) and level (0.05 … 3 m/s² at 40 km/h),
angle offset, encoder or not, flat road or drum, the ring (±6 %) and k_trd (±15 %).

Every time is printed as wall and CPU (process time) side by side, with the load average at
the start and the end; a case whose diagnosis raises is listed and no figures are printed.

Run: ``python benchmarks/bench_gap.py [n_profile_cases] [n_modal_cases] [first_seed_offset] [--quick]
[--effects NAME,...]`` (default 35 + 15, offset 0; ``--quick``: 1 + 1 cases and no cold start, a smoke run;
``--effects``: only those injections, e.g. ``--effects tread_shear,wheel_suspension``).
"""

from __future__ import annotations

import sys
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402

import ringfit  # noqa: F401,E402
from ringfit.gap import diagnose
from ringfit.synth.cases import MODAL_INJECTIONS, PROFILE_INJECTIONS, make_case, make_profile_case


def _ideal(part, ss_noise: float) -> float:
    """100 (1 − SS_noise/SS_before), SS_before of the baseline's held-out residual as the diagnosis weighs it."""
    prob = part.problem
    ss_before = float(np.sum(prob.standardised(prob.y - part.baseline.extra["heldout_pred"], heldout=True) ** 2))
    return 100.0 * (1.0 - ss_noise / ss_before)


def modal_ideal(d, label) -> float:
    """Ideal held-out shrink [%] of a mode-table case: 100 (1 − SS_noise/SS_before) over the rows of the part
    the effect acts on (frequency rows; damping rows in ln ζ for wave_damping), SS_noise from the realised
    noise of every row (hidden label), weighted and ψ-transformed exactly as the diagnosis weights its
    held-out residuals (docs/formats.md §5)."""
    damping = label.expected_verdict in ("wave_damping", "damping_growth", "viscous_damping")
    part = next(p for p in d.parts if p.problem.domain == ("damping" if damping else "modes"))
    prob = part.problem
    e = np.array([v for kind, v in label.noise["rows"] if kind == ("ln_damping" if damping else "freq")])
    if e.size != prob.m:  # row order not reproduced: fall back on the diagnosis's own estimate
        return part.summary["baseline"]["ideal_shrink_pct"]
    ss_noise = float(np.sum(prob.standardised(e, heldout=True) ** 2))
    return _ideal(part, ss_noise)


def profile_ideal(d, label) -> float:
    """Ideal held-out shrink [%] of a profile case: the true noise RMS of each run and channel on the
    diagnosis grid, weighted by each row's own σ as the diagnosis weights its held-out residuals."""
    part = next(p for p in d.parts if p.problem.domain == "profiles")
    prob = part.problem
    sigma = prob.sigma_heldout if prob.sigma_heldout is not None else prob.sigma
    by_run = np.asarray(label.noise["grid_rms_by_run_ms2"])  # (P, 2)
    P = by_run.shape[0]
    M = prob.m // (2 * P)
    true = np.repeat(by_run.reshape(-1), M)  # rows: run-major, radial then tangential (docs/formats.md §5)
    if true.size != prob.m:
        return part.summary["baseline"]["ideal_shrink_pct"]
    ss_noise = float(np.sum((true / sigma) ** 2))
    return _ideal(part, ss_noise)


def run(kind: str, n: int, offset: int, tmp: Path, confusion: Counter, errors: list, times: list,
        failures: bc.Failures, only: tuple[str, ...] | None = None) -> None:
    injections = PROFILE_INJECTIONS if kind == "profiles" else MODAL_INJECTIONS
    if only:
        injections = tuple(e for e in injections if e in only)
        if not injections:
            return
    make = make_profile_case if kind == "profiles" else make_case
    for i in range(n):
        effect = injections[i % len(injections)]
        folder = tmp / f"{kind}{i:03d}"
        label = make(folder, effect, seed=(2000 if kind == "profiles" else 1000) + offset + i)
        try:
            d, dt = bc.timed(diagnose, folder, progress=False)
        except Exception as exc:  # noqa: BLE001 - a failed case is listed, and the run prints no figures
            failures.add(f"{kind} case {i} ({effect})", f"{type(exc).__name__}: {exc}")
            print(f"{kind:8s} {i:3d} {label.expected_verdict:>15s} -> FAILED: {type(exc).__name__}: {exc}", flush=True)
            continue
        times.append((kind, dt))
        got = d.verdict["effect"]
        confusion[(label.expected_verdict, got)] += 1
        b = d.content["baseline"]
        note = ""
        if kind == "profiles":
            ideal = profile_ideal(d, label)
            note = (f"noise {label.noise['colour']:5s} true {label.noise['grid_rms_ms2']:.3g} "
                    f"est {b['noise_rms']:.3g}; M {label.ring['grid']} pts {label.ring['n_points']} ")
        else:
            ideal = modal_ideal(d, label)
        if got == label.expected_verdict and got not in ("none", "unexplained"):
            shrink = d.verdict["heldout_shrink_pct"]
            errors.append((kind, shrink - ideal))
            note += f"shrink {shrink:5.1f} ideal {ideal:5.1f}"
        else:
            note += f"ideal {ideal:5.1f}"
        flag = "" if got == label.expected_verdict else "  <-- MISS"
        print(f"{kind:8s} {i:3d} {label.expected_verdict:>15s} -> {' + '.join(d.verdict['effects']):30s} "
              f"{dt.wall:5.1f} s ({dt.cpu:5.1f} s CPU)  {note}{flag}", flush=True)


def cold_timing(tmp: Path) -> None:
    """Wall time of the very first diagnosis in this process: a four-speed profile folder with every
    candidate, compilation included (the "< 20 s on 2 cores" figure); not counted in the accuracy."""
    folder = tmp / "cold"
    make_profile_case(folder, "sensor_tilt", seed=1999)
    d, dt = bc.timed(diagnose, folder, progress=False)
    n = len(d.content["candidates"])
    refits = sum(not c.get("screened_out") for c in d.content["candidates"])
    print(f"cold start: four-speed profile folder, {n} candidates ({refits} refitted after the screen), "
          f"compilation included: {dt.wall:.1f} s wall, {dt.cpu:.1f} s CPU -> {' + '.join(d.verdict['effects'])}",
          flush=True)


def main(n_profiles: int = 35, n_modal: int = 15, offset: int = 0, quick: bool = False,
         only: tuple[str, ...] | None = None) -> None:
    bc.start(f"bench_gap: {n_profiles} profile + {n_modal} mode-table cases, seed offset {offset}"
             + (f", effects {', '.join(only)}" if only else "") + (" [--quick]" if quick else ""))
    confusion, errors, times = Counter(), [], []
    failures = bc.Failures()
    with tempfile.TemporaryDirectory() as tmp:
        if not quick and not only:  # the cold start is measured on a full run only
            cold_timing(Path(tmp))
        run("profiles", n_profiles, offset, Path(tmp), confusion, errors, times, failures, only)
        run("modes", n_modal, offset, Path(tmp), confusion, errors, times, failures, only)
    failures.refuse()
    n = n_profiles + n_modal
    labels = sorted({k[0] for k in confusion} | {k[1] for k in confusion})
    print("\nconfusion matrix (rows: expected, columns: verdict)")
    print(" " * 16 + "".join(f"{lab[:12]:>13s}" for lab in labels))
    for a in labels:
        print(f"{a[:15]:>15s} " + "".join(f"{confusion[(a, b)]:13d}" for b in labels))
    correct = sum(v for (a, b), v in confusion.items() if a == b)
    print(f"\naccuracy: {correct}/{n} = {100.0 * correct / max(n, 1):.1f} % (target >= 95 %)")
    for kind in ("profiles", "modes"):
        e = np.abs([x for k, x in errors if k == kind])
        if e.size:
            print(f"{kind}: held-out shrink - ideal shrink [points]: mean |err| {e.mean():.1f}, max |err| "
                  f"{e.max():.1f}, within 10 points: {np.mean(e <= 10) * 100:.0f} % of {e.size} detected effects")
        t = [x for k, x in times if k == kind]
        if t:
            print(f"{kind}: time per case (warm): wall median {np.median(bc.walls(t)):.1f} s, max "
                  f"{max(bc.walls(t)):.1f} s; CPU median {np.median(bc.cpus(t)):.1f} s, max {max(bc.cpus(t)):.1f} s"
                  + ("" if kind == "profiles" else f"; first {t[0].wall:.1f} s wall, {t[0].cpu:.1f} s CPU with the "
                                                   f"mode-table compilation"))
    bc.finish()


if __name__ == "__main__":
    ap = bc.parser(__doc__.splitlines()[0], quick_help="1 profile + 1 mode-table case, no cold start (smoke run)")
    ap.add_argument("n_profile_cases", nargs="?", type=bc.count("a number of cases >= 0", 0, 10**4), default=35)
    ap.add_argument("n_modal_cases", nargs="?", type=bc.count("a number of cases >= 0", 0, 10**4), default=15)
    ap.add_argument("first_seed_offset", nargs="?", type=bc.count("a seed offset >= 0", 0, 10**6), default=0)
    ap.add_argument("--effects", default=None, metavar="NAME[,NAME...]",
                    help="inject only these effects (cycled over the cases of each kind that has them; a kind "
                         "with none of them runs no case). Profile: " + ", ".join(PROFILE_INJECTIONS)
                         + ". Mode tables: " + ", ".join(MODAL_INJECTIONS) + ". The seed of case i is still "
                         "2000 (profiles) or 1000 (mode tables) + first_seed_offset + i.")
    a = ap.parse_args()
    only = None
    if a.effects is not None:
        only = tuple(e.strip() for e in a.effects.split(",") if e.strip())
        unknown = [e for e in only if e not in PROFILE_INJECTIONS + MODAL_INJECTIONS]
        if not only or unknown:
            bc.fail(f"--effects: unknown effect {', '.join(unknown) or '(empty)'}; expected names from "
                    f"{', '.join(sorted(set(PROFILE_INJECTIONS + MODAL_INJECTIONS)))}")
    if a.quick:
        a.n_profile_cases, a.n_modal_cases = 1, 1
    if a.n_profile_cases + a.n_modal_cases == 0:
        bc.fail("no cases: give n_profile_cases or n_modal_cases > 0")
    main(a.n_profile_cases, a.n_modal_cases, a.first_seed_offset, quick=a.quick, only=only)
