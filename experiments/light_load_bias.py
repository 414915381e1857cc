"""Why do light loads come out high? (issue 22 item 5). Noise-free profiles of known load, estimated.

    python experiments/light_load_bias.py grid      # truth grid × estimator grid, loads 1.5–6 kN
    python experiments/light_load_bias.py radius    # speed_kmh only (Ω from R_e) against rotation_hz
    python experiments/light_load_bias.py staircase # the load–shape map of the estimator's grid, load by load
    python experiments/light_load_bias.py fd        # truth from an independent finite-difference discretisation
    python experiments/light_load_bias.py refine    # the load shift when the estimator's grid is doubled, against the FD error

Each case: the one forward model on a fine grid (the truth: flat road, no gravity, no high-pass, no tilt,
no noise other than 1e-4 of the reading so that the noise weights are defined), written at 2048 angles
with ``rotation_hz`` in the sidecar; :func:`ringfit.fit.estimate.estimate_load` with the estimator's grid.
Printed: the signed load error, the interval's half-width and whether it covers.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

sys.path.insert(0, str(__import__("pathlib").Path(__file__).resolve().parents[1] / "benchmarks"))
import ringfit  # noqa: F401,E402  (float64)
from _independent_ring import fd_profile as independent_fd_profile  # noqa: E402
from ringfit.fit.estimate import EstimateSettings, estimate_load
from ringfit.io.profiles import Profile
from ringfit.params import table9
from ringfit.physics.contact import ContactSolver
from ringfit.physics.profile import ProfileModel, simulate_profile
from ringfit.units import KMH

GEOMETRY, RING = table9()
MODEL = ProfileModel().with_sensor(gravity=0.0, corner_hz=0.0, tilt_gain=0.0)
LOADS = (1500.0, 2000.0, 2500.0, 3000.0, 4500.0, 6000.0)


def truth(load, grid, *, speed=60.0, drum=None, with_rate=True, noise=1e-4, seed=0):
    prof = simulate_profile(RING, GEOMETRY, speed_kmh=speed, load_n=load, drum_diameter_m=drum, model=MODEL,
                            solver=ContactSolver(n_grid=grid), n_points=2048)
    rng = np.random.default_rng(seed)
    ch = prof.channels + noise * np.max(np.abs(prof.channels[0])) * rng.standard_normal(prof.channels.shape)
    cond = {k: v for k, v in prof.condition.items() if k != "load_n"}
    if not with_rate:
        cond.pop("rotation_hz")
    return Profile(prof.angle_deg, ch[0], ch[1], condition=cond, source=f"truth {load:g} N M={grid}")


def line(label, load, est, dt):
    err = est.load_n / load - 1
    half = 0.5 * (est.hi - est.lo) / est.load_n
    print(f"{label:<28s} load {load:6.0f} N  error {100 * err:+6.3f} %  half-width {100 * half:5.3f} %  "
          f"covers {'yes' if est.lo < load < est.hi else 'NO '}  patch {est.patch['length_mm']:6.1f} mm  "
          f"{dt:5.1f} s", flush=True)
    return err


def grid():
    for t_grid in (2048, 8192):
        for e_grid in (512, 1024, 2048):
            settings = EstimateSettings(n_grid=e_grid)
            for load in LOADS:
                t0 = time.perf_counter()
                est = estimate_load(truth(load, t_grid), GEOMETRY, RING, settings=settings)
                line(f"truth M={t_grid} est M={e_grid}", load, est, time.perf_counter() - t0)


def radius():
    """The rolling-radius convention: a truth at 20 km/h with gravity, a 1 Hz high-pass and tilt 1, whose
    wheel turns at V/R_e' for another convention R_e' (the loaded radius R_out − δ, or the free radius
    R_out), its sidecar giving only ``speed_kmh``: the estimator takes Ω = V/R_e with R_e = R_out − δ/3
    (docs/physics.md §4.3), so Ω is off by up to 2δ/3R; the gain absorbs Ω² and only the high-pass and
    gravity's share see it."""
    from ringfit.physics.profile import effective_rolling_radius

    speed = 20.0
    model = ProfileModel().with_sensor(gravity=9.81, corner_hz=1.0, tilt_gain=1.0)
    r_out = float(GEOMETRY.outer_radius)
    for load in (1500.0, 2000.0, 3000.0, 6000.0):
        r_e = float(effective_rolling_radius(RING, GEOMETRY, load, None))
        delta = 3 * (r_out - r_e)
        for label, radius_m in (("same convention", r_e), ("R_out − δ", r_out - delta), ("free radius R_out", r_out)):
            rot = speed * KMH / radius_m / (2 * math.pi)
            prof = simulate_profile(RING, GEOMETRY, speed_kmh=speed, load_n=load, rotation_hz=rot, model=model,
                                    solver=ContactSolver(n_grid=2048), n_points=2048)
            cond = {k: v for k, v in prof.condition.items() if k not in ("load_n", "rotation_hz")}
            ch = prof.channels + 1e-4 * np.max(np.abs(prof.channels[0])) * np.random.default_rng(0).standard_normal(
                prof.channels.shape)
            t0 = time.perf_counter()
            est = estimate_load(Profile(prof.angle_deg, ch[0], ch[1], condition=cond, source="radius"), GEOMETRY, RING)
            line(f"{label} (Ω {100 * (r_e / radius_m - 1):+.2f} %)", load, est, time.perf_counter() - t0)


def staircase():
    """Loads 1500–2100 N in 25 N steps, truth M = 8192, estimator 512: error against load."""
    for load in np.arange(1500.0, 2101.0, 25.0):
        t0 = time.perf_counter()
        est = estimate_load(truth(float(load), 8192), GEOMETRY, RING)
        line("staircase est M=512", float(load), est, time.perf_counter() - t0)


# ----------------------------------------------------------------------------- independent discretisation


def fd_profile(load, n, *, order=4, omega=2 * math.pi * 9.0):
    """A :class:`Profile` of :func:`_independent_ring.fd_profile` (Table 9 ring, 60 km/h nominal, Ω given)."""
    from ringfit.io.profiles import grid_angles_deg

    _, reading = independent_fd_profile(RING, GEOMETRY, load, n, order=order, omega=omega)
    cond = {"speed_kmh": 60.0, "pressure_bar": 2.2, "rotation_hz": omega / (2 * math.pi), "revolutions": 1}
    return Profile(grid_angles_deg(n), reading, np.zeros(n), condition=cond, source=f"FD{order} n={n} {load:g} N")


def fd():
    """Truth from the FD discretisation (orders 2 and 4, n = 1024 and 4096); estimator M = 512 on the same ring
    without damping (the FD truth has none)."""
    ring = RING.replace(damping_ratio=0.0)
    for order, n in ((4, 4096), (4, 1024), (2, 4096), (2, 1024)):
        for load in LOADS:
            t0 = time.perf_counter()
            est = estimate_load(fd_profile(load, n, order=order), GEOMETRY, ring)
            line(f"FD{order} n={n} est M=512", load, est, time.perf_counter() - t0)


def refine():
    """FD4 truths (n = 4096) at light loads in 50 N steps and the heavier ones: the estimator's error (M = 512)
    beside its own grid-refinement shift (M = 512 → 1024, :func:`ringfit.fit.estimate.load.grid_shift`)."""
    ring = RING.replace(damping_ratio=0.0)
    for load in (*np.arange(1500.0, 2101.0, 50.0), 3000.0, 4500.0, 6000.0):
        est = estimate_load(fd_profile(float(load), 4096), GEOMETRY, ring)
        err = est.load_n / load - 1
        shift = est.grid_check["load_shift_pct"] / 100  # ringfit.fit.estimate.load.grid_shift, M = 512 → 1024
        print(f"FD4 n=4096  load {load:6.0f} N  error {100 * err:+6.3f} %  grid shift M→2M {100 * shift:+6.3f} %  "
              f"error after the shift {100 * ((1 + err) * (1 + shift) - 1):+6.3f} %  half-width "
              f"{50 * (est.hi - est.lo) / est.load_n:5.3f} %", flush=True)


if __name__ == "__main__":
    {"grid": grid, "radius": radius, "staircase": staircase, "fd": fd, "refine": refine}[sys.argv[1]]()
