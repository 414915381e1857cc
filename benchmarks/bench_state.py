"""The tyre's state from one accelerometer (issue 33 items 4 and 6): a blind check on the independent simulator,
and the Fisher table.

Run ``python benchmarks/bench_state.py`` (default: 6 seeds × 6 blind recordings of 10 s — 36 recordings, so that a
coverage's Clopper–Pearson interval spans about ±10 points rather than ±17 at 18 — about 35 minutes of CPU on the
shared machine: the simulator about 0.7, the averaged fits about 17 (with a drifting recording's fit on stretches,
docs/physics.md §13.4 *a drifting state*); ``--seeds 0 1 2`` halves it). It prints:

1. **Blind accuracy** on recordings of :mod:`ringfit.synth.state` (the *independent* simulator: its own finite
   differences, a memory brush at its fixed point, coloured noise, tilt, the IEPE high-pass in time) written by
   ``ringfit example state`` (:func:`ringfit.synth.state.write_state_example`) at hidden states: speed 20–120 km/h,
   load 0.3–1.2 × rated, pressure ± 20 %, Fx within ± 0.3 Fz (drive and brake, ramping), tread depth 2–8 mm, the
   load oscillating by up to 4 %; the true tyre is the example's nominal ``tyre.toml`` jittered. Each recording is
   read the way ``ringfit estimate --state`` reads a continuous recording: one pass for every whole revolution's
   radial and tangential harmonics and their average (:func:`ringfit.fit.estimate.revolutions.recording_revolutions`),
   the load estimate of the averaged profile, the state of the averaged profile
   (:func:`ringfit.fit.estimate.state.estimate_state`; the whole recording, "averaged over 10 s") and of every
   revolution (:func:`~ringfit.fit.estimate.state.state_revolutions`); a recording whose state drifted is fitted on
   stretches (:func:`~ringfit.fit.estimate.state.drifting_state`), and the averaged fit alone is printed beside it.
   Per quantity (load, pressure, Fx as % of the load, speed, tread depth): the median |error| against the issue's targets, the signed median (bias), and the
   coverage of the 95 % intervals with its Clopper–Pearson interval (target 90–98 %). The per-revolution truth is
   the simulator's revolutions' states averaged over each estimated revolution's time span (the two codes count
   revolutions from different angles). The tyre: ``--tyre nominal`` (default; what a user has: the example's
   ``tyre.toml``), ``--tyre identified`` (``ringfit identify`` of the example's ``calibration/`` through
   :func:`ringfit.synth.examples.calibration_case`, cached in each example's ``identified/``: what a user reads
   with) or ``--tyre truth`` (the true tyre file: a diagnosis — what is left is the model's form and the
   estimator, not the tyre file's values).
2. **Speed**: revolutions per CPU second of the per-revolution stage (the pass over the recording + the
   linearised step) and end to end (with the averaged fits), CPU beside wall (target ≥ 500 on one core).
3. **The Fisher table** (``--fisher``, or ``--fisher-only``): per-revolution σ of each quantity from
   :func:`ringfit.fit.estimate.state.state_fisher` over 20–120 km/h × 0.3–1.2 × rated load, at white noise
   σ = 0.5 % of Ω²R per sample (the example's range is 0.3–1 %) on 1024 samples per revolution, the nuisances
   free, the data alone; the load–pressure and Fx–κ correlations; "–" where σ exceeds the prior (not told).

The example's tyre files state the new tread's depth (``tread_depth_new_mm`` = 8 mm, the blind depths' upper end):
the estimate holds the tread depth within it (docs/physics.md §13.4 *the new tread's bound*).

``--quick``: one seed, two blind recordings of 4 s (a smoke run; its figures are not the targets').
"""

from __future__ import annotations

import csv
import math
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402

import ringfit  # noqa: F401,E402  (float64)

#: The issue's targets: quantity → (median |error| target, unit of the error).
TARGETS = {"load": (0.5, "%"), "pressure": (2.0, "%"), "fx": (2.0, "% of Fz"), "speed": (0.3, "%"),
           "tread": (0.5, "mm")}
#: The estimate's keys (docs/formats.md §7.1) and the truth CSV's columns of each quantity.
KEYS = {"load": "load_n", "pressure": "pressure_bar", "fx": "fx_n", "speed": "speed_kmh", "tread": "tread_depth_mm"}
#: Fisher table grid and noise.
FISHER_SPEEDS = (20.0, 40.0, 60.0, 80.0, 100.0, 120.0)
FISHER_LOADS = (0.3, 0.6, 0.9, 1.2)
FISHER_NOISE_SHARE = 0.005
FISHER_SAMPLES = 1024

ARGS = None


def parse_args(argv=None):
    p = bc.parser(__doc__.splitlines()[0])
    p.add_argument("--seeds", type=bc.count("a seed >= 0", lo=0, hi=2**31), nargs="+", default=[0, 1, 2, 3, 4, 5])
    p.add_argument("--blind", type=bc.count("a number of recordings", lo=1, hi=100), default=6,
                   help="blind recordings per seed (default 6)")
    p.add_argument("--seconds", type=bc.number("a duration in seconds", lo=1.0, hi=600.0), default=10.0,
                   help="length of each recording (default 10 s: the issue's 'averaged over 10 s')")
    p.add_argument("--tyre", choices=("nominal", "identified", "truth"), default="nominal",
                   help="the tyre file the estimate reads (default: the example's nominal tyre.toml; 'identified': "
                        "`ringfit identify` of the example's calibration/, what a user reads with)")
    p.add_argument("--hold", type=bc.choices_list(("pressure", "tread"), "quantities"), default=[],
                   help="hold these at the recording's true mean (a TPMS, a known wear): pressure,tread")
    p.add_argument("--examples", type=Path, default=None,
                   help="keep the simulated examples in this folder (seedS-bB-Ts/) and reuse them on the next run")
    p.add_argument("--fisher", action="store_true", help="print the Fisher table too")
    p.add_argument("--fisher-only", action="store_true", help="print only the Fisher table")
    p.add_argument("--steps", type=bc.count("1 or 2", hi=2), default=1,
                   help="Gauss–Newton steps per revolution (default 1)")
    p.add_argument("--harmonics", type=bc.count("a number of harmonics >= 8", lo=8, hi=1000), default=None,
                   metavar="K", help="revolution harmonics 2…K of both channels (default: `ringfit estimate --state`'s, "
                        "with its fall-back to 40 where the model's form error shows above)")
    args = p.parse_args(argv)
    if args.quick:
        args.seeds, args.blind, args.seconds = args.seeds[:1], 2, 4.0
    return args


# --------------------------------------------------------------------------- statistics
def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    from scipy import stats

    a = 1 - level
    lo = stats.beta.ppf(a / 2, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(1 - a / 2, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def coverage_text(k: int, n: int) -> str:
    if n == 0:
        return "–"
    lo, hi = clopper_pearson(k, n)
    verdict = "met" if 0.90 <= k / n <= 0.98 else "MISSED"
    return f"{k}/{n} = {100 * k / n:.1f} % [{100 * lo:.1f}, {100 * hi:.1f}] {verdict}"


# --------------------------------------------------------------------------- reading a recording
def read_state(path: Path, tyre, steps: int = 1, fixed: dict | None = None, settings=None):
    """``(load estimate, state estimate, per-revolution state, CPU s of the per-revolution stage, of the averaged
    fits, the averaged fit's quantities before a drift's fit on stretches)`` of one continuous recording, read as
    ``ringfit estimate --state`` does."""
    from ringfit.fit.estimate import state as st
    from ringfit.io.continuous import read_continuous

    record = read_continuous(path)
    geometry, ring, laws = tyre.geometry, tyre.ring, tyre.laws
    c0 = time.process_time()
    from ringfit.fit.estimate.problem import EstimateSettings

    if settings is None:
        from ringfit.fit.estimate.state import STATE_K_MAX

        settings = EstimateSettings(k_max=STATE_K_MAX)
    data = _recording_revolutions(record, geometry, settings.k_max)
    c1 = time.process_time()
    omega = 2 * math.pi * float(np.mean(data.rotation_hz))
    from ringfit.fit.estimate.load import estimate_load

    load = estimate_load(data.profile, geometry, ring, omega=omega, omega_source=data.rotation_source,
                         response=data.response, noise_per_angle=data.noise, noise_source=data.noise_source,
                         ring_covariance=tyre.covariance, settings=settings)
    state = st.estimate_state(data.profile, geometry, ring, laws, omega=omega, omega_source=data.rotation_source,
                              response=data.response, ring_covariance=tyre.covariance, load=load, fixed=fixed,
                              settings=settings)
    c2 = time.process_time()
    rows = np.concatenate([data.rows, data.rows_tangential], axis=1)
    revs = st.state_revolutions(rows, data.rotation_hz, state, revolution=data.revolution, t_s=data.t_s, steps=steps)
    c3 = time.process_time()
    # as estimate_recording_state: a drifting recording refitted on stretches (an averaged fit's cost)
    averaged = state.quantities  # the averaged fit's alone, for the comparison (drifting_state leaves them)
    state, revs = st.drifting_state(data, state, revs, geometry, ring, laws, settings=settings,
                                    ring_covariance=tyre.covariance, steps=steps, rows=rows)
    c4 = time.process_time()
    return load, state, revs, (c1 - c0) + (c3 - c2), (c2 - c1) + (c4 - c3), averaged


def _recording_revolutions(record, geometry, k_max):
    """One pass over the recording for both channels (``ringfit estimate --state``'s)."""
    from ringfit.fit.estimate.revolutions import recording_revolutions

    return recording_revolutions(record, geometry=geometry, tangential=True, k_max=k_max, clamp=True)


def truth_table(path: Path) -> dict:
    with open(path) as f:
        rows = list(csv.DictReader(f))
    return {k: np.array([float(r[k]) for r in rows]) for k in rows[0]}


def truth_over(truth: dict, key: str, t0: float, t1: float) -> float:
    """The time-weighted mean of the simulator's per-revolution ``key`` over [t0, t1] (each simulated revolution
    holds its state from its first to its last sample)."""
    a, b = truth["t_start_s"], np.append(truth["t_start_s"][1:], truth["t_end_s"][-1])
    w = np.clip(np.minimum(b, t1) - np.maximum(a, t0), 0.0, None)
    if w.sum() <= 0:
        return math.nan
    return float(np.sum(w * truth[key]) / w.sum())


def error_of(q: str, est: float, true: float, true_load: float) -> float:
    if q in ("load", "pressure", "speed"):
        return 100 * (est / true - 1)
    if q == "fx":
        return 100 * (est - true) / true_load
    return est - true  # tread depth [mm]


def identified_tyre(folder: Path) -> Path:
    """The tyre file a user identifies from the example's ``calibration/`` (docs/formats.md §6, §18):
    :func:`ringfit.synth.examples.calibration_case` (the flat-road recordings at the tyre file's tread depth averaged
    into profiles, the free tables), then ``ringfit identify``. Cached in ``folder/identified/`` (the case folder
    and ``identified.tyre.toml``; delete it to identify again)."""
    import shutil

    from ringfit.cli import main
    from ringfit.synth.examples import calibration_case

    out = folder / "identified" / "identified.tyre.toml"
    if out.is_file():
        return out
    case = folder / "identified" / "case"
    if case.exists():
        shutil.rmtree(case)
    calibration_case(folder, case)
    tmp = out.with_name("tmp.tyre.toml")
    if main(["identify", str(case), "--out", str(tmp), "--quiet", "--force"]) != 0:
        raise RuntimeError(f"{folder.name}: ringfit identify failed on {case}")
    tmp.replace(out)
    return out


# --------------------------------------------------------------------------- the blind check
def blind():
    from ringfit.io.tyre import read_tyre
    from ringfit.synth.state import RATED_LOAD, write_state_example

    quantities = list(TARGETS)
    avg = {q: [] for q in quantities}       # (error, inside, status)
    per = {q: [] for q in quantities}       # arrays of errors, inside per revolution
    per_told = {q: [] for q in quantities}
    onestep = {q: [] for q in quantities}   # the value the other side of its grid extrapolation (§13.4): diagnostic
    spread = {q: [] for q in quantities}    # the estimate's own σ, in the error's unit: what the data could tell
    speed_rows, sim_cpu, lines, drift_rows, true_loads = [], 0.0, [], [], []
    alone = {q: [] for q in quantities}     # the averaged fit alone (before a drift's stretches): (error, inside)
    print(f"\n1. Blind state on the independent simulator: seeds {ARGS.seeds}, {ARGS.blind} blind recordings of "
          f"{ARGS.seconds:g} s each; tyre: " + ("the example's NOMINAL tyre.toml (the truth is jittered around it; "
                                                "its laws are the nominal ones, not the truth's)" if ARGS.tyre ==
                                                "nominal" else "the tyre file `ringfit identify` writes from the "
                                                "example's calibration/ (what a user reads with)" if ARGS.tyre ==
                                                "identified" else "the TRUE tyre file (a diagnosis, not a user's case)")
          + (f"; held at the truth: {', '.join(ARGS.hold)}" if ARGS.hold else ""))
    from ringfit.fit.estimate.problem import EstimateSettings

    from ringfit.fit.estimate.state import STATE_K_MAX

    settings = EstimateSettings(k_max=STATE_K_MAX if ARGS.harmonics is None else ARGS.harmonics)
    print(f"   harmonics 2…{settings.k_max} of both channels, model grid {settings.n_grid}")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in ARGS.seeds:
            folder = (ARGS.examples or Path(tmp)) / f"seed{seed}-b{ARGS.blind}-{ARGS.seconds:g}s"
            if not (folder / "README.md").is_file():  # written in full (its README comes last)
                folder.mkdir(parents=True, exist_ok=True)
                c = time.process_time()
                write_state_example(folder, seed=seed, blind=ARGS.blind, seconds=ARGS.seconds, overwrite=True)
                sim_cpu += time.process_time() - c
            if ARGS.tyre == "identified":
                c = time.process_time()
                tyre = read_tyre(identified_tyre(folder))
                print(f"   {folder.name}: identified from calibration/ ({time.process_time() - c:.0f} s CPU here; "
                      f"cached in {folder.name}/identified/)")
            else:
                tyre = read_tyre(folder / ("tyre.toml" if ARGS.tyre == "nominal" else "truth/tyre.truth.toml"))
            if tyre.laws.tread_depth_new is None:  # an example kept (--examples) from before the key
                print(f"   WARNING: {folder.name}'s tyre file has no tread_depth_new_mm: the tread depth is not "
                      "bounded by the new tread's (docs/physics.md §13.3); delete the folder to rewrite it")
            for path in sorted((folder / "blind").glob("*.records.npz")):
                name = path.name.removesuffix(".records.npz")
                truth = truth_table(folder / "truth" / f"{name}.truth.csv")
                fixed = {}
                if "pressure" in ARGS.hold:
                    fixed["pressure_pa"] = 1e5 * float(np.mean(truth["pressure_bar"]))
                if "tread" in ARGS.hold:
                    fixed["tread_depth_m"] = 1e-3 * float(np.mean(truth["tread_depth_mm"]))
                w = time.perf_counter()
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    load, state, revs, cpu_rev, cpu_avg, averaged = read_state(path, tyre, ARGS.steps, fixed,
                                                                                   settings)
                wall = time.perf_counter() - w
                speed_rows.append((len(revs), cpu_rev, cpu_avg, wall))
                t_lo, t_hi = float(truth["t_start_s"][0]), float(truth["t_end_s"][-1])
                true_load = truth_over(truth, "load_n", t_lo, t_hi)
                wider = "".join(f" (κ {v:.1f} on 2…{k})" for k, v in (state.band_kappa or {}).items())
                drifted = any(f.startswith("the state drifted") for f in state.flags)
                drift_rows.append(drifted)
                true_loads.append(true_load)
                line = [f"   s{seed} {name}: {len(revs)} rev, {state.status}, 2…{state.k_max} κ {state.discrepancy:.1f}"
                        f"{wider}{' DRIFT' if drifted else ''}"]
                for q in quantities:
                    key = KEYS[q]
                    Q = state.quantities[key]
                    true = truth_over(truth, key, t_lo, t_hi)
                    e = error_of(q, Q["value"], true, true_load)
                    avg[q].append((e, Q["lo"] <= true <= Q["hi"], Q["status"]))
                    spread[q].append(abs(error_of(q, Q["value"] + Q["sd"], true, true_load) - e))
                    if state.grid_check is not None:
                        g = state.to_record()["fit"]["grid_check"]
                        # the other side of Richardson's extrapolation: without it where ringfit applied it, with it
                        # where it did not
                        moved = Q["value"] + (-1.0 if g.get("applied") else 1.0) * g["shift"][key]
                        onestep[q].append(error_of(q, moved, true, true_load))
                    line.append(f"{q} {e:+.2f}{'' if Q['lo'] <= true <= Q['hi'] else '!'}"
                                f"{'' if Q['status'] == 'estimated' else '(' + Q['status'] + ')'}"
                                f" ±{spread[q][-1]:.2f}")
                    # per revolution
                    period = 1.0 / revs.rotation_hz
                    tv = np.array([truth_over(truth, key, t - p / 2, t + p / 2) for t, p in zip(revs.t_s, period)])
                    tl = np.array([truth_over(truth, "load_n", t - p / 2, t + p / 2)
                                   for t, p in zip(revs.t_s, period)])
                    ok = np.isfinite(tv)
                    er = np.array([error_of(q, a, b, c) for a, b, c in zip(revs.values[key][ok], tv[ok], tl[ok])])
                    inside = (revs.lo[key][ok] <= tv[ok]) & (tv[ok] <= revs.hi[key][ok])
                    per[q].append((er, inside))
                    if Q["status"] == "estimated":
                        per_told[q].append((er, inside))
                lines.append(" ".join(line))
                print(lines[-1], flush=True)
                before = []
                for q in quantities:
                    key = KEYS[q]
                    A, true = averaged[key], truth_over(truth, key, t_lo, t_hi)
                    e = error_of(q, A["value"], true, true_load)
                    alone[q].append((e, A["lo"] <= true <= A["hi"]))
                    before.append(f"{q} {e:+.2f}{'' if A['lo'] <= true <= A['hi'] else '!'}")
                if state.stretches is not None:
                    print(f"      (the averaged fit alone: {' '.join(before)})", flush=True)
    print("   (error: load, pressure, speed in %, Fx in % of Fz, tread in mm; '!' the truth outside the 95 % "
          "interval; (not told)/(fixed) the estimate's status)")
    print(f"\n   {'quantity':10s} {'target':>10s} | {'averaged: median |err|':>22s} {'bias':>7s}  {'coverage 95 %':38s}|"
          f" {'per revolution: median |err|':>28s} {'bias':>7s}  coverage 95 %")
    for q in quantities:
        tgt, unit = TARGETS[q]
        if all(a[2] == "fixed" for a in avg[q]):
            print(f"   {q:10s} {tgt:>5g} {unit:>4s} | held at the truth (--hold): not estimated")
            continue
        ea = np.array([a[0] for a in avg[q]])
        ka = sum(bool(a[1]) for a in avg[q])
        told = [a for a in avg[q] if a[2] == "estimated"]
        er = np.concatenate([p[0] for p in per[q]]) if per[q] else np.zeros(0)
        inside = np.concatenate([p[1] for p in per[q]]) if per[q] else np.zeros(0, bool)
        ma, mr = float(np.median(np.abs(ea))), float(np.median(np.abs(er)))
        print(f"   {q:10s} {tgt:>5g} {unit:>4s} | {ma:>15.3f} {'met' if ma <= tgt else 'MISSED':>6s} {np.median(ea):+7.3f}"
              f"  {coverage_text(ka, len(ea)):38s}| {mr:>21.3f} {'met' if mr <= tgt else 'MISSED':>6s} "
              f"{np.median(er):+7.3f}  {coverage_text(int(inside.sum()), inside.size)}")
        if len(told) < len(ea):
            et = np.array([a[0] for a in told])
            kt = sum(bool(a[1]) for a in told)
            pt = np.concatenate([p[0] for p in per_told[q]]) if per_told[q] else np.zeros(0)
            it = np.concatenate([p[1] for p in per_told[q]]) if per_told[q] else np.zeros(0, bool)
            print(f"   {'  told':10s} {'':>10s} | {len(told)}/{len(ea)} recordings 'estimated': "
                  f"{(float(np.median(np.abs(et))) if len(et) else math.nan):.3f} {coverage_text(kt, len(et))} | "
                  f"per rev {(float(np.median(np.abs(pt))) if pt.size else math.nan):.3f} "
                  f"{coverage_text(int(it.sum()), it.size)}")
    print("   (per-revolution coverage pools revolutions that share one recording's bias: its Clopper–Pearson "
          "interval is narrower than the evidence; the averaged coverage counts recordings)")
    print("   the estimates' own σ (median over the recordings; a calibrated estimate's median |error| is about 0.67 σ, "
          "so a target below that is below what these recordings tell): " + ", ".join(
              f"{q} {float(np.median(spread[q])):.3f}" for q in quantities if spread[q]))
    if true_loads:  # light loads: where one accelerometer tells the state least (the patch is short)
        light = np.array(true_loads) < 0.5 * RATED_LOAD
        parts = []
        for q in quantities:
            e, sd = np.abs([a[0] for a in avg[q]]), np.array(spread[q])
            inside = np.array([bool(a[1]) for a in avg[q]])
            parts.append(" / ".join(f"{float(np.median(e[m])):.3f} (σ {float(np.median(sd[m])):.3f}, "
                                    f"{int(inside[m].sum())}/{int(m.sum())})" if m.any() else "—"
                                    for m in (light, ~light)))
        print(f"   by the true load, below / at or above half the rated load ({0.5 * RATED_LOAD:.0f} N; "
              f"{int(light.sum())} / {int((~light).sum())} recordings): median |err| (median σ, covered): "
              + ", ".join(f"{q} {t}" for q, t in zip(quantities, parts)))
    if drift_rows:  # the drift flag (docs/physics.md §13.6): coverage of the flagged and the steady recordings
        flagged = np.array(drift_rows)
        parts = []
        for q in quantities:
            inside = np.array([bool(a[1]) for a in avg[q]])
            parts.append(f"{q} {int(inside[flagged].sum())}/{int(flagged.sum())} vs "
                         f"{int(inside[~flagged].sum())}/{int((~flagged).sum())}")
        print(f"   drift flag ('the state drifted within the recording'): {int(flagged.sum())} of {flagged.size} "
              "recordings; coverage flagged vs not: " + ", ".join(parts))
    if any(alone[q] for q in quantities):  # what the drifting recordings' fit on stretches changed
        print("   the averaged fit alone (no fit on stretches; docs/physics.md §13.4 *a drifting state*): " + ", ".join(
            f"{q} median |err| {float(np.median(np.abs([a[0] for a in alone[q]]))):.3f}, "
            f"{sum(bool(a[1]) for a in alone[q])}/{len(alone[q])} covered" for q in quantities))
    if any(onestep.values()):
        print("   the value the other side of Richardson's extrapolation (docs/physics.md §13.4 *the model's grid*; "
              "without it where ringfit applies it; a diagnostic): median |err| " + ", ".join(
                  f"{q} {float(np.median(np.abs(onestep[q]))):.3f}" for q in quantities if onestep[q]))
    R = sum(r[0] for r in speed_rows)
    c_rev = sum(r[1] for r in speed_rows)
    c_avg = sum(r[2] for r in speed_rows)
    wall = sum(r[3] for r in speed_rows)
    print(f"\n2. Speed over {len(speed_rows)} recordings, {R} revolutions "
          f"({len(os.sched_getaffinity(0))} core(s) visible, XLA threads as configured):")
    print(f"   per-revolution stage (pass over both channels + the linearised step): {R / c_rev:.0f} revolutions per "
          f"CPU second ({c_rev:.2f} s CPU) {'met' if R / c_rev >= 500 else 'MISSED'} (target ≥ 500)")
    print(f"   end to end (+ the averaged load and state fits, once per recording, {c_avg:.1f} s CPU; "
          f"{wall:.1f} s wall in all): {R / (c_rev + c_avg):.0f} revolutions per CPU second")
    print(f"   (the simulator took {sim_cpu:.1f} s CPU; not counted)")


# --------------------------------------------------------------------------- the Fisher table
def fisher_table():
    """σ per revolution of each quantity over the speed × load grid (nominal example tyre, p_ref, d = 5 mm,
    κ = 0.005), the nuisances free, data alone."""
    from ringfit.fit.estimate.state import (PRESSURE_PRIOR_SD, SLIP_PRIOR_SD, TREAD, TREAD_PRIOR_SD,
                                            state_fisher)
    from ringfit.physics.state import TyreState
    from ringfit.synth.state import RATED_LOAD, nominal_tyre
    from ringfit.units import KMH

    from ringfit.io.tyre import read_tyre, write_tyre

    with tempfile.TemporaryDirectory() as tmp:  # the example's tyre.toml, read as a user's file
        write_tyre(nominal_tyre().tyre_file("example tyre (nominal)"), Path(tmp) / "tyre.toml")
        tyre = read_tyre(Path(tmp) / "tyre.toml")
    geometry, ring, laws = tyre.geometry, tyre.ring, tyre.laws
    depth, slip = 0.005, 0.005
    rout = float(geometry.radius) + float(geometry.tread_thickness) + (depth - float(laws.tread_depth_ref))
    print(f"\n3. Fisher table (state_fisher): σ of ONE revolution, nominal example tyre at p_ref "
          f"{geometry.pressure / 1e5:.2f} bar, tread {1e3 * depth:g} mm, κ = {slip:g}; white noise σ = "
          f"{100 * FISHER_NOISE_SHARE:g} % of Ω²R_out per sample in each channel, {FISHER_SAMPLES} samples per "
          "revolution; nuisances (gain, tangential gain, angle offset, high-pass corner, tilt, liner offset) free; "
          "the data alone (no priors). "
          "'*': σ wider than the estimate's weak prior (§13.4): not told by one revolution. 'd held': the tread depth "
          "stated (known from the wear history). '10 s': σ/√R over the R revolutions of 10 s at that speed.")
    print(f"   {'':14s} | {'per revolution, d free':^43s} | {'d held':^20s} | {'10 s, d free':^21s} |")
    print(f"   {'km/h':>5s} {'Fz/rated':>8s} | {'Fz %':>7s} {'p %':>7s} {'Fx %Fz':>8s} {'V %':>7s} {'d mm':>8s} | "
          f"{'Fz %':>6s} {'p %':>6s} {'V %':>6s} | {'R':>4s} {'Fz %':>7s} {'d mm':>7s} | "
          f"{'ρ(Fz,p)':>7s} {'ρ(Fz,d)':>7s} {'ρ(d,V)':>7s}")
    c = time.process_time()
    rows = []

    def star(x, fmt, told):
        return format(x, fmt) + ("" if told else "*")

    for v in FISHER_SPEEDS:
        for lf in FISHER_LOADS:
            load = lf * RATED_LOAD
            omega = v * KMH / rout
            noise = FISHER_NOISE_SHARE * omega**2 * rout
            state = TyreState(load, float(geometry.pressure), depth, slip, omega)
            f = state_fisher(geometry, ring, laws, state, noise, samples_per_revolution=FISHER_SAMPLES)
            t = f.table()
            held = state_fisher(geometry, ring, laws, state, noise, samples_per_revolution=FISHER_SAMPLES,
                                fixed=(TREAD,)).table()
            revs = int(10.0 * omega / (2 * math.pi))
            sd_p = t["pressure_bar"]["sd"] / t["pressure_bar"]["value"]
            sd_d = t["tread_depth_mm"]["sd"] / t["tread_depth_mm"]["value"]
            row = dict(speed=v, load=lf, load_pct=t["load_n"]["sd_pct"], p_pct=100 * sd_p,
                       fx_pct=100 * t["fx_n"]["sd"] / load, v_pct=t["speed_kmh"]["sd_pct"],
                       d_mm=t["tread_depth_mm"]["sd"], load_held=held["load_n"]["sd_pct"],
                       p_held=held["pressure_bar"]["sd_pct"], v_held=held["speed_kmh"]["sd_pct"], revs=revs,
                       r_lp=f.corr("load_n", "pressure_bar"), r_ld=f.corr("load_n", "tread_depth_mm"),
                       r_dv=f.corr("tread_depth_mm", "speed_kmh"), p_told=sd_p < PRESSURE_PRIOR_SD,
                       d_told=sd_d < TREAD_PRIOR_SD, k_told=t["slip"]["sd"] < SLIP_PRIOR_SD,
                       d_told_10s=sd_d / math.sqrt(revs) < TREAD_PRIOR_SD)
            rows.append(row)
            print(f"   {v:5.0f} {lf:8.1f} | {row['load_pct']:7.2f} {star(row['p_pct'], '7.2f', row['p_told'])} "
                  f"{star(row['fx_pct'], '8.2f', row['k_told'])} {row['v_pct']:7.3f} "
                  f"{star(row['d_mm'], '8.2f', row['d_told'])} | {row['load_held']:6.2f} {row['p_held']:6.2f} "
                  f"{row['v_held']:6.3f} | {revs:4d} {row['load_pct'] / math.sqrt(revs):7.3f} "
                  f"{star(row['d_mm'] / math.sqrt(revs), '7.3f', row['d_told_10s'])} | {row['r_lp']:+7.3f} "
                  f"{row['r_ld']:+7.3f} {row['r_dv']:+7.3f}", flush=True)
    print(f"   ({len(rows)} states in {time.process_time() - c:.1f} s CPU)")
    return rows


def main():
    global ARGS
    ARGS = parse_args()
    import jax

    bc.start(f"bench_state: JAX {jax.__version__} on {jax.devices()[0].platform}, float64"
             + (" [--quick]" if ARGS.quick else ""))
    if not ARGS.fisher_only:
        blind()
    if ARGS.fisher or ARGS.fisher_only:
        fisher_table()
    bc.finish()


if __name__ == "__main__":
    main()
