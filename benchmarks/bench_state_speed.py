"""The tyre's state per revolution (issue 33): revolutions per CPU second and the per-revolution errors on a
self-consistent recording (the forward model at a known state; the blind figures are bench_state.py's).

Run ``python benchmarks/bench_state_speed.py`` (about a minute on one core). A continuous recording of the one
forward model at 4.2 kN, 2.0 bar, 5 mm, braking at κ = −0.006, 12 Hz, sampled at 511.6 samples per revolution
(a clock not locked to the wheel; ``--samples-per-revolution``) with
white noise (2 m/s² radial, 0.3 m/s² tangential per sample) and a 37° encoder offset, is read once for both
channels (``recording_revolutions(tangential=True)``), its averaged profile's state fitted
(``estimate_state``), and every revolution estimated by the linearised Gauss–Newton step
(``state_revolutions``, warm). Prints revolutions per CPU second (wall beside it) of the pass over the
recording, of the per-revolution step and of both together against the target (≥ 500 per CPU second on one
core), and each quantity's median |error| per revolution with the coverage of its 95 % intervals.
``--revolutions N`` (default 400); ``--quick``: 60 revolutions.
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402


def parse():
    ap = bc.parser(__doc__.split("\n")[0], quick_help="60 revolutions (a smoke run)")
    ap.add_argument("--revolutions", type=bc.count("a number of revolutions >= 10", 10, 10**6), default=400)
    ap.add_argument("--samples-per-revolution", type=float, default=511.6,
                    help="the acquisition's samples per revolution (default 511.6: not locked to the angle)")
    ap.add_argument("--truth-grid", type=bc.count("a number of angles >= 512", 512, 65536), default=2048,
                    help="angles the recording's state is solved on (default 2048)")
    ap.add_argument("--cores", type=bc.count("a number of cores (0: no pinning)", 0, 4096), default=1)
    args = ap.parse_args()
    if args.quick:
        args.revolutions = 60
    return args


def main() -> int:
    args = parse()
    if args.cores:
        os.sched_setaffinity(0, set(sorted(os.sched_getaffinity(0))[: args.cores]))
    import numpy as np

    from ringfit.fit.estimate.revolutions import recording_revolutions
    from ringfit.fit.estimate.state import estimate_state, state_revolutions
    from ringfit.io.continuous import ContinuousRecord
    from ringfit.params import TyreLaws, table9
    from ringfit.physics.contact import ContactSolver
    from ringfit.physics.profile import ProfileModel
    from ringfit.physics.sensor import STANDARD_GRAVITY
    from ringfit.physics.state import TyreState, solve_state
    from ringfit.units import KMH

    print(f"load average at start: {bc.loadavg()}")
    geo, ring = table9()
    laws = TyreLaws(tread_depth_ref=0.008, k_x=15e6, kw_share=0.5, kv_share=0.3, has_tread_depth=True,
                    has_brush=True)
    f_rot = 12.0
    om = 2 * math.pi * f_rot
    # solved on 2048 angles: the model the estimate fits (the 4M model by defect correction, docs/physics.md §13.4)
    _, ch, q = solve_state(geo, ring, laws, TyreState(4200.0, 2.0e5, 0.005, -0.006, om),
                           model=ProfileModel().with_sensor(gravity=STANDARD_GRAVITY, tilt_gain=0.8, corner_hz=0.5),
                           solver=ContactSolver(n_grid=args.truth_grid))
    spec = np.fft.rfft(ch, axis=1) * 2 / ch.shape[1]
    fs = f_rot * args.samples_per_revolution
    t = np.arange(int(args.revolutions * fs / f_rot)) / fs
    ang = -37.0 + 360 * f_rot * t
    w = np.radians(ang) + np.pi
    # harmonics below the acquisition's Nyquist (an anti-aliased acquisition)
    x = sum((spec[:, k, None] * np.exp(1j * k * w[None, :])).real for k in range(1, 256))
    x = x + np.array([[2.0], [0.3]]) * np.random.default_rng(1).standard_normal(x.shape)
    rec = ContinuousRecord(acc=x, axes=("radial", "tangential"), fs_hz=fs, encoder_angle_deg=ang, condition={},
                           source="bench")
    c0, w0 = time.process_time(), time.time()
    from ringfit.fit.estimate.state import STATE_K_MAX

    data = recording_revolutions(rec, k_max=STATE_K_MAX, tangential=True, clamp=True)
    c1, w1 = time.process_time(), time.time()
    state = estimate_state(data.profile, geo, ring, laws, omega=om, response=data.response)
    rows = np.concatenate([data.rows, data.rows_tangential], axis=1)
    state_revolutions(rows[:10], data.rotation_hz[:10], state)  # warm
    c2, w2 = time.process_time(), time.time()
    revs = state_revolutions(rows, data.rotation_hz, state)
    c3, w3 = time.process_time(), time.time()
    R = len(revs)
    print(f"{R} revolutions, {args.samples_per_revolution:g} samples each, both channels")
    print(f"pass over the recording:  {R / (c1 - c0):8.0f} rev per CPU s  ({R / (w1 - w0):.0f} per wall s)")
    print(f"per-revolution step:      {R / (c3 - c2):8.0f} rev per CPU s  ({R / (w3 - w2):.0f} per wall s)")
    both = R / ((c1 - c0) + (c3 - c2))
    print(f"together:                 {both:8.0f} rev per CPU s  target >= 500: {'met' if both >= 500 else 'NOT met'}")
    truth = {"load_n": 4200.0, "pressure_bar": 2.0, "slip": -0.006, "fx_n": q["fx"], "tread_depth_mm": 5.0,
             "speed_kmh": q["speed"] / KMH}
    print(f"{'quantity':16s} {'median |error|':>16s} {'coverage 95 %':>14s} {'mean error / σ':>15s}")
    for key, value in truth.items():
        err = np.abs(revs.values[key] - value)
        rel = f"{100 * np.median(err) / abs(value):.3f} %" if key != "slip" else f"{np.median(err):.2e}"
        if key == "fx_n":
            rel = f"{100 * np.median(err) / 4200.0:.3f} % of Fz"
        if key == "tread_depth_mm":
            rel = f"{np.median(err):.3f} mm"
        cover = np.mean((revs.lo[key] <= value) & (value <= revs.hi[key]))
        sd = (revs.hi[key] - revs.lo[key]) / (2 * 1.959964)
        bias = np.mean(revs.values[key] - value) / np.median(sd)  # a shared offset, against the σ per revolution
        print(f"{key:16s} {rel:>16s} {100 * cover:13.1f}% {bias:+15.2f}")
    print(f"load average at end: {bc.loadavg()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
