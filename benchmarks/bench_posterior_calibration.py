"""Simulation-based calibration of ringfit's posteriors (issue 32): do the intervals cover what they claim?

Run: python benchmarks/bench_posterior_calibration.py [--n 200] [--noise both] [--n-identify 0] [--sampler compiled]

1. `sample` (eq. 18, docs/physics.md §2.1, §12): ``--n`` synthetic tyres drawn from the prior the sampler uses
   — log-normal on ρA, EI, k_w, k_v around Table 9 (σ_ln 0.1, 0.7, 0.3, 0.3) — the bundled free table's modes
   n = 1 … 9, each frequency with Gaussian noise of σ = 0.5 % of f, then least squares and the posterior (32
   walkers until 50 τ). Two noise models (``--noise``):

   a. ``fixed`` — the table states σ and the fit takes it as known (``noise="fixed"``): the posterior is the
      exact Bayesian one, which simulation-based calibration checks;
   b. ``estimated`` — the table states no σ, and the fit and the posterior use the free-modes block's noise
      model as ``ringfit fit`` / ``ringfit sample`` do by default (docs/physics.md §11 "Noise per block", §12.3):
      the least squares take the scale from the residual and widen their 95 % intervals by Student's t; the
      posterior integrates the scale out (a 1/s prior; ``scale_marginal``), which is the t shape at every level,
      and widens the rows by √κ. The same SBC verdict as a. (Until stop 39 the posterior sampled a plug-in scale
      widened by the 95 % quantiles' ratio: its 50 % intervals covered 58–64 % and k_v's ranks crowded to the
      middle, rank χ² p = 0.001.)

   Per parameter: the rank of the
   truth among L = 99 effectively independent draws (one per walker per τ, evenly chosen) and a χ² test of
   uniformity over 10 bins [p > 0.05 per parameter; with 4 parameters, one below 0.05 by chance has
   probability 19 %: the verdict is also given at Bonferroni's 0.05/4]; the coverage of the central 50/90/95 %
   intervals with Clopper–Pearson 95 % bounds [nominal inside].
2. `identify --posterior` (docs/physics.md §11–12): ``--n-identify`` joint cases (free + loaded + profiles at
   known load, ringfit.synth.make_identify_case: tyres drawn at random, noise as the case writes it), each
   identified and sampled as `identify --posterior` does (2k walkers, the intervals' noise model), until 50 τ
   or ``--identify-max-steps``. The joint problem's prior is flat, so SBC's rank statistic is uniform only
   where the data dominate the posterior (the truths' spread is many posterior widths wide, as here): the rank
   of the truth among L = 99 draws per parameter with a χ² test over 5 bins, and the coverage of the 50/90/95 %
   posterior intervals of every ring parameter, pooled over cases, with Clopper–Pearson bounds. Posteriors
   that did not reach 50 τ are counted and left out of both.

   Each case's record can be appended to a file as it finishes (``--identify-log``), so a run cut short, or
   several runs over disjoint cases (``--identify-first``), are summarised together (``--identify-summary``).

   The cost, measured on case 100 (12 free parameters, a shared 2-core machine): the case ~15 s of CPU, the
   identification ~25 s, compilation ~30 s, then the posterior. Its density is the contact solves (5 per
   evaluation, dense LU of the contact window's points): with the fit's solver 4.7–8.2 ms of CPU per evaluation
   (the spread is the machine's load), with the posterior's (``Identification.posterior_fit``: the window
   narrowed to the patches, no derivative step, the active sets started at the optimum's; docs/physics.md
   §12.3) 2.9–3.7 ms, the same density to 1e-10. τ ≈ 60–150 steps of 24 walkers asks for 3,000–7,500 steps:
   3–8 minutes of CPU per case. The default is 0 cases.

CPU time beside wall time; the load average at the start and end.
"""

import json
import math
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402

import ringfit  # noqa: F401,E402  (float64)
from ringfit.fit.least_squares import fit_natural_frequencies  # noqa: E402
from ringfit.fit.posterior import sample  # noqa: E402
from ringfit.io.modes import ModeTable  # noqa: E402
from ringfit.params import table9  # noqa: E402
from ringfit.physics.natural import natural_frequencies_jit  # noqa: E402

FREE = ("rho_a", "ei", "kw", "kv")
SIGMA_LN = {"rho_a": 0.1, "ei": 0.7, "kw": 0.3, "kv": 0.3}
REL_STD = 0.005
N = np.arange(1, 10)
LEVELS = (0.5, 0.9, 0.95)
RANK_DRAWS = 99


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    a = 1 - level
    lo = stats.beta.ppf(a / 2, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(1 - a / 2, k + 1, n - k) if k < n else 1.0
    return float(lo), float(hi)


def rank_draws(post, rng) -> np.ndarray:
    """``(L, k)`` effectively independent draws: thinned to one per τ after burn-in, L chosen evenly at random;
    with a systematic direction (identify's grid check, ``post.shift_u``) each moved by ε δu, ε ~ N(0, 1), as the
    draws the intervals are read from (:attr:`~ringfit.fit.posterior.Posterior.log_samples`)."""
    step = max(1, int(math.ceil(np.max(post.tau))))
    u = post.chain[post.burn :: step].reshape(-1, len(post.names))
    pick = rng.choice(u.shape[0], RANK_DRAWS, replace=u.shape[0] < RANK_DRAWS)
    u = u[pick]
    if post.shift_u is not None and np.any(post.shift_u != 0):
        u = u + rng.standard_normal(u.shape[0])[:, None] * np.asarray(post.shift_u)[None, :]
    return u


def coverage_line(label, hits, n) -> tuple[str, bool]:
    parts, ok = [], True
    for level in LEVELS:
        k = int(hits[level])
        lo, hi = clopper_pearson(k, n)
        inside = lo <= level <= hi
        ok &= inside
        parts.append(f"{level:.0%}: {k}/{n} = {k / n:.3f} [{lo:.3f}, {hi:.3f}]{'' if inside else ' MISS'}")
    return f"   {label:14s} coverage " + "; ".join(parts), ok


def sbc_sample(n: int, sampler: str, seed: int = 0, noise: str = "fixed") -> tuple[list[str], bool]:
    geo, ring = table9()
    median = {k: getattr(ring, k) for k in FREE}
    prior = {k: (median[k], SIGMA_LN[k]) for k in FREE}
    rng = np.random.default_rng(seed)
    ranks = np.zeros((n, len(FREE)), dtype=int)
    hits = {k: {lv: 0 for lv in LEVELS} for k in FREE}
    bad = 0
    with bc.Clock() as clock:
        for i in range(n):
            truth = {k: median[k] * math.exp(SIGMA_LN[k] * rng.standard_normal()) for k in FREE}
            tr = ring.replace(**truth)
            f = np.asarray(natural_frequencies_jit(tr, geo, N.astype(float)))
            sd = REL_STD * f
            table = ModeTable(freq_hz=f + sd * rng.standard_normal(f.size), n=N,
                              freq_std_hz=sd if noise == "fixed" else None)
            lsq = fit_natural_frequencies(table, geo, ring, free=FREE, prior=prior, noise=noise)
            # the fit's noise model sampled as `ringfit sample` does (sample_posterior): its σ and its row widening
            post = sample(lsq, sampler=sampler, walkers=32, min_steps=2000, max_steps=20000, seed=i, progress=False)
            bad += not (lsq.converged and post.converged)
            u = rank_draws(post, rng)
            t = np.log([truth[k] for k in post.names])
            ranks[i] = np.sum(u < t[None, :], axis=0)
            s = post.log_samples
            for j, k in enumerate(post.names):
                for lv in LEVELS:
                    lo, hi = np.percentile(s[:, j], [50 * (1 - lv), 50 * (1 + lv)])
                    hits[k][lv] += lo <= t[j] <= hi
    how = ("σ stated, taken as known (noise='fixed')" if noise == "fixed" else
           "no σ stated, the block's scale estimated, t- and κ-widened (noise='estimated', the default)")
    lines = [f"1{'a' if noise == 'fixed' else 'b'}. `sample` ({sampler}, {how}): {n} tyres from the prior, eq. 18 "
             f"modes n = 1…9 with noise σ = {REL_STD:.1%} of f; "
             f"{clock.wall:.0f} s wall, {clock.cpu:.0f} s CPU ({clock.cpu / n:.2f} s CPU per tyre); "
             f"{bad} fit(s) or chain(s) not converged"]
    ok_all, ok_bonf, ok_ks = True, True, True
    for j, k in enumerate(FREE):
        counts = np.histogram(ranks[:, j], bins=10, range=(0, RANK_DRAWS + 1))[0]
        p = float(stats.chisquare(counts).pvalue)
        p_ks = float(stats.kstest((ranks[:, j] + rng.uniform(size=n)) / (RANK_DRAWS + 1), "uniform").pvalue)
        ok_all &= p > 0.05
        ok_bonf &= p > 0.05 / len(FREE)
        ok_ks &= p_ks > 0.05
        line, cov_ok = coverage_line(k, hits[k], n)
        ok_all &= cov_ok
        ok_bonf &= cov_ok
        lines.append(f"   {k:14s} rank χ² (10 bins) p = {p:.3f}, KS p = {p_ks:.3f}; bins {counts.tolist()}")
        lines.append(line)
    lines.append(f"   verdict (rank uniformity by the χ² test): every p > 0.05 and every coverage inside its "
                 f"Clopper–Pearson interval: {'PASS' if ok_all else 'FAIL'}; with Bonferroni over the "
                 f"{len(FREE)} parameters (p > {0.05 / len(FREE):.4f}): {'PASS' if ok_bonf else 'FAIL'}; KS p "
                 f"> 0.05 for every parameter: {'PASS' if ok_ks else 'FAIL'}")
    return lines, ok_bonf


def identify_case(i: int, seed: int, sampler: str, max_steps: int, rng, folder: Path) -> dict:
    """One joint case: made, identified and sampled as `identify --posterior` does; per ring parameter the truth's
    rank among :data:`RANK_DRAWS` draws and whether each central interval of :data:`LEVELS` covers it."""
    from ringfit.fit.identify import identify, read_identify_folder
    from ringfit.synth.identify import make_identify_case

    with bc.Clock() as clock:
        truth = make_identify_case(folder, seed=seed)
        ident = identify(read_identify_folder(folder))
        out = dict(case=i, seed=seed, fit_converged=bool(ident.converged), params={})
        if not ident.converged:
            out["message"] = str(ident.fit.message)
            return out
        k = len(ident.fit.names)
        post = sample(ident.posterior_fit(), sampler=sampler, walkers=2 * k, min_steps=min(500, max_steps),
                      max_steps=max_steps, check_every=250, seed=i, progress=False, spread=0.25)
    out.update(posterior_converged=bool(post.converged), steps=int(post.steps), tau_max=float(np.max(post.tau)),
               walkers=2 * k, wall_s=clock.wall, cpu_s=clock.cpu)
    s = post.log_samples
    draws = rank_draws(post, rng)
    ring_truth = truth["ring"] if "ring" in truth else truth
    for j, name in enumerate(post.names):
        if name not in ident.free or name not in ring_truth:
            continue
        t = math.log(float(ring_truth[name]))
        cover = {}
        for lv in LEVELS:
            lo, hi = np.percentile(s[:, j], [50 * (1 - lv), 50 * (1 + lv)])
            cover[str(lv)] = bool(lo <= t <= hi)
        out["params"][name] = dict(rank=int(np.sum(draws[:, j] < t)), cover=cover)
    return out


def identify_summary(records: list[dict], sampler: str, wall: float, cpu: float,
                     min_tau: float | None = None) -> tuple[list[str], bool]:
    """Coverage (pooled and per parameter, Clopper–Pearson) and rank χ² per parameter of the cases' records: those
    whose chain reached 50 τ (the sampler's own criterion), or ``min_tau`` τ when given."""
    n = len(records)

    def long_enough(r):
        if min_tau is None:
            return r["posterior_converged"]
        return bool(r["params"]) and r["steps"] >= min_tau * r["tau_max"]

    skipped = sum(not r["fit_converged"] for r in records)
    unconverged = sum(r["fit_converged"] and not long_enough(r) for r in records)
    used = [r for r in records if r["fit_converged"] and long_enough(r)]
    hits, count, per_param, ranks = {lv: 0 for lv in LEVELS}, 0, {}, {}
    for r in used:
        for name, q in r["params"].items():
            count += 1
            ranks.setdefault(name, []).append(q["rank"])
            per_param.setdefault(name, {lv: 0 for lv in LEVELS})
            for lv in LEVELS:
                hits[lv] += q["cover"][str(lv)]
                per_param[name][lv] += q["cover"][str(lv)]
    line, ok = coverage_line("all ring", hits, count) if count else ("   no converged case: no coverage", False)
    tau = "50 τ" if min_tau is None else f"{min_tau:g} τ"
    lines = [f"2. `identify --posterior` ({sampler}): {n} joint cases (free + loaded + profiles), {skipped} fit(s) "
             f"not converged and {unconverged} posterior(s) shorter than {tau} (left out), {count} parameter "
             f"intervals from {len(used)} case(s); {wall:.0f} s wall, {cpu:.0f} s CPU", line]
    for name, r in ranks.items():
        r = np.asarray(r)
        counts = np.histogram(r, bins=5, range=(0, RANK_DRAWS + 1))[0]
        p = float(stats.chisquare(counts).pvalue) if len(r) >= 5 else math.nan
        cov, ok_p = coverage_line(name, per_param[name], len(r))
        ok &= ok_p and p > 0.05 / len(ranks)  # fewer than 5 ranks: no test, no pass
        lines.append(f"   {name:14s} rank χ² (5 bins) p = {p:.3f}{' (too few cases)' if len(r) < 5 else ''}; "
                     f"bins {counts.tolist()}")
        lines.append(cov)
    return lines, ok


def coverage_identify(n: int, sampler: str, seed0: int = 100, max_steps: int = 5000,
                      log: Path | None = None, first: int = 0) -> tuple[list[str], bool]:
    """``n`` joint cases (:func:`identify_case`; case i has seed ``seed0 + i``, i = ``first`` …), one line each as
    it finishes; ``log``: each case's record appended as one JSON line (a run cut short, or several runs over
    disjoint cases, are summarised with ``--identify-summary``)."""
    rng = np.random.default_rng(seed0 + first)
    records = []
    with bc.Clock() as clock, tempfile.TemporaryDirectory() as d:
        for i in range(first, first + n):
            r = identify_case(i, seed0 + i, sampler, max_steps, rng, Path(d) / f"c{i}")
            records.append(r)
            if log is not None:
                with open(log, "a") as fh:
                    fh.write(json.dumps(r) + "\n")
            if not r["fit_converged"]:
                print(f"   case {i} (seed {seed0 + i}): the joint fit did not converge ({r['message']}); left out",
                      flush=True)
            else:
                if not r["posterior_converged"]:
                    print(f"   case {i} (seed {seed0 + i}): posterior not converged ({r['steps']} steps, τ max "
                          f"{r['tau_max']:.0f}, {r['steps'] / r['tau_max']:.0f} τ); left out at 50 τ", flush=True)
                case = ", ".join(f"{k} {'in' if q['cover']['0.95'] else 'OUT'}" for k, q in r["params"].items())
                print(f"   case {i} (seed {seed0 + i}): {r['steps']} steps, τ max {r['tau_max']:.0f}, "
                      f"{r['cpu_s']:.0f} s CPU; 95 %: {case}", flush=True)
    return identify_summary(records, sampler, clock.wall, clock.cpu)


def main(argv=None):
    ap = bc.parser(__doc__.splitlines()[0], quick_help="20 tyres, no identify cases (a smoke run)")
    ap.add_argument("--n", type=bc.count("a number of tyres", 0, 100_000), default=200,
                    help="synthetic tyres for `sample` (default 200; 0: part 1 skipped)")
    ap.add_argument("--n-identify", type=bc.count("a number of cases", 0, 10_000, ), default=0,
                    help="joint cases for `identify --posterior` (default 0; 3–8 minutes of CPU each, see 2.)")
    ap.add_argument("--identify-max-steps", type=bc.count("a number of steps", 100, 10**6), default=10000,
                    help="posterior steps at most per joint case (default 10000, `identify`'s)")
    ap.add_argument("--sampler", choices=("compiled", "emcee"), default="compiled")
    ap.add_argument("--noise", choices=("both", "fixed", "estimated"), default="both",
                    help="the free block's noise model of part 1: a stated σ taken as known (SBC proper), the "
                         "estimated scale (`ringfit sample`'s default), or both (default)")
    ap.add_argument("--seed", type=bc.count("a whole number >= 0", 0, 2**31), default=0,
                    help="seed of the synthetic tyres (default 0)")
    ap.add_argument("--identify-first", type=bc.count("a case index >= 0", 0, 10**6), default=0,
                    help="index of the first joint case (its seed: 100 + 1000 × seed + index; default 0)")
    ap.add_argument("--identify-log", type=Path, default=None,
                    help="append each joint case's record (ranks, coverage) to this file as one JSON line")
    ap.add_argument("--identify-summary", type=Path, default=None,
                    help="summarise the records of an --identify-log file (a partial run included) and stop")
    ap.add_argument("--identify-min-tau", type=float, default=None,
                    help="with --identify-summary: count chains at least this many τ long (default: the sampler's "
                         "50 τ)")
    args = ap.parse_args(argv)
    if args.identify_summary is not None:
        try:
            records = [json.loads(line) for line in args.identify_summary.read_text().splitlines() if line.strip()]
        except (OSError, ValueError) as e:
            print(f"error: {args.identify_summary}: expected an --identify-log file of JSON lines ({e})",
                  file=sys.stderr)
            sys.exit(2)
        more, ok2 = identify_summary(records, args.sampler, sum(r.get("wall_s", 0.0) for r in records),
                                     sum(r.get("cpu_s", 0.0) for r in records), min_tau=args.identify_min_tau)
        for line in more:
            print(line, flush=True)
        print(f"   verdict (every coverage inside its Clopper–Pearson interval, every rank p > 0.05 / the parameters; "
              f"at least one converged case): {'PASS' if ok2 else 'FAIL'}", flush=True)
        return
    n = 20 if args.quick else args.n
    bc.start(f"bench_posterior_calibration: {n} tyres for sample, {args.n_identify} joint cases for identify"
             + (" [--quick]" if args.quick else ""))
    for noise in (("fixed", "estimated") if args.noise == "both" and n else (args.noise,) if n else ()):
        lines, ok = sbc_sample(n, args.sampler, seed=args.seed, noise=noise)
        for line in lines:
            print(line, flush=True)
    if args.n_identify:
        more, ok2 = coverage_identify(args.n_identify, args.sampler, seed0=100 + 1000 * args.seed,
                                      max_steps=args.identify_max_steps, log=args.identify_log,
                                      first=args.identify_first)
        for line in more:
            print(line, flush=True)
        print(f"   verdict (every coverage inside its Clopper–Pearson interval, every rank p > 0.05 / the parameters; "
              f"at least one converged case): {'PASS' if ok2 else 'FAIL'}", flush=True)
    bc.finish()


if __name__ == "__main__":
    main()
