"""Steady rolling model: solve, gradient, tread-stiffness fit, scaling with harmonics (issue 4, item 9).

Prints figures; run with ``python benchmarks/bench_rolling.py``. Timings are
warm (after compilation), best of repeated calls on this machine's CPU (the
minimum is robust to other processes sharing the cores; fits: median of 5).
"""

from __future__ import annotations

import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

import ringfit  # noqa: F401  (float64)
from ringfit.fit.rolling import fit_rolling, sum_of_squares, tread_stiffness_sweep
from ringfit.params import table9
from ringfit.physics.contact import ContactSolver, solve_rolling
from ringfit.physics.operating import OperatingPoint
from ringfit.physics.sensor import sensor_signals
from ringfit.synth.profiles import synthetic_profile

GEOMETRY, RING = table9()
OP = OperatingPoint(26.88, 4000.0)


def timed(fn, *args, repeat=200):
    jax.block_until_ready(fn(*args))
    samples = []
    for _ in range(repeat):
        t = time.perf_counter()
        jax.block_until_ready(fn(*args))
        samples.append(time.perf_counter() - t)
    return min(samples)  # best of `repeat`: robust to other load on a shared machine


def solver_functions(M):
    solver = ContactSolver(n_grid=M)

    def solve(k):
        sol = solve_rolling(RING.replace(k_tread=k), GEOMETRY, OP, solver=solver)
        return sol.w, sol.pressure, sol.axle_height

    def loss(k):
        sol = solve_rolling(RING.replace(k_tread=k), GEOMETRY, OP, solver=solver)
        radial, tangential = sensor_signals(sol, GEOMETRY)
        return jnp.sum(radial**2) + jnp.sum(tangential**2)

    return jax.jit(solve), jax.jit(loss), jax.jit(jax.grad(loss)), solver


def main():
    print(f"JAX {jax.__version__} on {jax.devices()[0].platform}, float64")
    k = jnp.asarray(19e6)
    print("\n1-2. one warm steady-state solve with contact, and its gradient (M = 512 grid, 256 harmonics)")
    solve, loss, grad, solver = solver_functions(512)
    t_solve, t_loss, t_grad = timed(solve, k), timed(loss, k), timed(grad, k)
    print(f"   solve (H, p, w on the grid, window K = {solver.window()[1]} points): {1e3 * t_solve:.3f} ms  (target < 1 ms)")
    print(f"   solve + sensor channels + loss:                          {1e3 * t_loss:.3f} ms")
    print(f"   gradient of that loss w.r.t. k_tread (implicit diff.):   {1e3 * t_grad:.3f} ms  "
          f"= {t_grad / t_loss:.2f}× the forward loss, {t_grad / t_solve:.2f}× the solve (target < 3×)")

    print("\n4. scaling with the number of harmonics (warm solve)")
    print(f"   {'M':>6} {'harmonics':>9} {'window K':>8} {'solve [ms]':>11} {'gradient [ms]':>14}")
    for M in (128, 256, 512, 1024, 2048, 4096):
        s, _, g, sv = solver_functions(M)
        rep = 100 if M <= 1024 else 20
        print(f"   {M:>6} {M // 2:>9} {sv.window()[1]:>8} {1e3 * timed(s, k, repeat=rep):>11.3f} "
              f"{1e3 * timed(g, k, repeat=rep):>14.3f}")

    print("\n3. tread-stiffness fit over four speeds (drum, synthetic truth k = 25e6 N/m², 2 m/s² noise)")
    truth = RING.replace(k_tread=25e6)
    profiles = [synthetic_profile(truth, GEOMETRY, v, drum_diameter_m=1.2192, noise_ms2=2.0, seed=i)
                for i, v in enumerate((20.0, 30.0, 40.0, 50.0))]
    t = time.perf_counter()
    res = fit_rolling(profiles, GEOMETRY, RING)
    t_cold = time.perf_counter() - t
    warm = []
    for _ in range(5):
        t = time.perf_counter()
        res = fit_rolling(profiles, GEOMETRY, RING)
        warm.append(time.perf_counter() - t)
    print(f"   cold (compile + fit): {t_cold:.1f} s; warm: {statistics.median(warm):.3f} s (target < 1 s); "
          f"{res.iterations} LM steps, {res.extra['evaluations']} model-evaluation equivalents")
    print(f"   k_tread = {res.values['k_tread']:.5g} ± {res.stderr['k_tread']:.2g} N/m² (truth 2.5e7), "
          f"status {res.status}")

    print("\n   versus the source study's sweep at 50 km/h (k = 10–40 MN/m² in 0.1 MN/m² steps)")
    at50 = profiles[-1:]
    sweep = tread_stiffness_sweep(at50, GEOMETRY, RING, np.arange(10e6, 40.001e6, 0.1e6))
    t = time.perf_counter()
    sweep = tread_stiffness_sweep(at50, GEOMETRY, RING, np.arange(10e6, 40.001e6, 0.1e6))
    t_sweep = time.perf_counter() - t
    fit50 = fit_rolling(at50, GEOMETRY, RING)
    t = time.perf_counter()
    fit50 = fit_rolling(at50, GEOMETRY, RING)
    t_fit50 = time.perf_counter() - t
    print(f"   sweep: {sweep.evaluations} evaluations, best k = {sweep.best:.4g}, SSE {sweep.best_sse:.6g}, "
          f"{t_sweep:.2f} s warm")
    print(f"   fit:   {fit50.extra['evaluations']} evaluation equivalents, k = {fit50.values['k_tread']:.6g}, "
          f"SSE {sum_of_squares(fit50):.6g}, {t_fit50:.3f} s warm")
    print(f"   → {sweep.evaluations / fit50.extra['evaluations']:.0f}× fewer evaluations, "
          f"SSE {'≤' if sum_of_squares(fit50) <= sweep.best_sse else '>'} the sweep's best")


if __name__ == "__main__":
    main()
