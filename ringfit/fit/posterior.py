"""Posterior of ring parameters given measured natural frequencies (emcee).

Likelihood: independent Gaussians on the frequencies with the σ of the
least-squares fit (:func:`ringfit.fit.least_squares.frequency_data`), model
eq. 18 (PHYSICS.md §2.1). Priors, on ``log θ`` of each free parameter: the
log-normal priors chosen (e.g. ``"physical"``), otherwise uniform in ``log θ``
within :data:`ringfit.fit.priors.BOUNDS`; every parameter is also truncated to
those bounds.

Sampling: ``emcee.EnsembleSampler(vectorize=True)`` on one jitted, vmapped
log-probability; walkers start in a small ball around the least-squares
optimum; the chain is extended in blocks until it is longer than
:data:`TAU_FACTOR` integrated autocorrelation times (or ``max_steps``, with a
warning). Draws and everything needed to rebuild a report are saved to HDF5.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ringfit.fit.least_squares import (
    DEFAULT_FREE,
    DEFAULT_RELATIVE_STD,
    RING_FIELDS,
    check_free,
    fit_natural_frequencies,
    frequency_data,
    ring_from_log,
    ring_vector,
)
from ringfit.fit.priors import log_bounds, prior_arrays, resolve_priors
from ringfit.params import BAR, RingParams, TyreGeometry
from ringfit.physics.natural import natural_frequencies

#: Stop when the chain is longer than this many integrated autocorrelation times.
TAU_FACTOR = 50
FORMAT = "ringfit-posterior/1"


def log_probability(log_free, args, free_index):
    """Log posterior density of ``log θ`` (one walker), up to a constant.

    ``args = (base (8,), geometry, n (m,), freq (m,), sigma (m,), mu (k,), sd (k,), mask (k,), lo (k,), hi (k,))``.
    """
    base, geometry, n, freq, sigma, mu, sd, mask, lo, hi = args
    ring = ring_from_log(log_free, free_index, base)
    r = (natural_frequencies(ring, geometry, n) - freq) / sigma
    loglike = -0.5 * jnp.sum(r**2)
    logprior = -0.5 * jnp.sum(mask * ((log_free - mu) / sd) ** 2)
    inside = jnp.all((log_free >= lo) & (log_free <= hi))
    value = jnp.where(inside, loglike + logprior, -jnp.inf)
    return jnp.where(jnp.isnan(value), -jnp.inf, value)


def _arviz():
    """arviz, imported quietly (its import warns about a coming refactor)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz

    return arviz


_batched = {}


def batched_log_probability(free_index: tuple[int, ...]):
    """The jitted, vmapped log-probability ``(walkers, k) -> (walkers,)`` for a free set (cached)."""
    fn = _batched.get(free_index)
    if fn is None:
        fn = jax.jit(jax.vmap(lambda y, args: log_probability(y, args, free_index), in_axes=(0, None)))
        _batched[free_index] = fn
    return fn


@dataclass
class Posterior:
    """Posterior draws and sampler diagnostics.

    - ``names``: free parameters ``(k,)``; ``values0``: all ring parameters
      (fixed ones at their values; free ones at the least-squares optimum).
    - ``chain``: ``(steps, walkers, k)`` log-parameters; ``log_prob``: ``(steps, walkers)``.
    - ``acceptance``: ``(walkers,)`` acceptance fractions.
    - ``tau``: ``(k,)`` integrated autocorrelation times [steps].
    - ``burn``, ``thin``: what :attr:`samples` discards and keeps.
    - ``data``: ``n``, ``freq_hz``, ``sigma_hz`` ``(m,)``, ``sigma_source``;
      ``geometry``: radius/width/pressure; ``priors``: name -> (median, σ_ln, source).
    """

    names: tuple[str, ...]
    values0: dict[str, float]
    chain: np.ndarray
    log_prob: np.ndarray
    acceptance: np.ndarray
    tau: np.ndarray
    burn: int
    thin: int
    data: dict
    geometry: dict
    priors: dict
    source: str = ""
    lsq: dict = field(default_factory=dict)

    @property
    def steps(self) -> int:
        return self.chain.shape[0]

    @property
    def converged(self) -> bool:
        """Chain longer than :data:`TAU_FACTOR` × the largest τ."""
        return bool(np.all(np.isfinite(self.tau)) and self.steps > TAU_FACTOR * np.max(self.tau))

    @property
    def log_samples(self) -> np.ndarray:
        """``(draws, k)`` flattened log-parameter draws after burn-in and thinning."""
        return self.chain[self.burn :: self.thin].reshape(-1, len(self.names))

    @property
    def samples(self) -> np.ndarray:
        """``(draws, k)`` parameter draws in SI units."""
        return np.exp(self.log_samples)

    def ring_samples(self) -> RingParams:
        """A RingParams whose free fields are ``(draws,)`` arrays."""
        s = self.samples
        values = {k: np.full(s.shape[0], v) for k, v in self.values0.items()}
        values.update({k: s[:, i] for i, k in enumerate(self.names)})
        return RingParams(**values)

    def geometry_params(self) -> TyreGeometry:
        return TyreGeometry(self.geometry["radius"], self.geometry["width"], self.geometry["pressure"])

    def rhat(self) -> np.ndarray:
        """Split-R̂ per parameter, walkers treated as chains (arviz)."""
        az = _arviz()
        post = self.chain[self.burn :: self.thin]  # (draws, walkers, k)
        return np.array([float(az.rhat(post[:, :, i].T)) for i in range(len(self.names))])

    def ess(self) -> np.ndarray:
        """Bulk effective sample size per parameter (arviz)."""
        az = _arviz()
        post = self.chain[self.burn :: self.thin]
        return np.array([float(az.ess(post[:, :, i].T)) for i in range(len(self.names))])

    def summary_table(self, level: float = 0.95) -> list[dict]:
        """Per parameter: mean, median, sd and the central ``level`` interval (SI)."""
        s = self.samples
        q = [(1 - level) / 2 * 100, 50, (1 + level) / 2 * 100]
        rows = []
        for i, k in enumerate(self.names):
            lo, med, hi = np.percentile(s[:, i], q)
            rows.append(dict(name=k, mean=float(s[:, i].mean()), median=float(med), sd=float(s[:, i].std()),
                             lo=float(lo), hi=float(hi), tau=float(self.tau[i])))
        return rows

    def predictive(self, n, level: float = 0.95, noise: bool = True, seed: int = 0):
        """Posterior predictive natural frequencies for indices ``n`` ``(p,)``.

        **Returns:** dict of ``(p,)`` arrays ``median``, ``lo``, ``hi`` [Hz]; with
        ``noise`` each draw adds the measurement scatter (σ = the data's
        relative σ, median over modes, × f), i.e. where a new measurement
        should fall; without it the band is the model's credible band.
        """
        n = np.asarray(n, dtype=float)
        f = np.asarray(natural_frequencies(self.ring_samples(), self.geometry_params(), n[:, None]))  # (p, draws)
        if noise:
            rel = float(np.median(np.asarray(self.data["sigma_hz"]) / np.asarray(self.data["freq_hz"])))
            rng = np.random.default_rng(seed)
            f = f * (1 + rel * rng.standard_normal(f.shape))
        q = np.percentile(f, [(1 - level) / 2 * 100, 50, (1 + level) / 2 * 100], axis=1)
        return dict(n=n, lo=q[0], median=q[1], hi=q[2])

    def diagnostics(self) -> dict:
        """τ, chain length / τ, acceptance, R̂ and ESS, with a one-line verdict."""
        rhat = self.rhat()
        verdict = (f"chain of {self.steps} steps is {self.steps / np.max(self.tau):.0f} τ long "
                   f"(target > {TAU_FACTOR} τ)")
        return dict(tau=self.tau, steps=self.steps, walkers=self.chain.shape[1],
                    acceptance_mean=float(self.acceptance.mean()), rhat=rhat, ess=self.ess(),
                    converged=self.converged, verdict=verdict)

    def save(self, path, *, overwrite: bool = False) -> Path:
        """Write to HDF5 (atomic; refuses to overwrite unless asked)."""
        import h5py

        from ringfit.io.files import atomic_write, check_output_path

        path = check_output_path(path, overwrite=overwrite)

        def write(tmp):
            with h5py.File(tmp, "w") as h5:
                h5.attrs["format"] = FORMAT
                h5.create_dataset("chain", data=self.chain, compression="gzip")
                h5.create_dataset("log_prob", data=self.log_prob, compression="gzip")
                h5.create_dataset("acceptance", data=self.acceptance)
                h5.create_dataset("tau", data=self.tau)
                meta = dict(names=list(self.names), values0=self.values0, burn=self.burn, thin=self.thin,
                            geometry=self.geometry, priors=self.priors, source=self.source, lsq=self.lsq,
                            data={k: (np.asarray(v).tolist() if not isinstance(v, str) else v)
                                  for k, v in self.data.items()})
                h5.attrs["meta"] = json.dumps(meta, default=float)

        return atomic_write(path, write)


def load_posterior(path) -> Posterior:
    """Read a posterior written by :meth:`Posterior.save`; InputError naming the file for anything else."""
    import h5py

    from ringfit.errors import InputError

    path = Path(path)
    if not path.exists():
        raise InputError("file not found", source=path)
    try:
        with h5py.File(path, "r") as h5:
            if h5.attrs.get("format") != FORMAT:
                raise InputError(f"not a ringfit posterior (format {h5.attrs.get('format')!r})", source=path)
            meta = json.loads(h5.attrs["meta"])
            arrays = {k: np.asarray(h5[k][()], dtype=np.float64) for k in ("chain", "log_prob", "acceptance", "tau")}
        data = {k: (np.asarray(v) if isinstance(v, list) else v) for k, v in meta["data"].items()}
        post = Posterior(names=tuple(str(n) for n in meta["names"]), values0=dict(meta["values0"]),
                         burn=int(meta["burn"]), thin=int(meta["thin"]), data=data, geometry=dict(meta["geometry"]),
                         priors=dict(meta["priors"]), source=str(meta["source"]), lsq=dict(meta.get("lsq", {})),
                         **arrays)
        steps, walkers, k = post.chain.shape
        if (k != len(post.names) or post.log_prob.shape != (steps, walkers) or post.acceptance.shape != (walkers,)
                or post.tau.shape != (k,) or not 0 <= post.burn < steps or post.thin < 1):
            raise ValueError("inconsistent shapes")
    except InputError:
        raise
    except (OSError, KeyError, TypeError, ValueError, AttributeError, RecursionError, OverflowError) as exc:
        text = str(exc).splitlines()[0][:120] if str(exc) else ""
        raise InputError(f"not a readable ringfit posterior ({exc.__class__.__name__}: {text})", source=path) from None
    return post


def run_ensemble(log_prob_fn, p0, *, min_steps: int, max_steps: int, check_every: int = 1000, seed: int = 0,
                 progress: bool = False):
    """Run ``emcee.EnsembleSampler(vectorize=True)`` until the chain exceeds :data:`TAU_FACTOR` τ.

    **Arguments:** ``log_prob_fn`` — ``(walkers, k) -> (walkers,)`` NumPy float64,
    −inf outside the support; ``p0`` — ``(walkers, k)`` start; the chain grows in
    blocks of ``check_every`` after ``min_steps`` until it is longer than
    :data:`TAU_FACTOR` × max τ or reaches ``max_steps``; ``progress`` — tqdm bar on stderr.

    **Returns:** ``(sampler, tau)`` with ``tau`` ``(k,)`` the integrated autocorrelation times.
    """
    import emcee

    walkers, k = np.shape(p0)
    sampler = emcee.EnsembleSampler(walkers, k, log_prob_fn, vectorize=True)
    sampler.random_state = np.random.RandomState(seed).get_state()
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=min_steps, desc="sampling", unit="step", leave=False)
    state = p0
    tau = np.full(k, np.inf)
    while sampler.iteration < max_steps:
        block = check_every if sampler.iteration >= min_steps else min_steps - sampler.iteration
        block = min(block, max_steps - sampler.iteration)
        for state in sampler.sample(state, iterations=block):
            if bar is not None:
                bar.update(1)
        tau = sampler.get_autocorr_time(tol=0)
        if bar is not None:
            bar.set_postfix_str(f"τ≈{np.max(tau):.0f}, need {TAU_FACTOR * np.max(tau):.0f} steps")
        if np.all(np.isfinite(tau)) and sampler.iteration > TAU_FACTOR * np.max(tau):
            break
        if bar is not None:
            bar.total = min(max_steps, max(sampler.iteration + check_every, int(TAU_FACTOR * np.max(tau))))
            bar.refresh()
    if bar is not None:
        bar.close()
    return sampler, np.asarray(tau)


def sample_posterior(
    table,
    geometry: TyreGeometry,
    initial: RingParams,
    *,
    free=DEFAULT_FREE,
    prior="physical",
    modes=None,
    default_relative_std: float = DEFAULT_RELATIVE_STD,
    walkers: int = 32,
    min_steps: int = 2000,
    max_steps: int = 20000,
    check_every: int = 1000,
    seed: int = 0,
    progress: bool = True,
) -> Posterior:
    """Sample the posterior of the free ring parameters with emcee.

    **Arguments:** as :func:`~ringfit.fit.least_squares.fit_natural_frequencies`,
    plus ``walkers``, ``min_steps``/``max_steps`` (chain length bounds),
    ``check_every`` (steps between autocorrelation checks), ``seed``,
    ``progress`` (tqdm bar on stderr).

    **Returns:** :class:`Posterior`. Warns (``RuntimeWarning``) when the chain
    did not reach :data:`TAU_FACTOR` autocorrelation times by ``max_steps``.
    """
    free = check_free(free)
    lsq = fit_natural_frequencies(table, geometry, initial, free=free, prior=prior, modes=modes,
                                  default_relative_std=default_relative_std)
    data = frequency_data(table, modes, default_relative_std)
    priors = resolve_priors(prior, free)
    mu, sd, mask = prior_arrays(priors, free)
    lo, hi = log_bounds(free)
    base = ring_vector(initial)
    free_index = tuple(RING_FIELDS.index(k) for k in free)
    args = tuple(jnp.asarray(a) if isinstance(a, np.ndarray) else a for a in
                 (base, geometry, data.n, data.freq_hz, data.sigma_hz, mu, sd, mask, lo, hi))
    logp = batched_log_probability(free_index)

    def log_prob_fn(x):
        return np.asarray(logp(jnp.asarray(x), args), dtype=np.float64)

    rng = np.random.default_rng(seed)
    y_opt = np.clip(np.log([lsq.values[k] for k in free]), lo + 0.05, hi - 0.05)
    step = np.sqrt(np.clip(np.diag(lsq.covariance_log), 1e-8, 0.01))
    p0 = y_opt + 0.1 * step * rng.standard_normal((walkers, len(free)))
    p0 = np.clip(p0, lo + 1e-6, hi - 1e-6)
    sampler, tau = run_ensemble(log_prob_fn, p0, min_steps=min_steps, max_steps=max_steps,
                                check_every=check_every, seed=int(rng.integers(2**31)), progress=progress)
    chain = sampler.get_chain()
    tmax = float(np.max(tau)) if np.all(np.isfinite(tau)) else chain.shape[0] / 10
    burn = int(min(2 * tmax, chain.shape[0] // 2))
    thin = max(1, int(tmax / 2))
    post = Posterior(
        names=free,
        values0={k: float(v) for k, v in zip(RING_FIELDS, base)} | {k: lsq.values[k] for k in free},
        chain=chain, log_prob=sampler.get_log_prob(), acceptance=sampler.acceptance_fraction,
        tau=np.asarray(tau), burn=burn, thin=thin,
        data=dict(n=data.n, freq_hz=data.freq_hz, sigma_hz=data.sigma_hz, sigma_source=data.sigma_source),
        geometry=dict(radius=float(geometry.radius), width=float(geometry.width),
                      pressure=float(geometry.pressure), pressure_bar=float(geometry.pressure) / BAR,
                      name=geometry.name),
        priors={k: dict(median=p.median, sigma_ln=p.sigma_ln, source=p.source) for k, p in priors.items()},
        source=table.source,
        lsq=dict(status=lsq.status, values={k: lsq.values[k] for k in free},
                 stderr={k: lsq.stderr[k] for k in free}, flags=lsq.flags),
    )
    if not post.converged:
        warnings.warn(
            f"posterior chain of {post.steps} steps is only {post.steps / max(tmax, 1e-9):.1f} autocorrelation "
            f"times long (< {TAU_FACTOR}); increase max_steps or treat intervals as rough",
            RuntimeWarning, stacklevel=2,
        )
    return post


__all__ = ["Posterior", "sample_posterior", "run_ensemble", "load_posterior", "log_probability", "batched_log_probability",
           "TAU_FACTOR"]
