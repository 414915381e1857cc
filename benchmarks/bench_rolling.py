"""Steady rolling model: solve, gradient, tread-stiffness fit, scaling with harmonics (issue 4, item 9).

Prints figures; run with ``python benchmarks/bench_rolling.py [--quick]``. Timings are
warm (after compilation), best of repeated calls on this machine's CPU (the
minimum is robust to other processes sharing the cores; fits: median of 5), wall
and CPU (process time) side by side; the load average at the start and the end.
``--quick``: fewer repeats and grids (a smoke run).
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402

import ringfit  # noqa: F401,E402  (float64)
from ringfit.fit.rolling import fit_rolling, sum_of_squares, tread_stiffness_sweep
from ringfit.params import table9
from ringfit.physics.contact import ContactSolver, solve_rolling
from ringfit.physics.operating import OperatingPoint
from ringfit.physics.sensor import sensor_signals
from ringfit.synth.profiles import synthetic_profile

GEOMETRY, RING = table9()
OP = OperatingPoint(26.88, 4000.0)


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


def main(argv=None):
    args = bc.parser(__doc__.splitlines()[0], quick_help="fewer repeats and grids (smoke run)").parse_args(argv)
    rep1 = 10 if args.quick else 200
    bc.start(f"bench_rolling: JAX {jax.__version__} on {jax.devices()[0].platform}, float64"
             + (" [--quick]" if args.quick else ""))
    failures = bc.Failures()
    lines = []  # printed only if nothing failed
    say = lines.append
    k = jnp.asarray(19e6)
    say("\n1-2. one warm steady-state solve with contact, and its gradient (M = 512 grid, 256 harmonics)")
    solve, loss, grad, solver = solver_functions(512)
    t_solve, t_loss, t_grad = bc.best(solve, k, repeat=rep1), bc.best(loss, k, repeat=rep1), bc.best(grad, k, repeat=rep1)
    failures.check(bool(np.isfinite(float(loss(k))) and np.isfinite(float(grad(k)))), "the M = 512 solve",
                   "non-finite loss or gradient")
    say(f"   solve (H, p, w on the grid, window K = {solver.window()[1]} points): {bc.ms(t_solve)}  (target < 1 ms)")
    say(f"   solve + sensor channels + loss:                          {bc.ms(t_loss)}")
    say(f"   gradient of that loss w.r.t. k_tread (implicit diff.):   {bc.ms(t_grad)}  "
          f"= {t_grad.cpu / t_loss.cpu:.2f}× the forward loss, {t_grad.cpu / t_solve.cpu:.2f}× the solve in CPU time "
          f"(target < 3×)")

    say("\n4. scaling with the number of harmonics (warm solve; wall, and CPU in brackets)")
    say(f"   {'M':>6} {'harmonics':>9} {'window K':>8} {'solve [ms]':>20} {'gradient [ms]':>20}")
    for M in ((128, 512) if args.quick else (128, 256, 512, 1024, 2048, 4096)):
        s, _, g, sv = solver_functions(M)
        rep = 5 if args.quick else (100 if M <= 1024 else 20)
        ts, tg = bc.best(s, k, repeat=rep), bc.best(g, k, repeat=rep)
        say(f"   {M:>6} {M // 2:>9} {sv.window()[1]:>8} {1e3 * ts.wall:>9.3f} ({1e3 * ts.cpu:>7.3f}) "
              f"{1e3 * tg.wall:>9.3f} ({1e3 * tg.cpu:>7.3f})")

    say("\n3. tread-stiffness fit over four speeds (drum, synthetic truth k = 25e6 N/m², 2 m/s² noise)")
    truth = RING.replace(k_tread=25e6)
    profiles = [synthetic_profile(truth, GEOMETRY, v, drum_diameter_m=1.2192, noise_ms2=2.0, seed=i)
                for i, v in enumerate((20.0, 30.0, 40.0, 50.0))]
    for reading, kw in (("plain reading (each run's gain and angle offset; --plain-reading)",
                         dict(sensor_nuisances=False)),
                        ("the default: each run's sensor nuisances too (tilt, IEPE corner, liner offset, "
                         "tangential gain)", {})):
        say(f"   {reading}:")
        res, t_cold = bc.timed(fit_rolling, profiles, GEOMETRY, RING, **kw)
        warm = []
        for _ in range(2 if args.quick else 5):
            res, t = bc.timed(fit_rolling, profiles, GEOMETRY, RING, **kw)
            warm.append(t)
        failures.check(res.converged, "the four-speed tread-stiffness fit", f"status {res.status}")
        say(f"     cold (compile + fit): {t_cold.wall:.1f} s wall, {t_cold.cpu:.1f} s CPU; warm: median "
            f"{statistics.median(bc.walls(warm)):.3f} s wall, {statistics.median(bc.cpus(warm)):.3f} s CPU "
            f"(target < 1 s); {res.iterations} LM steps in the last of {res.extra.get('passes', 1)} noise passes, "
            f"{res.extra['evaluations']} model-evaluation equivalents")
        say(f"     k_tread = {res.values['k_tread']:.5g} ± {res.stderr['k_tread']:.2g} N/m² (truth 2.5e7), "
            f"status {res.status}")

    say("\n   versus the source study's sweep at 50 km/h (k = 10–40 MN/m² in 0.1 MN/m² steps)")
    at50 = profiles[-1:]
    grid = np.arange(10e6, 40.001e6, 0.1e6)
    tread_stiffness_sweep(at50, GEOMETRY, RING, grid)
    sweep, t_sweep = bc.timed(tread_stiffness_sweep, at50, GEOMETRY, RING, grid)
    fit_rolling(at50, GEOMETRY, RING, sensor_nuisances=False)  # the study's reading, as the sweep's
    fit50, t_fit50 = bc.timed(fit_rolling, at50, GEOMETRY, RING, sensor_nuisances=False)
    failures.check(fit50.converged, "the 50 km/h fit", f"status {fit50.status}")
    failures.refuse()
    for line in lines:
        print(line)
    print(f"   sweep: {sweep.evaluations} evaluations, best k = {sweep.best:.4g}, SSE {sweep.best_sse:.6g}, "
          f"{t_sweep.wall:.2f} s wall, {t_sweep.cpu:.2f} s CPU warm")
    print(f"   fit:   {fit50.extra['evaluations']} evaluation equivalents, k = {fit50.values['k_tread']:.6g}, "
          f"SSE {sum_of_squares(fit50):.6g}, {t_fit50.wall:.3f} s wall, {t_fit50.cpu:.3f} s CPU warm")
    print(f"   → {sweep.evaluations / fit50.extra['evaluations']:.0f}× fewer evaluations, "
          f"SSE {'≤' if sum_of_squares(fit50) <= sweep.best_sse else '>'} the sweep's best "
          f"(the fit weighs harmonic rows by their noise, with the run's gain and offset: not the sweep's criterion); "
          f"|k − sweep's best| = {abs(fit50.values['k_tread'] - sweep.best) / fit50.stderr['k_tread']:.2f} σ")
    bc.finish()


if __name__ == "__main__":
    main()
