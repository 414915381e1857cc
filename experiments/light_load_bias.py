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

import ringfit  # noqa: F401  (float64)
from ringfit.fit.estimate import EstimateSettings, estimate_load
from ringfit.io.profiles import Profile
from ringfit.params import table9
from ringfit.physics.contact import ContactSolver
from ringfit.physics.profile import ProfileModel, simulate_profile

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
    for with_rate in (True, False):
        for load in LOADS:
            t0 = time.perf_counter()
            est = estimate_load(truth(load, 2048, with_rate=with_rate), GEOMETRY, RING)
            line("rotation_hz" if with_rate else "speed_kmh only", load, est, time.perf_counter() - t0)


def staircase():
    """Loads 1500–2100 N in 25 N steps, truth M = 8192, estimator 512: error against load."""
    for load in np.arange(1500.0, 2101.0, 25.0):
        t0 = time.perf_counter()
        est = estimate_load(truth(float(load), 8192), GEOMETRY, RING)
        line("staircase est M=512", float(load), est, time.perf_counter() - t0)


# ----------------------------------------------------------------------------- independent discretisation


def _stencils(n, h, order):
    """Periodic central finite-difference matrices d/dφ … d⁴/dφ⁴ (order 2 or 4)."""
    import scipy.sparse as sp

    def st(coeffs, scale):
        rows = np.concatenate([np.arange(n)] * len(coeffs))
        cols = np.concatenate([(np.arange(n) + k) % n for k in coeffs])
        vals = np.concatenate([np.full(n, c / scale) for c in coeffs.values()])
        return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))

    if order == 4:
        return (st({-2: 1, -1: -8, 1: 8, 2: -1}, 12 * h), st({-2: -1, -1: 16, 0: -30, 1: 16, 2: -1}, 12 * h**2),
                st({-3: 1, -2: -8, -1: 13, 1: -13, 2: 8, 3: -1}, 8 * h**3),
                st({-3: -1, -2: 12, -1: -39, 0: 56, 1: -39, 2: 12, 3: -1}, 6 * h**4))
    return (st({-1: -1, 1: 1}, 2 * h), st({-1: 1, 0: -2, 1: 1}, h**2), st({-2: -1, -1: 2, 1: -2, 2: 1}, 2 * h**3),
            st({-2: 1, -1: -4, 0: 6, 1: -4, 2: 1}, h**4))


def fd_profile(load, n, *, order=4, omega=2 * math.pi * 9.0, ea=1e9, window_deg=35.0):
    """The radial reading of the steady rolling ring on a flat road, written independently of ringfit:
    §4.1's steady equations (χ = 1, a membrane penalty EA for inextensibility, no damping) by central
    finite differences in φ on n points, the §4.3 tread-spring law (radial springs, s = H/cos φ) with Fz
    imposed, a plain active-set loop, and §4.6's a_r = Ω²(w″ − 2v′ − w) (spectral derivatives of the FD
    solution). No gravity, no high-pass, sensor on the belt."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    R, b, p0, tau = float(GEOMETRY.radius), float(GEOMETRY.width), float(GEOMETRY.pressure), float(GEOMETRY.tread_thickness)
    rho_a, ei, kw, kv, ktrd = (float(getattr(RING, k)) for k in ("rho_a", "ei", "kw", "kv", "k_tread"))
    P = p0 * b / R
    h = 2 * np.pi / n
    phi = -np.pi + h * np.arange(n)
    d1, d2, d3, d4 = _stencils(n, h, order)
    eye = sp.identity(n)
    m = ea / R**2 - rho_a * omega**2
    b4 = ei / R**4
    L = sp.bmat([[b4 * d4 + m * eye - P * (d2 + eye) + kw * eye, -b4 * d3 + m * d1],
                 [b4 * d3 - m * d1, -b4 * d2 - m * d2 + kv * eye]]).tocsc()
    lu = spla.splu(L)
    win = np.flatnonzero(np.abs(phi) <= math.radians(window_deg))
    rhs = np.zeros((2 * n, win.size))
    rhs[win, np.arange(win.size)] = -1.0
    resp = lu.solve(rhs)
    A = resp[:n][win]
    phik = phi[win]
    active = np.abs(phik) < 0.1
    for _ in range(60):
        k_idx = np.flatnonzero(active)
        sysm = np.zeros((k_idx.size + 1, k_idx.size + 1))
        sysm[:-1, :-1] = np.eye(k_idx.size) - ktrd * A[np.ix_(k_idx, k_idx)]
        sysm[:-1, -1] = ktrd / np.cos(phik[k_idx])
        sysm[-1, :-1] = R * h * np.cos(phik[k_idx])
        x = np.linalg.solve(sysm, np.append(np.full(k_idx.size, ktrd * (R + tau)), load))
        p = np.zeros(win.size)
        p[k_idx] = x[:-1]
        new = (R + tau + A @ p - x[-1] / np.cos(phik)) > 0
        if np.array_equal(new, active):
            break
        active = new
    wv = resp @ p
    w, v = wv[:n], wv[n:]
    k = np.fft.rfftfreq(n, 1.0 / n)
    W, V = np.fft.rfft(w), np.fft.rfft(v)
    a_r = omega**2 * np.fft.irfft(-(k**2) * W - 2j * k * V - W, n)
    reading = -a_r  # toward the centre +, DC (−Ω²R) left out: the estimator fits k ≥ 2
    cond = {"speed_kmh": 60.0, "pressure_bar": 2.2, "rotation_hz": omega / (2 * math.pi), "revolutions": 1}
    from ringfit.io.profiles import grid_angles_deg

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


def grid_shift(est, factor=2):
    """Load shift [relative] of a converged fit when its model grid M is refined to factor·M: one Gauss–Newton
    step from the fit with the coarse Jacobian, on the fine model's residual rows (same data, same weights)."""
    import dataclasses

    from ringfit.fit.engine import linearize, residuals
    from ringfit.fit.estimate import LOAD, estimate_problem

    fit = est.fit
    coarse = fit.problem
    settings = dataclasses.replace(EstimateSettings(), n_grid=factor * coarse.model.solver.n_grid)
    fine = estimate_problem(coarse.data, settings, coarse.model.k_max, coarse.prior)
    lin = linearize(coarse, fit.theta, fit.names)
    r_fine, _ = residuals(fine, fit.theta)
    du = -np.linalg.lstsq(lin.jacobian, r_fine - lin.residuals, rcond=None)[0]
    return float(np.expm1(du[list(lin.names).index(LOAD)]))


def refine():
    """FD4 truths (n = 4096) at light loads in 50 N steps and the heavier ones: the estimator's error (M = 512)
    beside its own grid-refinement shift (M = 512 → 1024)."""
    ring = RING.replace(damping_ratio=0.0)
    for load in (*np.arange(1500.0, 2101.0, 50.0), 3000.0, 4500.0, 6000.0):
        est = estimate_load(fd_profile(float(load), 4096), GEOMETRY, ring)
        err = est.load_n / load - 1
        shift = grid_shift(est)
        print(f"FD4 n=4096  load {load:6.0f} N  error {100 * err:+6.3f} %  grid shift M→2M {100 * shift:+6.3f} %  "
              f"error after the shift {100 * ((1 + err) * (1 + shift) - 1):+6.3f} %  half-width "
              f"{50 * (est.hi - est.lo) / est.load_n:5.3f} %", flush=True)


if __name__ == "__main__":
    {"grid": grid, "radius": radius, "staircase": staircase, "fd": fd, "refine": refine}[sys.argv[1]]()
