"""Free-tyre fit benchmarks: ringfit's public calls against bare peers in the same script.

Run: python benchmarks/bench_fit.py [--repeats 3] [--quick]
Prints, each figure as min / median / max over ``--repeats`` interleaved runs, wall time and CPU time
(process time; children's for the shell commands) side by side, and the load average at the start
and end (targets from issues 2 and 11 in brackets):

1. warm fit through the public API vs a bare optimistix Levenberg–Marquardt fit of eq. 18  [< 2 ms]
2. batched log-probability: evaluations per second at a large batch, and the cost of one call at
   emcee's batch (half the walkers) vs a trivial jitted function  [≥ 5e6 /s]
3. a 32-walker × 5000-step posterior (first call in the process and warm) vs emcee alone with a
   trivial log-probability  [< 5 s]
4. cold `ringfit fit` from the shell, with an empty and with a warm compilation cache, vs a bare
   script that imports JAX and optimistix and solves the same fit cold  [< 2.5 s]
5. the XLA programs a cold `ringfit fit` compiles (JAX_LOG_COMPILES=1, empty cache) vs the bare
   script's: the issue counted 19, 18 of them small eager ops
6. the posterior of the bundled free table, warm, both samplers in the same run (issue 32): the compiled
   stretch move (ringfit.fit.ensemble) against emcee's, 32 walkers from the same start until 50 τ; bulk ESS
   (arviz, the smallest over the parameters) per CPU-second, wall beside CPU, and both posteriors' medians
   and sd  [ratio ≥ 15×, ≥ 1,000 ESS per CPU-second]
7. cold `ringfit sample` from the shell (empty compilation cache), compiled sampler against
   `--sampler emcee`  [no slower]

Run it on one core for the issue's figures: `taskset -c 0 python benchmarks/bench_fit.py` (the first line
says how many cores the process may use).

`--quick` shortens 3 to 1000 steps (a smoke run; its figure is not the target's).
"""

import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402

import ringfit  # noqa: F401,E402  (float64)
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx

from ringfit.data import path
from ringfit.fit.least_squares import fit_natural_frequencies
from ringfit.fit.posterior import log_probability_function, sample_posterior
from ringfit.io.modes import read_mode_table
from ringfit.params import table9

MODES, TYRE = path("free-ssi.modes.csv"), path("table9.tyre.toml")



def best_of(fn, repeat=7, number=20) -> bc.Sample:
    """The fastest of ``repeat`` batches of ``number`` calls: wall and CPU seconds per call."""
    best = None
    for _ in range(repeat):
        with bc.Clock() as c:
            for _ in range(number):
                fn()
        s = bc.Sample(c.wall / number, c.cpu / number)
        best = s if best is None or s.wall < best.wall else best
    return best


def both(samples, scale=1.0, fmt="{:.2f}", unit="s") -> str:
    """``wall a / b / c unit, CPU a / b / c unit`` of samples."""
    return (f"wall {bc.span(bc.walls(samples), scale, fmt)} {unit}, "
            f"CPU {bc.span(bc.cpus(samples), scale, fmt)} {unit}")


def compiled_programs(stderr: str) -> list[str]:
    """Names of the XLA programs compiled, from JAX_LOG_COMPILES=1 output."""
    return re.findall(r"Finished XLA compilation of (\S+) in", stderr)


def the_fit_figures(args, reps, failures, geo, ring, table):
    """Figures 1–5."""
    n = jnp.arange(1.0, 10.0)
    f = jnp.asarray(table.freq_hz[:9])
    sigma = 0.01 * f
    R, P = geo.radius, float(geo.hoop_pressure_stiffness)

    # --- 1. warm fit vs a bare optimistix peer: same model, same solver, written inline
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
    fit = fit_natural_frequencies(table, geo, ring, prior="physical")
    t_api, t_bare = [], []
    for _ in range(reps):
        t_bare.append(best_of(lambda: bare(y0).block_until_ready()))
        t_api.append(best_of(lambda: fit_natural_frequencies(table, geo, ring, prior="physical")))
    if not fit.converged:
        failures.add("1. the warm fit", "did not converge")
    lines = [f"1. warm fit: public API {both(t_api, 1e3, unit='ms')}; bare optimistix LM {both(t_bare, 1e3, unit='ms')} "
             f"(CPU ratio {bc.ratio_span(t_api, t_bare)}; target < 2 ms)"]

    # --- 2. log-probability: throughput at a large batch, cost per call at emcee's batch
    batch = 200_000
    logp, _, _ = log_probability_function(fit)
    ys = np.asarray(y0 + 0.01 * np.random.default_rng(0).standard_normal((batch, 4)))
    small = ys[:16]  # emcee's stretch move evaluates half of the 32 walkers per call
    bare_lp = jax.jit(jax.vmap(lambda y: -0.5 * jnp.sum(resid(y, 0.0) ** 2)))
    trivial = jax.jit(lambda y: -0.5 * jnp.sum(y**2, axis=1))
    for fn in (logp, lambda y: np.asarray(bare_lp(y)), lambda y: np.asarray(trivial(y))):
        fn(ys), fn(small)
    t_ours, t_peer, c_ours, c_triv = [], [], [], []
    for _ in range(reps):
        t_ours.append(best_of(lambda: logp(ys), repeat=5, number=3))
        t_peer.append(best_of(lambda: bare_lp(ys).block_until_ready(), repeat=5, number=3))
        c_ours.append(best_of(lambda: logp(small), repeat=5, number=500))
        c_triv.append(best_of(lambda: np.asarray(trivial(small)), repeat=5, number=500))
    if not np.all(np.isfinite(logp(small))):
        failures.add("2. log-probability", "not finite at the walkers' start")
    lines.append(f"2. log-probability: ringfit {bc.span([batch / t.cpu for t in t_ours], fmt='{:.3g}')} evals per "
                 f"CPU-second (per wall-second {bc.span([batch / t.wall for t in t_ours], fmt='{:.3g}')}), bare "
                 f"vmapped eq. 18 {bc.span([batch / t.cpu for t in t_peer], fmt='{:.3g}')} per CPU-second "
                 f"(target ≥ 5e6 /s); one call at emcee's batch of 16: ringfit {both(c_ours, 1e6, '{:.0f}', 'µs')}, "
                 f"a trivial jitted function {both(c_triv, 1e6, '{:.0f}', 'µs')}")

    # --- 3. posterior 32 × 5000 (the first call in a process compiles the batch shape)
    import emcee

    steps = 1000 if args.quick else 5000

    def posterior():
        with bc.Clock() as c:
            post = sample_posterior(table, geo, ring, prior="physical", walkers=32, min_steps=steps, max_steps=steps,
                                    progress=False)
        ok = post.chain.shape[0] >= steps and bool(np.all(np.isfinite(post.log_prob)))
        return post, bc.Sample(c.wall, c.cpu, ok, "" if ok else "short or non-finite chain")

    def emcee_alone():
        sampler = emcee.EnsembleSampler(32, 4, lambda x: -0.5 * np.sum(x**2, axis=1), vectorize=True)
        with bc.Clock() as c:
            sampler.run_mcmc(np.random.default_rng(0).standard_normal((32, 4)), steps)
        return bc.Sample(c.wall, c.cpu)

    post, first = posterior()  # the first call in a process compiles the batch shape
    failures.check(first.ok, "3. posterior (first)", first.detail)
    runs3 = bc.interleaved({"posterior": lambda: posterior()[1], "emcee": emcee_alone}, reps, failures)
    lines.append(f"3. posterior 32 walkers × {steps} steps (LSQ start and τ checks included): {first.wall:.2f} s "
                 f"wall, {first.cpu:.2f} s CPU first in the process; warm {both(runs3['posterior'])}; emcee alone "
                 f"with a trivial log-prob {both(runs3['emcee'])} "
                 f"({np.median(bc.cpus(runs3['emcee'])) / steps * 1e6:.0f} µs CPU/step of emcee's own overhead"
                 f"{'' if not args.quick else '; --quick: not the target figure'}; target < 5 s)")

    # --- 4 and 5. cold CLI vs a bare cold script; XLA programs compiled
    exe = [sys.executable, "-m", "ringfit", "fit", str(MODES), "--tyre", str(TYRE), "--out"]
    programs, bare_programs = [], []
    with tempfile.TemporaryDirectory() as d:
        shared = dict(os.environ, RINGFIT_CACHE_DIR=str(Path(d) / "warm-cache"))
        filled = bc.run_process(exe + [str(Path(d) / "w.toml"), "--force"], shared)  # fill the cache
        failures.check(filled.ok, "4. filling the cache", filled.detail)
        count = iter(range(10**6))

        def cold():
            i = next(count)
            env = dict(os.environ, RINGFIT_CACHE_DIR=str(Path(d) / f"cold-cache-{i}"), JAX_LOG_COMPILES="1")
            r = bc.run_process(exe + [str(Path(d) / f"c{i}.toml")], env)
            programs[:] = compiled_programs(r.stderr)
            return r

        def bare_cold():
            r = bc.run_process([sys.executable, "-c", bc.BARE_FIT_SCRIPT, str(MODES)],
                               dict(os.environ, JAX_LOG_COMPILES="1"))
            bare_programs[:] = compiled_programs(r.stderr)
            return r

        runs4 = bc.interleaved({"cold": cold, "warm": lambda: bc.run_process(exe + [str(Path(d) / "w.toml"), "--force"],
                                                                              shared),
                                "bare": bare_cold}, reps, failures)
    failures.refuse()
    for line in lines:
        print(line)
    print(f"4. cold `ringfit fit` from the shell: empty compilation cache {both(runs4['cold'])}; warm cache "
          f"{both(runs4['warm'])} (target < 2.5 s); a bare script importing JAX + optimistix and solving the "
          f"same fit cold: {both(runs4['bare'])} (CPU ratio, empty cache: {bc.ratio_span(runs4['cold'], runs4['bare'])}×)")

    def summary(names):
        counts = {name: names.count(name) for name in dict.fromkeys(names)}
        return ", ".join(f"{k} ×{v}" if v > 1 else k for k, v in counts.items())

    print(f"5. XLA programs a cold `ringfit fit` compiles: {len(programs)} ({summary(programs)}); the bare "
          f"script: {len(bare_programs)} ({summary(bare_programs)}). The small ones are compiled while the "
          f"solve is traced, inside equinox/lineax/optimistix (enum comparisons and RESULTS.promote), "
          f"the same in both.")


def main(argv=None):
    ap = bc.parser(__doc__.splitlines()[0], quick_help="1000 posterior steps instead of 5000, 1 repeat (smoke run)")
    ap.add_argument("--repeats", type=bc.count("a number of runs", 1, 100), default=3,
                    help="runs per figure; min / median / max is printed (default 3)")
    ap.add_argument("--samplers-only", action="store_true", help="only figures 6 and 7 (the two samplers)")
    args = ap.parse_args(argv)
    reps = 1 if args.quick else args.repeats
    bc.start(f"bench_fit: min / median / max over {reps} interleaved run(s)" + (" [--quick]" if args.quick else "")
             + f"; {bc.usable_cores()} usable core(s)")
    failures = bc.Failures()
    geo, ring = table9()
    table = read_mode_table(MODES)
    fit = fit_natural_frequencies(table, geo, ring, prior="physical")
    if not args.samplers_only:
        the_fit_figures(args, reps, failures, geo, ring, table)
    lines = samplers(fit, reps, failures)
    failures.refuse()
    for line in lines:
        print(line)
    bc.finish()


def samplers(fit, reps, failures) -> list[str]:
    """Figures 6 and 7: the compiled sampler against emcee's, warm and cold."""
    # --- 6. the two samplers, warm, same run
    from ringfit.fit.posterior import sample

    def sampled(name):
        def run():
            with bc.Clock() as c:
                p = sample(fit, sampler=name, walkers=32, min_steps=2000, max_steps=20000, seed=3, progress=False)
            ess = float(np.min(p.ess()))
            ok = p.converged and np.isfinite(ess)
            posts[name] = p
            return bc.Sample(c.wall, c.cpu, ok, "" if ok else "not converged"), ess
        return run

    posts, ess6 = {}, {"compiled": [], "emcee": []}
    for name in ("compiled", "emcee"):
        sampled(name)()  # compile both first
    runs6 = {"compiled": [], "emcee": []}
    for _ in range(reps):
        for name in ("compiled", "emcee"):
            sm, e = sampled(name)()
            failures.check(sm.ok, f"6. {name} posterior", sm.detail)
            runs6[name].append(sm)
            ess6[name].append(e)
    per_cpu = {k: [e / r.cpu for e, r in zip(ess6[k], runs6[k])] for k in runs6}
    per_wall = {k: [e / r.wall for e, r in zip(ess6[k], runs6[k])] for k in runs6}
    ratio = [a / b for a, b in zip(per_cpu["compiled"], per_cpu["emcee"])]
    lines6 = [f"6. posterior of the bundled free table, warm, 32 walkers until 50 τ: compiled "
              f"{bc.span(per_cpu['compiled'], fmt='{:.0f}')} ESS per CPU-second (per wall-second "
              f"{bc.span(per_wall['compiled'], fmt='{:.0f}')}; {both(runs6['compiled'])}), emcee "
              f"{bc.span(per_cpu['emcee'], fmt='{:.0f}')} per CPU-second (per wall-second "
              f"{bc.span(per_wall['emcee'], fmt='{:.0f}')}; {both(runs6['emcee'])}); ratio "
              f"{bc.span(ratio, fmt='{:.1f}')}× (targets ≥ 15×, ≥ 1,000 ESS per CPU-second)"]
    for name in ("compiled", "emcee"):
        p = posts[name]
        rows = ", ".join(f"{r['name']} {r['median']:.4g} ± {r['sd']:.3g}" for r in p.summary_table())
        lines6.append(f"   {name:8s} median ± sd: {rows} ({p.steps} steps, τ max {np.max(p.tau):.0f})")

    # --- 7. cold `ringfit sample`, both samplers
    sample_exe = [sys.executable, "-m", "ringfit", "sample", str(MODES), "--tyre", str(TYRE), "--quiet", "--out"]
    with tempfile.TemporaryDirectory() as d:
        count7 = iter(range(10**6))

        def cold_sample(extra):
            def run():
                i = next(count7)
                env = dict(os.environ, RINGFIT_CACHE_DIR=str(Path(d) / f"cache-{i}"))
                return bc.run_process(sample_exe + [str(Path(d) / f"p{i}.h5"), *extra], env)
            return run

        runs7 = bc.interleaved({"compiled": cold_sample([]), "emcee": cold_sample(["--sampler", "emcee"])}, reps,
                               failures)
    lines6.append(f"7. cold `ringfit sample` (empty compilation cache): compiled {both(runs7['compiled'])}; "
                  f"--sampler emcee {both(runs7['emcee'])} (CPU ratio {bc.ratio_span(runs7['compiled'], runs7['emcee'])}"
                  f"; target ≤ 1)")
    return lines6


if __name__ == "__main__":
    main()
