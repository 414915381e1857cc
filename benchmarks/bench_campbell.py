"""Campbell diagram of the rolling, loaded tyre and its gradient (issue 13, item 7).

Prints figures against the issue's targets; run with ``python benchmarks/bench_campbell.py``.
Timings are warm (after compilation), best of repeated calls (robust to other
processes sharing the cores), BLAS limited to one thread as the library does
for these small eigenproblems (``ringfit.targets.ssi.small_matrix_threads``).
Each figure is wall time with the CPU time of the same call beside it
(``time.process_time``: all threads of this process; CPU well below wall means
the call waited for a core another process held); the load average is printed
at the start and the end.

1. ``campbell_modes``: 17 speeds (0–80 km/h) × the Hill basis K = 32 (modes up to
   n ≈ 30, of which n ≤ 15 are kept), Table 9 tyre, 4 kN, 1.2192 m drum — the
   standing solve for R_e, 17 contact solves and 17 Hermitian eigensolves of size
   2·65, one jit region. Target < 1 s.
2. The whole ``campbell_diagram`` (the same, plus branch tracking and labels in NumPy).
3. ``jax.grad`` of a least-squares loss on every branch with n ≤ 15 at the 17
   speeds with respect to the ring parameters (ρA, EI, k_w, k_v, k_trd), through the
   contact solves (implicit differentiation) and the eigensolves. Target < 3× item 1.
"""

from __future__ import annotations

import os
import time

import jax
import jax.numpy as jnp
import numpy as np

import ringfit  # noqa: F401  (float64)
from ringfit.gap.campbell import campbell_diagram
from ringfit.params import table9
from ringfit.physics.contact import as_traced
from ringfit.physics.operating import Drum
from ringfit.physics.rolling_modes import DEFAULT_HARMONICS, campbell_modes
from ringfit.targets.ssi import small_matrix_threads

GEOMETRY, RING = table9()
SPEEDS = jnp.arange(0.0, 80.0 + 1e-9, 5.0)
LOAD = 4000.0
ROAD = Drum(diameter=1.2192)
NAMES = ("rho_a", "ei", "kw", "kv", "k_tread")


def timed(fn, *args, repeat=20):
    """Best of ``repeat`` warm calls: ``(wall, cpu)`` [s] of the fastest call (CPU of this process, all threads)."""
    jax.block_until_ready(fn(*args))
    best = (np.inf, np.inf)
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        jax.block_until_ready(fn(*args))
        wall, cpu = time.perf_counter() - t, time.process_time() - c
        if wall < best[0]:
            best = (wall, cpu)
    return best


def _load() -> str:
    return ", ".join(f"{x:.2f}" for x in os.getloadavg()) + f" on {os.cpu_count()} cores"


def main():
    print(f"JAX {jax.__version__} on {jax.devices()[0].platform} ({jax.device_count()} device), float64; "
          f"{len(SPEEDS)} speeds, Hill basis K = {DEFAULT_HARMONICS}")
    print(f"load average at the start: {_load()}")
    ring, geometry, road = as_traced((RING, GEOMETRY, ROAD))
    theta = jnp.log(jnp.array([getattr(RING, n) for n in NAMES]))

    def ring_of(th):
        return ring.replace(**{n: jnp.exp(th[i]) for i, n in enumerate(NAMES)})

    def diagram(th):
        cm = campbell_modes(ring_of(th), geometry, LOAD, SPEEDS, road)
        return cm.modes.angular_frequency, cm.modes.order, cm.ok

    forward = jax.jit(diagram)
    with small_matrix_threads():
        freq, order, ok = forward(theta)
        keep = jnp.asarray(np.asarray(order) <= 15)
        target = 1.01 * freq  # a "measurement" 1 % off every branch with n ≤ 15

        def loss(th):
            f = diagram(th)[0]
            return jnp.sum(jnp.where(keep, (f - target) ** 2 / target**2, 0.0))

        loss_j, grad_j = jax.jit(loss), jax.jit(jax.grad(loss))
        t0 = time.perf_counter()
        jax.block_until_ready(forward(theta))
        t_first = time.perf_counter() - t0
        t_fwd, c_fwd = timed(forward, theta)
        t_loss, c_loss = timed(loss_j, theta)
        t_grad, c_grad = timed(grad_j, theta)
        g = grad_j(theta)
        speeds = np.asarray(SPEEDS)
        d = campbell_diagram(RING, GEOMETRY, LOAD, speeds, drum_diameter_m=1.2192)  # compiles the labels
        t_full = []
        for _ in range(5):
            t0, c0 = time.perf_counter(), time.process_time()
            d = campbell_diagram(RING, GEOMETRY, LOAD, speeds, drum_diameter_m=1.2192)
            t_full.append((time.perf_counter() - t0, time.process_time() - c0))
        t_full = min(t_full)
    n_modes = int(np.sum(np.asarray(order)[0] <= 15))
    print(f"\n1. Campbell diagram, {len(SPEEDS)} speeds × {n_modes} modes with n ≤ 15 "
          f"(all converged: {bool(np.all(ok))})")
    print(f"   warm: {1e3 * t_fwd:.1f} ms wall, {1e3 * c_fwd:.1f} ms CPU   (target < 1000 ms; "
          f"{1e3 * t_fwd / len(SPEEDS):.2f} ms per speed)")
    print(f"   (first call after compilation: {1e3 * t_first:.1f} ms wall)")
    print(f"\n2. campbell_diagram (+ branch tracking by MAC and acceleration labels, NumPy): "
          f"{1e3 * t_full[0]:.1f} ms wall, {1e3 * t_full[1]:.1f} ms CPU for {d.branches} branches")
    print(f"\n3. gradient of a least-squares loss on all n ≤ 15 branches w.r.t. {', '.join(NAMES)} (log space)")
    print(f"   loss: {1e3 * t_loss:.1f} ms wall ({1e3 * c_loss:.1f} ms CPU), gradient: {1e3 * t_grad:.1f} ms wall "
          f"({1e3 * c_grad:.1f} ms CPU) = {t_grad / t_fwd:.2f}× the diagram (target < 3×), "
          f"{t_grad / t_loss:.2f}× the loss")
    print("   ∂loss/∂log θ: " + ", ".join(f"{n} {float(v):+.3g}" for n, v in zip(NAMES, g)))
    print(f"\nload average at the end: {_load()}")


if __name__ == "__main__":
    main()
