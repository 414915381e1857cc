"""Campbell diagram of the rolling, loaded tyre and its gradient (issue 13, item 7).

Prints figures against the issue's targets; run with ``python benchmarks/bench_campbell.py [--quick]``
(``--quick``: 3 repeats, a smoke run). Timings are warm (after compilation), best of repeated
calls (robust to other processes sharing the cores), wall and CPU (process time) side by side,
ratios of CPU times, the load average at the start and the end, BLAS limited to one thread as the library does
for these small eigenproblems (``ringfit._threads.small_matrix_threads``).

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

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402

import ringfit  # noqa: F401,E402  (float64)
from ringfit.physics.campbell import campbell_diagram
from ringfit.params import table9
from ringfit.physics.contact import as_traced
from ringfit.physics.operating import Drum
from ringfit.physics.rolling_modes import DEFAULT_HARMONICS, campbell_modes
from ringfit._threads import small_matrix_threads

GEOMETRY, RING = table9()
SPEEDS = jnp.arange(0.0, 80.0 + 1e-9, 5.0)
LOAD = 4000.0
ROAD = Drum(diameter=1.2192)
NAMES = ("rho_a", "ei", "kw", "kv", "k_tread")


def main(argv=None):
    args = bc.parser(__doc__.splitlines()[0], quick_help="3 repeats (smoke run)").parse_args(argv)
    rep = 3 if args.quick else 20
    bc.start(f"bench_campbell: JAX {jax.__version__} on {jax.devices()[0].platform} ({jax.device_count()} device), "
             f"float64; {len(SPEEDS)} speeds, Hill basis K = {DEFAULT_HARMONICS}" + (" [--quick]" if args.quick else ""))
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
        t_first = bc.best(forward, theta, repeat=1, warm=False)
        t_fwd = bc.best(forward, theta, repeat=rep)
        t_loss = bc.best(loss_j, theta, repeat=rep)
        t_grad = bc.best(grad_j, theta, repeat=rep)
        g = grad_j(theta)
        speeds = np.asarray(SPEEDS)
        d = campbell_diagram(RING, GEOMETRY, LOAD, speeds, drum_diameter_m=1.2192)
        t_full = bc.best(lambda: campbell_diagram(RING, GEOMETRY, LOAD, speeds, drum_diameter_m=1.2192),
                         repeat=3 if args.quick else 5, warm=False)
    failures = bc.Failures()
    failures.check(bool(np.all(ok)), "the Campbell diagram", "not every contact solve converged")
    failures.check(bool(np.all(np.isfinite(np.asarray(g)))), "the gradient", "not finite")
    failures.refuse()
    n_modes = int(np.sum(np.asarray(order)[0] <= 15))
    print(f"\n1. Campbell diagram, {len(SPEEDS)} speeds × {n_modes} modes with n ≤ 15 "
          f"(all converged: {bool(np.all(ok))})")
    print(f"   warm: {bc.ms(t_fwd, 1)}   (target < 1000 ms; {1e3 * t_fwd.wall / len(SPEEDS):.2f} ms per speed)")
    print(f"   (first call after compilation: {bc.ms(t_first, 1)})")
    print(f"\n2. campbell_diagram (+ branch tracking by MAC and acceleration labels, NumPy): "
          f"{bc.ms(t_full, 1)} for {d.branches} branches")
    print(f"\n3. gradient of a least-squares loss on all n ≤ 15 branches w.r.t. {', '.join(NAMES)} (log space)")
    print(f"   loss: {bc.ms(t_loss, 1)}, gradient: {bc.ms(t_grad, 1)} = {t_grad.cpu / t_fwd.cpu:.2f}× the diagram "
          f"in CPU time (target < 3×), {t_grad.cpu / t_loss.cpu:.2f}× the loss")
    print("   ∂loss/∂log θ: " + ", ".join(f"{n} {float(v):+.3g}" for n, v in zip(NAMES, g)))
    bc.finish()


if __name__ == "__main__":
    main()
