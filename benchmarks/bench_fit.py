"""Free-tyre fit benchmarks: ringfit's overhead against bare peers in the same process.

Run: python benchmarks/bench_fit.py
Prints (targets from issue 2 in brackets):
1. warm fit through the public API vs a bare optimistix Levenberg–Marquardt fit of eq. 18  [< 2 ms]
2. batched log-probability evaluations per second vs a bare jitted vmapped eq. 18 likelihood  [≥ 5e6 /s]
3. a 32-walker × 5000-step posterior vs emcee alone with a trivial log-probability  [< 5 s]
4. cold `ringfit fit` from the shell, with and without the persistent compilation cache  [< 2.5 s]
"""

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import ringfit  # noqa: F401  (float64)
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx

from ringfit.data import path
from ringfit.fit.least_squares import fit_natural_frequencies
from ringfit.fit.posterior import log_probability_function, sample_posterior
from ringfit.io.modes import read_mode_table
from ringfit.params import table9


def best_of(fn, repeat=7, number=20):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        times.append((time.perf_counter() - t0) / number)
    return min(times)


def main():
    geo, ring = table9()
    table = read_mode_table(path("free-ssi.modes.csv"))
    n = jnp.arange(1.0, 10.0)
    f = jnp.asarray(table.freq_hz[:9])
    sigma = 0.01 * f
    R, P = geo.radius, float(geo.hoop_pressure_stiffness)

    # --- 1. bare optimistix peer: same model, same solver, written inline
    def resid(y, args):
        rho, ei, kw, kv = jnp.exp(y)
        n2 = n**2
        k = ei / R**4 * n2 * (n2 - 1) ** 2 + P * n2 * (n2 - 1) + kw * n2 + kv
        return (jnp.sqrt(k / (rho * (1 + n2))) / (2 * jnp.pi) - f) / sigma + 0 * args

    @jax.jit
    def bare(y0):
        solver = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10, linear_solver=lx.SVD())
        prior = jnp.array([0.0, 1.0, 0.0, 0.0])  # EI prior row as in ringfit's physical prior
        mu = jnp.log(jnp.sqrt(0.2))
        fn = lambda y, a: jnp.concatenate([resid(y, a), prior * (y - mu) / 1.0954])  # noqa: E731
        return optx.least_squares(fn, solver, y0, args=0.0, max_steps=256, throw=False).value

    y0 = jnp.log(jnp.array([ring.rho_a, ring.ei, ring.kw, ring.kv]))
    bare(y0).block_until_ready()
    t_bare = best_of(lambda: bare(y0).block_until_ready())
    fit_natural_frequencies(table, geo, ring, prior="physical")
    t_api = best_of(lambda: fit_natural_frequencies(table, geo, ring, prior="physical"))
    print(f"1. warm fit: public API {t_api * 1e3:.2f} ms, bare optimistix LM {t_bare * 1e3:.2f} ms "
          f"(ratio {t_api / t_bare:.2f}; target < 2 ms)")

    # --- 2. log-probability throughput
    batch = 200_000
    logp, _, _ = log_probability_function(fit_natural_frequencies(table, geo, ring, prior="physical"))
    ys = np.asarray(y0 + 0.01 * np.random.default_rng(0).standard_normal((batch, 4)))
    logp(ys)
    t_ours = best_of(lambda: logp(ys), repeat=5, number=3)
    bare_lp = jax.jit(jax.vmap(lambda y: -0.5 * jnp.sum(resid(y, 0.0) ** 2)))
    bare_lp(ys).block_until_ready()
    t_peer = best_of(lambda: bare_lp(ys).block_until_ready(), repeat=5, number=3)
    print(f"2. log-probability: ringfit {batch / t_ours:.3g} evals/s, bare vmapped eq. 18 {batch / t_peer:.3g} "
          f"evals/s (ratio {t_ours / t_peer:.2f}; target ≥ 5e6 /s)")

    # --- 3. posterior 32 × 5000
    import emcee

    t0 = time.perf_counter()
    post = sample_posterior(table, geo, ring, prior="physical", walkers=32, min_steps=5000, max_steps=5000,
                            progress=False)
    t_post = time.perf_counter() - t0
    trivial = emcee.EnsembleSampler(32, 4, lambda x: -0.5 * np.sum(x**2, axis=1), vectorize=True)
    t0 = time.perf_counter()
    trivial.run_mcmc(np.random.default_rng(0).standard_normal((32, 4)), 5000)
    t_emcee = time.perf_counter() - t0
    print(f"3. posterior 32 walkers × {post.steps} steps: {t_post:.2f} s incl. the LSQ start and τ checks; "
          f"emcee alone with a trivial log-prob {t_emcee:.2f} s ({t_emcee / t_post:.0%} of it is emcee's own "
          f"per-step overhead, {t_emcee / 5000 * 1e6:.0f} µs/step; target < 5 s)")

    # --- 4. cold CLI
    exe = [sys.executable, "-m", "ringfit", "fit", str(path("free-ssi.modes.csv")), "--tyre",
           str(path("table9.tyre.toml")), "--out"]
    with tempfile.TemporaryDirectory() as d:
        env = dict(os.environ, RINGFIT_CACHE_DIR=str(Path(d) / "cache"))
        out = []
        for i in range(3):
            t0 = time.perf_counter()
            subprocess.run(exe + [str(Path(d) / f"f{i}.toml")], env=env, capture_output=True, check=True)
            out.append(time.perf_counter() - t0)
    print(f"4. cold `ringfit fit` from the shell: {out[0]:.2f} s with an empty compilation cache, "
          f"{min(out[1:]):.2f} s with it warm (target < 2.5 s)")


if __name__ == "__main__":
    main()
