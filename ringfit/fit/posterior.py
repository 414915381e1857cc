"""The one posterior of ringfit: the affine-invariant ensemble sampler on any problem of the least-squares engine.

:func:`sample` takes a :class:`~ringfit.fit.result.FitResult` of
:func:`ringfit.fit.engine.least_squares` and samples its free parameters in the
solver coordinates ``u`` (log for positive parameters, scaled for linear ones; docs/physics.md §12):

- likelihood ``−½ Σ r²`` of the problem's weighted residuals (divided by the
  fit's residual σ when the problem's ``sigma`` is ``"estimate"``, and by a per-row widening
  ``row_scale`` where given: identify's Student-t widening and model-discrepancy ratio);
- prior: the problem's Gaussian prior on ``u``, flat elsewhere, truncated to the
  coordinates' bounds and the problem's plausible ranges;
- sampler (``sampler=``): ``"compiled"`` (default) — Goodman & Weare's stretch move as one compiled
  program per block of steps (:mod:`ringfit.fit.ensemble`), several independent ensembles batched
  (``chains``); ``"emcee"`` — the same move by ``emcee.EnsembleSampler(vectorize=True)`` on one jitted,
  vmapped log-probability evaluated in fixed chunks of half the walkers, the reference;
- walkers start in a small ball around the least-squares optimum; the chain grows
  in blocks until it is longer than :data:`TAU_FACTOR` integrated autocorrelation
  times (or ``max_steps``, with a warning);
- a posterior predictive check of every measured table's χ² (:func:`predictive_check`).

:class:`Posterior` holds the draws and diagnostics (arviz R̂ and ESS) and saves to
HDF5 with whatever the problem wants kept beside them (``meta``), so that a report
can be rebuilt from the file alone. :func:`sample_posterior` is the free-tyre
(eq. 18, docs/physics.md §2.1) convenience built on it.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import signal
import threading
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from ringfit.fit.engine import LOG, free_set, log_density, log_probability
from ringfit.fit.priors import PriorSpec
from ringfit.params import RingParams

#: Stop when the chain is longer than this many integrated autocorrelation times.
TAU_FACTOR = 50
FORMAT = "ringfit-posterior/2"
#: Earlier files (every free parameter a logarithm) still load.
FORMATS_READ = ("ringfit-posterior/1", FORMAT)


def _arviz():
    """arviz, imported quietly (its import warns about a coming refactor)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz

    return arviz


@dataclass
class Posterior:
    """Posterior draws and sampler diagnostics.

    - ``names``: free parameters ``(k,)``; ``kinds``: ``"log"``/``"linear"`` per name, with
      ``centers``, ``scales`` of the linear ones (θ = center + scale·u).
    - ``values0``: every parameter of the problem (fixed ones at their values, free ones at
      the least-squares optimum), natural units.
    - ``chain``: ``(steps, walkers, k)`` solver coordinates u; ``log_prob``: ``(steps, walkers)``.
    - ``acceptance``: ``(walkers,)`` acceptance fractions; ``tau``: ``(k,)`` integrated
      autocorrelation times [steps]; ``burn``, ``thin``: what :attr:`samples` discards and keeps.
    - ``meta``: what the problem keeps beside the draws (data, geometry, priors, the
      least-squares fits, …; JSON-serialisable), saved with them.
    """

    names: tuple[str, ...]
    kinds: tuple[str, ...]
    values0: dict[str, float]
    chain: np.ndarray
    log_prob: np.ndarray
    acceptance: np.ndarray
    tau: np.ndarray
    burn: int
    thin: int
    centers: tuple[float, ...] = ()
    scales: tuple[float, ...] = ()
    meta: dict = field(default_factory=dict)
    sampler: str = "emcee"
    chains: int = 1
    shift_u: np.ndarray | None = None
    seed: int = 0

    @property
    def steps(self) -> int:
        return self.chain.shape[0]

    @property
    def converged(self) -> bool:
        """Chain longer than :data:`TAU_FACTOR` × the largest τ."""
        return bool(np.all(np.isfinite(self.tau)) and self.steps > TAU_FACTOR * np.max(self.tau))

    @property
    def log_samples(self) -> np.ndarray:
        """``(draws, k)`` flattened draws of the solver coordinates after burn-in and thinning.

        With ``shift_u`` (systematic directions δu, ``(k,)`` or ``(d, k)``: identify's grid check and its held
        friction, docs/physics.md §12.3) each draw is moved by Σ ε_j δu_j, ε_j ~ N(0, 1) drawn once per draw from
        ``seed``: the posterior convolved with those doubts, as the least-squares covariance adds Σ δu_j δu_jᵀ."""
        u = self.chain[self.burn :: self.thin].reshape(-1, len(self.names))
        if self.shift_u is not None and np.any(self.shift_u != 0):
            shifts = np.atleast_2d(np.asarray(self.shift_u, dtype=np.float64))
            eps = np.random.default_rng([int(self.seed), 7919]).standard_normal((u.shape[0], shifts.shape[0]))
            u = u + eps @ shifts
        return u

    @property
    def samples(self) -> np.ndarray:
        """``(draws, k)`` parameter draws in natural (SI) units."""
        u = self.log_samples
        out = np.empty_like(u)
        for i, kind in enumerate(self.kinds):
            out[:, i] = np.exp(u[:, i]) if kind == LOG else self.centers[i] + self.scales[i] * u[:, i]
        return out

    def ring_samples(self) -> RingParams:
        """A RingParams whose free fields are ``(draws,)`` arrays (for problems whose parameters are ring fields)."""
        from ringfit.fit.least_squares import RING_FIELDS

        s = self.samples
        values = {k: np.full(s.shape[0], self.values0[k]) for k in RING_FIELDS}
        values.update({k: s[:, i] for i, k in enumerate(self.names) if k in values})
        return RingParams(**values)

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
        """Per parameter: mean, median, sd and the central ``level`` interval (natural units)."""
        s = self.samples
        q = [(1 - level) / 2 * 100, 50, (1 + level) / 2 * 100]
        rows = []
        for i, k in enumerate(self.names):
            lo, med, hi = np.percentile(s[:, i], q)
            rows.append(dict(name=k, mean=float(s[:, i].mean()), median=float(med), sd=float(s[:, i].std()),
                             lo=float(lo), hi=float(hi), tau=float(self.tau[i])))
        return rows

    def diagnostics(self) -> dict:
        """τ, chain length / τ, acceptance, R̂ and ESS, with a one-line verdict."""
        tmax = float(np.max(self.tau)) if np.all(np.isfinite(self.tau)) else math.nan
        verdict = (f"chain of {self.steps} steps is {self.steps / tmax:.0f} τ long (target > {TAU_FACTOR} τ)"
                   if math.isfinite(tmax) else f"chain of {self.steps} steps is too short to estimate τ")
        return dict(tau=self.tau, steps=self.steps, walkers=self.chain.shape[1],
                    acceptance_mean=float(self.acceptance.mean()), rhat=self.rhat(), ess=self.ess(),
                    converged=self.converged, verdict=verdict)

    def to_inference_data(self):
        """The draws as an arviz ``InferenceData``, for your own diagnostics and plots.

        Walkers are arviz's chains (as in :meth:`rhat`), after burn-in and thinning.

        Returns
        -------
        arviz.InferenceData
            ``posterior``: one variable per free parameter, natural (SI) units, dims
            ``(chain, draw)``; ``sample_stats``: ``lp`` (log posterior density up to a
            constant); ``observed_data``: the fitted frequencies ``freq_hz`` (dim ``mode``,
            coordinate ``n``) when the posterior is a free-tyre one; attributes: ``burn``,
            ``thin``, ``tau`` (per parameter, in steps), ``converged``, ``acceptance_mean``,
            ``source`` (``ringfit``) and the file format.

        Examples
        --------
        >>> import numpy as np
        >>> from ringfit.fit.posterior import Posterior
        >>> rng = np.random.default_rng(0)
        >>> post = Posterior(names=("ei",), kinds=("log",), values0={"ei": 0.5},
        ...                  chain=np.log(0.5) + 0.01 * rng.standard_normal((200, 8, 1)),
        ...                  log_prob=np.zeros((200, 8)), acceptance=np.full(8, 0.4),
        ...                  tau=np.array([3.0]), burn=10, thin=2)
        >>> idata = post.to_inference_data()
        >>> idata.posterior["ei"].shape  # (walkers, draws kept)
        (8, 95)
        >>> round(float(idata.posterior["ei"].median()), 2)
        0.5
        """
        az = _arviz()
        kept = slice(self.burn, None, self.thin)
        u = self.chain[kept]  # (draws, walkers, k)
        s = self.samples.reshape(u.shape)  # natural units, same order as log_samples
        posterior = {name: np.ascontiguousarray(s[:, :, i].T) for i, name in enumerate(self.names)}
        sample_stats = {"lp": np.ascontiguousarray(self.log_prob[kept].T)}
        observed, coords, dims = None, None, None
        data = self.meta.get("data") or {}
        if "freq_hz" in data and "n" in data:
            observed = {"freq_hz": np.asarray(data["freq_hz"], dtype=np.float64)}
            coords = {"mode": np.arange(observed["freq_hz"].size), "n": ("mode", np.asarray(data["n"]))}
            dims = {"freq_hz": ["mode"]}
        attrs = dict(source="ringfit", format=FORMAT, burn=int(self.burn), thin=int(self.thin),
                     sampler=self.sampler, ensembles=int(self.chains),
                     tau=np.asarray(self.tau, dtype=np.float64), converged=int(self.converged),
                     acceptance_mean=float(np.mean(self.acceptance)))
        idata = az.from_dict(posterior=posterior, sample_stats=sample_stats, observed_data=observed,
                             coords={"mode": coords["mode"]} if coords else None, dims=dims, attrs=attrs)
        if coords:
            idata.observed_data = idata.observed_data.assign_coords(n=coords["n"])
        return idata

    def save_netcdf(self, path, *, overwrite: bool = False, inputs=()) -> Path:
        """Write :meth:`to_inference_data` to a NetCDF file (``InferenceData.to_netcdf``; atomic, as :meth:`save`).

        Parameters
        ----------
        path : str or os.PathLike
            The ``.nc`` file; refused if it exists (unless ``overwrite``), is a folder or one of ``inputs``.
        overwrite : bool
            Replace an existing file.
        inputs : iterable of paths
            Files the caller read, never written.

        Returns
        -------
        pathlib.Path
            The file written; ``arviz.from_netcdf`` reads it back.
        """
        from ringfit.io.files import atomic_write, check_output_path

        path = check_output_path(path, overwrite=overwrite, inputs=inputs)
        idata = self.to_inference_data()
        return atomic_write(path, lambda tmp: idata.to_netcdf(str(tmp)))

    def save(self, path, *, overwrite: bool = False, inputs=()) -> Path:
        """Write to HDF5 (atomic; refuses to overwrite unless asked, and never an input)."""
        import h5py

        from ringfit.io.files import atomic_write, check_output_path

        path = check_output_path(path, overwrite=overwrite, inputs=inputs)

        # HDF5 is built in memory and written as bytes by Python: a full disk is one OSError here, never a
        # write failure inside the HDF5 library (whose cleanup of a half-written file can crash the process).
        buf = io.BytesIO()
        with h5py.File(buf, "w") as h5:
            h5.attrs["format"] = FORMAT
            h5.create_dataset("chain", data=self.chain, compression="gzip")
            h5.create_dataset("log_prob", data=self.log_prob, compression="gzip")
            h5.create_dataset("acceptance", data=self.acceptance)
            h5.create_dataset("tau", data=self.tau)
            if self.shift_u is not None:
                h5.create_dataset("shift_u", data=np.asarray(self.shift_u, dtype=np.float64))
            head = dict(names=list(self.names), kinds=list(self.kinds), centers=list(self.centers),
                        scales=list(self.scales), values0=self.values0, burn=self.burn, thin=self.thin,
                        sampler=self.sampler, chains=int(self.chains), seed=int(self.seed), meta=self.meta)
            h5.attrs["meta"] = json.dumps(head, default=_json_default, allow_nan=True)
        image = buf.getvalue()
        return atomic_write(path, lambda tmp: tmp.write_bytes(image))


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"cannot save {type(x).__name__} with a posterior")


def load_posterior(path) -> Posterior:
    """Read a posterior written by :meth:`Posterior.save` (formats ``ringfit-posterior/1`` and ``/2``).

    Anything else — not HDF5, another format, missing or malformed metadata,
    arrays of inconsistent shapes — is an :class:`InputError` naming the file.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from ringfit.fit.posterior import Posterior, load_posterior
    >>> post = Posterior(names=("ei",), kinds=("log",), values0={"ei": 0.5},
    ...                  chain=np.log(0.5) + 0.01 * np.random.default_rng(0).standard_normal((100, 4, 1)),
    ...                  log_prob=np.zeros((100, 4)), acceptance=np.full(4, 0.4), tau=np.array([2.0]),
    ...                  burn=4, thin=1)
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = load_posterior(post.save(Path(tmp) / "post.h5"))
    >>> back.names, back.samples.shape, bool(np.array_equal(back.chain, post.chain))
    (('ei',), (384, 1), True)
    """
    import h5py

    from ringfit.errors import InputError

    path = Path(path)
    if not path.exists():
        raise InputError("file not found", source=path)
    try:
        with h5py.File(path, "r") as h5:
            fmt = h5.attrs.get("format")
            if fmt not in FORMATS_READ:
                raise InputError(f"not a ringfit posterior (format {fmt!r})", source=path)
            head = json.loads(h5.attrs["meta"])
            arrays = {k: np.asarray(h5[k][()], dtype=np.float64) for k in ("chain", "log_prob", "acceptance", "tau")}
            shift = np.asarray(h5["shift_u"][()], dtype=np.float64) if "shift_u" in h5 else None
        if fmt == "ringfit-posterior/1":  # every free parameter a logarithm; problem details at the top level
            meta = {k: head[k] for k in ("data", "geometry", "priors", "source", "lsq") if k in head}
            head = dict(head, kinds=["log"] * len(head["names"]), centers=[], scales=[], meta=meta)
        meta = dict(head["meta"])
        if "data" in meta:
            meta["data"] = {k: (np.asarray(v) if isinstance(v, list) else v) for k, v in meta["data"].items()}
        k = len(head["names"])
        post = Posterior(names=tuple(str(n) for n in head["names"]), kinds=tuple(head["kinds"]),
                         values0=dict(head["values0"]), burn=int(head["burn"]), thin=int(head["thin"]),
                         centers=tuple(head["centers"]) or (0.0,) * k, scales=tuple(head["scales"]) or (1.0,) * k,
                         meta=meta, sampler=str(head.get("sampler", "emcee")), chains=int(head.get("chains", 1)),
                         seed=int(head.get("seed", 0)), shift_u=shift, **arrays)
        steps, walkers, kk = post.chain.shape
        if (kk != k or len(post.kinds) != k or len(post.centers) != k or len(post.scales) != k
                or post.log_prob.shape != (steps, walkers) or post.acceptance.shape != (walkers,)
                or post.tau.shape != (k,) or not 0 <= post.burn < steps or post.thin < 1
                or post.chains < 1 or walkers % post.chains
                or (shift is not None and (shift.ndim not in (1, 2) or shift.shape[-1] != k))):
            raise ValueError("arrays and metadata of inconsistent shapes")
    except InputError:
        raise
    except OSError as exc:
        raise InputError(f"not a readable HDF5 file ({str(exc).splitlines()[0][:120]})", source=path) from None
    except (KeyError, TypeError, ValueError, AttributeError, RecursionError, OverflowError) as exc:
        text = str(exc).splitlines()[0][:120] if str(exc) else ""
        raise InputError(f"damaged posterior file ({exc.__class__.__name__}: {text})", source=path) from None
    return post


#: Steps between updates of the progress bar's target (τ re-estimated, cheap).
BAR_UPDATE = 250


def run_ensemble(log_prob_fn, p0, *, min_steps: int, max_steps: int, check_every: int = 1000, seed: int = 0,
                 progress: bool = False):
    """Run ``emcee.EnsembleSampler(vectorize=True)`` until the chain exceeds :data:`TAU_FACTOR` τ.

    **Arguments:** ``log_prob_fn`` — ``(walkers, k) -> (walkers,)`` NumPy float64,
    −inf outside the support; ``p0`` — ``(walkers, k)`` start; the chain grows to
    ``min_steps``, then in blocks of ``check_every`` until it is longer than
    :data:`TAU_FACTOR` × max τ or reaches ``max_steps``; ``progress`` — tqdm bar on
    stderr whose total is the chain length the current τ estimate asks for,
    re-estimated every :data:`BAR_UPDATE` steps (so it settles early instead of jumping
    at each check).

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
    target = min_steps  # where the next convergence check happens
    with _interrupt_between_steps() as interrupted:
        try:
            while sampler.iteration < max_steps:
                stop = min(target, max_steps)
                state = _advance(sampler, state, stop, bar, interrupted, min_steps, max_steps)
                tau = sampler.get_autocorr_time(tol=0)
                if np.all(np.isfinite(tau)) and sampler.iteration > TAU_FACTOR * np.max(tau):
                    break
                target = sampler.iteration + check_every
        finally:
            if bar is not None:
                bar.close()
    return sampler, np.asarray(tau)


@contextlib.contextmanager
def _interrupt_between_steps():
    """Ctrl-C during sampling stops the chain between two steps, as a plain ``KeyboardInterrupt`` raised here.

    emcee prints a traceback for any exception raised inside the log-probability (its wrapper catches
    everything, prints, re-raises); the first SIGINT only sets a flag that :func:`_advance` reads after
    each step, a second one interrupts at once. Outside the main thread (a batch worker) nothing changes.
    """
    flag = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return
    previous = signal.getsignal(signal.SIGINT)

    def handler(signum, frame):
        flag.set()
        signal.signal(signal.SIGINT, previous)

    signal.signal(signal.SIGINT, handler)
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, previous)


def _advance(sampler, state, stop, bar, interrupted, min_steps, max_steps):
    """Run ``sampler`` to ``stop`` steps (progress in chunks of :data:`BAR_UPDATE`); Ctrl-C checked per step."""
    while sampler.iteration < stop:
        chunk = min(BAR_UPDATE, stop - sampler.iteration) if bar is not None else stop - sampler.iteration
        for state in sampler.sample(state, iterations=chunk):
            if interrupted.is_set():
                raise KeyboardInterrupt
        if bar is not None:
            if sampler.iteration > bar.total:  # the next check lies beyond the τ estimate
                bar.total = stop
            bar.update(chunk)
            if sampler.iteration >= 2 * BAR_UPDATE:
                t = float(np.max(sampler.get_autocorr_time(tol=0)))
                need = int(min(max_steps, max(min_steps, TAU_FACTOR * t))) if np.isfinite(t) else bar.total
                if need > bar.total:
                    bar.total = need
                bar.set_postfix_str(f"τ≈{t:.0f}")
                bar.refresh()
    return state


def _support(result, bounds: dict | None = None):
    """``(lo_u, hi_u)`` ``(k,)``: the free coordinates' bounds, replaced or narrowed by ``bounds`` (natural units)
    and the problem's plausible ranges (see :func:`log_probability_function`)."""
    problem = result.problem
    fs = free_set(problem, tuple(result.names))
    lo, hi = fs.lo_u.copy(), fs.hi_u.copy()
    coords = [problem.coords[i] for i in fs.index]
    for j, c in enumerate(coords):
        rng = (bounds or {}).get(c.name) or (problem.plausible or {}).get(c.name)
        if rng is not None:
            lo[j], hi[j] = c.to_u(rng[0]) if c.kind != LOG or rng[0] > 0 else -np.inf, c.to_u(rng[1])
    return lo, hi


def log_probability_function(result, bounds: dict | None = None, chunk: int | None = None, row_scale=None,
                             scale_marginal: dict | None = None):
    """``(n, k) -> (n,)`` NumPy log-posterior of a fit's free parameters (see the module docstring).

    **Arguments:** ``result`` — a FitResult of the engine; ``bounds`` — name -> (lo, hi)
    natural-unit bounds that replace or add to the coordinates' bounds and the problem's
    plausible ranges; ``chunk`` — evaluate in chunks of exactly this many rows (padded),
    so one compilation serves every batch size; ``row_scale`` — ``(m,)`` per-row widening
    of the rows' σ; ``scale_marginal`` — the rows' common σ scale integrated out
    (:func:`ringfit.fit.engine.log_density`).

    **Returns:** ``(log_prob_fn, lo_u (k,), hi_u (k,))``.
    """
    lo, hi = _support(result, bounds)
    log_prob = log_probability(result.problem, result.theta, tuple(result.names), lo_u=lo, hi_u=hi,
                               sigma_scale=float(result.extra.get("sigma_scale", 1.0)), chunk=chunk,
                               row_scale=row_scale, scale_marginal=scale_marginal)
    return log_prob, lo, hi


def log_density_function(result, bounds: dict | None = None, row_scale=None, scale_marginal: dict | None = None):
    """The same density as :func:`log_probability_function`, traceable: ``(kernel, consts, lo_u, hi_u)``
    (:func:`ringfit.fit.engine.log_density`), for the compiled sampler."""
    lo, hi = _support(result, bounds)
    kernel, consts = log_density(result.problem, result.theta, tuple(result.names), lo_u=lo, hi_u=hi,
                                 sigma_scale=float(result.extra.get("sigma_scale", 1.0)), row_scale=row_scale,
                                 scale_marginal=scale_marginal)
    return kernel, consts, lo, hi


#: Posterior draws the predictive check evaluates the model at (at most; every kept draw when fewer).
PPC_DRAWS = 400


def predictive_check(result, u_draws: np.ndarray, blocks: dict | None = None, row_scale=None,
                     draws: int = PPC_DRAWS, seed: int = 0, log_prob=None) -> dict:
    """Posterior predictive p-value of each measured table's χ² (docs/physics.md §12.4).

    For each of up to ``draws`` posterior draws θ_i (``u_draws`` ``(n, k)``, solver coordinates of the fit's
    free parameters), the table's χ²_obs(θ_i) = Σ r²/(s² c²) over its rows (the likelihood's own rows: ``s`` the
    fit's σ scale, ``c`` = ``row_scale``); data replicated from the same draw, y_rep = model(θ_i) + σ ε, give
    χ²_rep ~ χ²_m exactly, so the p-value ``P(χ²_rep ≥ χ²_obs)`` is the mean over draws of the χ²_m survival
    function at χ²_obs(θ_i) (the replication integrated out, not simulated). Small p: the model cannot
    reproduce that table's scatter — read its intervals with care.

    **Arguments:** ``result`` — the engine's FitResult the posterior was sampled from; ``blocks`` — table
    name → row indices (a slice or an index array) of the problem's data rows (default: one block of every row,
    named after the problem's ``data_label``); ``log_prob`` — ``(n,)`` the draws' log densities: with one block
    of every row its χ² is read from them (``−2 log p`` less the prior rows), no model evaluation.

    **Returns:** name → ``dict(rows, chi2_median, p_value)``.
    """
    from scipy.special import chdtrc  # the χ² survival function, as the verdicts use it (scipy.stats costs ~1 s)

    from ringfit.fit.engine import residuals_batch

    problem = result.problem
    u = np.asarray(u_draws, dtype=np.float64)
    pick = np.random.default_rng(seed).choice(u.shape[0], draws, replace=False) if u.shape[0] > draws else None
    if pick is not None:
        u = u[pick]
    fs = free_set(problem, tuple(result.names))
    blocks = blocks or {problem.data_label: slice(None)}
    m_all = int(np.size(result.residuals))
    whole = len(blocks) == 1 and all(isinstance(b, slice) and b == slice(None) for b in blocks.values())
    if whole and log_prob is not None:
        # one block of every row: χ²/s² (row-widened) = −2 log p − |W (u − mean)|², already evaluated by the sampler
        lp = np.asarray(log_prob, dtype=np.float64)
        lp = lp[pick] if pick is not None else lp
        k = u.shape[1]
        du = np.concatenate([u, np.zeros((u.shape[0], fs.size - k))], axis=1) - fs.prior_mean[None, :]
        c2_all = -2.0 * lp - np.sum((du @ fs.prior_w.T) ** 2, axis=1)
        z2 = None
    else:
        thetas = np.repeat(np.asarray(result.theta, dtype=np.float64)[None], u.shape[0], axis=0)
        for j, i in enumerate(fs.index):
            thetas[:, i] = problem.coords[i].from_u(u[:, j])
        r = residuals_batch(problem, thetas, chunk=min(64, u.shape[0]))  # (n, m)
        s = float(result.extra.get("sigma_scale", 1.0))
        z2 = r**2 / s**2
        if row_scale is not None:
            z2 = z2 / np.asarray(row_scale, dtype=np.float64)[None, :] ** 2
    out = {}
    for name, rows in blocks.items():
        c2 = c2_all if z2 is None else z2[:, rows].sum(axis=1)
        m = m_all if z2 is None else int(z2[0, rows].size)
        ok = np.isfinite(c2)
        p = float(np.mean(chdtrc(m, c2[ok]))) if ok.any() and m > 0 else math.nan
        out[str(name)] = dict(rows=m, chi2_median=float(np.median(c2[ok])) if ok.any() else math.nan, p_value=p)
    return out


#: The samplers of :func:`sample`: the compiled stretch move (:mod:`ringfit.fit.ensemble`, the default) and
#: emcee's (the reference; same algorithm, driven from Python one step at a time).
Sampler = Literal["compiled", "emcee"]
#: The names of :data:`Sampler`, as :func:`sample` validates them.
SAMPLERS: tuple[str, ...] = get_args(Sampler)
#: Independent ensembles the compiled sampler runs side by side by default.
DEFAULT_CHAINS = 1


def fit_likelihood(result, row_scale="auto", shift_u="auto", tables="auto", scale_marginal="auto"):
    """``(row_scale, shift_u, tables, scale_marginal)`` that :func:`sample` uses: each ``"auto"`` one read from
    ``result.extra`` (the fit's own noise model; None where the fit recorded none), the others as given; with a
    scale marginal the rows' widening is the marginal's ``row_scale``. Raises ``ValueError`` for an explicit
    ``row_scale`` beside a marginal (two widenings of the same rows)."""
    extra = result.extra or {}

    def auto(v):
        return isinstance(v, str) and v == "auto"

    if auto(scale_marginal):
        scale_marginal = extra.get("scale_marginal")
    if scale_marginal is not None:
        if not auto(row_scale) and row_scale is not None:
            raise ValueError("sample: row_scale given beside a scale marginal, whose own row_scale is the rows' "
                             "widening; pass scale_marginal=None to sample with a fixed scale")
        row_scale = scale_marginal.get("row_scale")
    elif auto(row_scale):
        row_scale = extra.get("row_scale")
    shift_u = extra.get("shift_u") if auto(shift_u) else shift_u
    tables = extra.get("tables") if auto(tables) else tables
    return row_scale, shift_u, tables, scale_marginal


def sample(result, *, walkers: int = 32, min_steps: int = 2000, max_steps: int = 20000, check_every: int = 1000,
           seed: int = 0, progress: bool = True, bounds: dict | None = None, spread: float = 0.1,
           meta: dict | None = None, sampler: str = "compiled", chains: int = DEFAULT_CHAINS, row_scale="auto",
           shift_u="auto", tables="auto", scale_marginal="auto") -> "Posterior":
    """Sample the posterior of a least-squares fit's free parameters with the affine-invariant stretch move.

    **Arguments:** ``result`` — a :class:`~ringfit.fit.result.FitResult` of the engine;
    ``walkers`` (≥ 2k, even; per ensemble); ``min_steps``/``max_steps`` — chain length bounds (the chain
    stops once longer than :data:`TAU_FACTOR` τ); ``check_every`` — steps between τ checks (the compiled
    sampler's block); ``seed``; ``progress`` — tqdm bar on stderr; ``bounds`` — see
    :func:`log_probability_function`; ``spread`` — walkers start at the optimum plus
    ``spread`` × its standard error (in u, at most 0.1) times a standard normal draw;
    ``meta`` — kept with the draws (saved by :meth:`Posterior.save`); ``sampler`` — ``"compiled"``
    (:func:`ringfit.fit.ensemble.run_compiled`, the default) or ``"emcee"`` (the reference backend);
    ``chains`` — independent ensembles of ``walkers`` run side by side (compiled sampler only; the
    posterior's walker axis holds them one after another).

    **The likelihood is the fit's own** (docs/physics.md §12.3): ``"auto"`` (the default) reads each of these from
    ``result.extra``, where the fit that made ``result`` records its noise model (the free-modes block, identify's
    :meth:`~ringfit.fit.identify.Identification.posterior_fit`); an explicit value replaces the fit's.
    ``row_scale`` — ``(m,)`` widening of the rows' σ (a block's Student-t widening × √κ); ``shift_u`` — ``(k,)``
    or ``(d, k)``: systematic directions in u (identify's grid check, its held friction) convolved into the draws
    (:attr:`Posterior.log_samples`);
    ``tables`` — name → data rows of each measured table for the posterior predictive check
    (:func:`predictive_check`, kept in ``meta["predictive_check"]``; None: one block of every row);
    ``scale_marginal`` — ``dict(rows, s_min, row_scale)``: the rows' common σ scale integrated out
    (:func:`ringfit.fit.engine.log_density`), set by the free-modes block where it estimated a scale; its own
    ``row_scale`` (√κ) is then the rows' widening (the t-widening is the marginal itself), so an explicit
    ``row_scale`` beside a marginal is refused (pass ``scale_marginal=None`` to sample a fixed scale).

    **Returns:** :class:`Posterior`. Warns (``RuntimeWarning``) when the chain did not reach
    :data:`TAU_FACTOR` autocorrelation times by ``max_steps``.
    """
    from ringfit.errors import InputError

    free = tuple(result.names)
    k = len(free)
    if sampler not in SAMPLERS:
        raise InputError(f"sampler {sampler!r}: expected one of {', '.join(SAMPLERS)}")
    if walkers < 2 * k or walkers % 2:
        raise InputError(f"walkers = {walkers}: the stretch move needs an even number of at least {2 * k} "
                         f"(2 × {k} parameters)")
    if not 1 <= min_steps <= max_steps:
        raise InputError(f"chain length: need 1 <= min_steps ({min_steps}) <= max_steps ({max_steps})")
    chains = 1 if sampler == "emcee" else int(chains)
    if chains < 1:
        raise InputError(f"chains = {chains}: expected at least 1")
    problem = result.problem
    row_scale, shift_u, tables, scale_marginal = fit_likelihood(result, row_scale, shift_u, tables, scale_marginal)
    lo, hi = _support(result, bounds)
    coords = [problem.coordinate(n) for n in free]
    y_opt = np.array([c.to_u(result.values[n]) for c, n in zip(coords, free)])
    width = np.where(np.isfinite(hi - lo), hi - lo, np.inf)
    y_opt = np.clip(y_opt, lo + np.minimum(0.05, 0.01 * width), hi - np.minimum(0.05, 0.01 * width))
    step = np.sqrt(np.clip(np.diag(result.covariance_log), 1e-8, 0.01))
    rng = np.random.default_rng(seed)
    p0 = y_opt + spread * step * rng.standard_normal((chains, walkers, k))
    p0 = np.clip(p0, lo + 1e-9 * np.minimum(width, 1.0), hi - 1e-9 * np.minimum(width, 1.0))
    if sampler == "emcee":
        log_prob, _, _ = log_probability_function(result, bounds, chunk=walkers // 2, row_scale=row_scale,
                                                  scale_marginal=scale_marginal)
        ens, tau = run_ensemble(log_prob, p0[0], min_steps=min_steps, max_steps=max_steps, check_every=check_every,
                                seed=int(rng.integers(2**31)), progress=progress)
        chain, log_p, acceptance = ens.get_chain(), ens.get_log_prob(), ens.acceptance_fraction
    else:
        from ringfit.fit.ensemble import run_compiled

        kernel, consts, _, _ = log_density_function(result, bounds, row_scale=row_scale, scale_marginal=scale_marginal)
        with _interrupt_between_steps() as interrupted:
            run = run_compiled(kernel, consts, p0, min_steps=min_steps, max_steps=max_steps,
                               block=min(check_every, max_steps),
                               seed=int(rng.integers(2**31)), tau_factor=TAU_FACTOR, progress=progress,
                               interrupted=interrupted)
        chain, log_p, acceptance, tau = run.chain, run.log_prob, run.acceptance, run.tau
    tmax = float(np.max(tau)) if np.all(np.isfinite(tau)) else chain.shape[0] / 10
    burn = int(min(2 * tmax, chain.shape[0] // 2))
    thin = max(1, int(tmax / 2))
    post = Posterior(
        names=free, kinds=tuple(c.kind for c in coords), values0=dict(result.values), chain=chain,
        log_prob=log_p, acceptance=np.asarray(acceptance), tau=np.asarray(tau),
        burn=burn, thin=thin, centers=tuple(c.center for c in coords), scales=tuple(c.scale for c in coords),
        meta=dict(meta or {}), sampler=sampler, chains=chains,
        shift_u=None if shift_u is None else np.asarray(shift_u, dtype=np.float64), seed=int(seed),
    )
    post.meta["predictive_check"] = predictive_check(result, post.chain[post.burn :: post.thin].reshape(-1, k),
                                                     tables, row_scale=row_scale, seed=seed,
                                                     log_prob=None if scale_marginal is not None else
                                                     post.log_prob[post.burn :: post.thin].reshape(-1))
    if not post.converged:
        warnings.warn(
            f"posterior chain of {post.steps} steps is only {post.steps / max(tmax, 1e-9):.1f} autocorrelation "
            f"times long (< {TAU_FACTOR}); increase max_steps or treat intervals as rough",
            RuntimeWarning, stacklevel=2,
        )
    return post


# ----------------------------------------------------------------------------- the free tyre (eq. 18)


def sample_posterior(
    table,
    geometry,
    initial: RingParams,
    *,
    free=None,
    prior: PriorSpec = "physical",
    modes=None,
    default_relative_std: float | None = None,
    walkers: int = 32,
    min_steps: int = 2000,
    max_steps: int = 20000,
    check_every: int = 1000,
    seed: int = 0,
    progress: bool = True,
    lsq=None,
    data_only=None,
    sampler: Sampler = "compiled",
    chains: int = DEFAULT_CHAINS,
) -> Posterior:
    """Posterior of ring parameters given measured natural frequencies (eq. 18, docs/physics.md §2.1).

    Likelihood: independent Gaussians on the frequencies with the noise model of the least-squares fit's
    intervals (:mod:`ringfit.fit.free_block`, docs/physics.md §11 "Noise per block"): the σ it settled, each row
    widened by its Student-t factor (``row_scale``). Priors on ``log θ``: the
    log-normal priors chosen (e.g. ``"physical"``), otherwise uniform in ``log θ`` within
    :data:`ringfit.fit.priors.BOUNDS` (every parameter is truncated there).

    **Arguments:** as :func:`~ringfit.fit.least_squares.fit_natural_frequencies`, plus the
    sampler's (:func:`sample`); ``lsq`` — the least-squares fit to start from (default:
    fitted here with the same arguments); ``data_only`` — ``(fit, identifiability)`` of the
    same table without an informative prior (default: computed here, with the profile
    likelihood of EI when it is free).

    **Returns:** :class:`Posterior` whose ``meta`` holds everything its report draws: the
    data (``n``, ``freq_hz``, ``sigma_hz``, ``sigma_source``, ``noise``, ``noise_scale``, ``noise_dof``,
    ``t_widening``, ``discrepancy``), ``geometry``, ``priors``,
    ``source``, ``lsq`` (the least-squares fit with the prior: values, standard errors,
    status, flags, model frequencies), ``data_only`` (the fit without a prior) and
    ``identifiability`` (its Fisher analysis and profile likelihood).
    """
    from ringfit.fit.identifiability import identifiability, profile_natural_frequencies
    from ringfit.fit.least_squares import DEFAULT_FREE, fit_natural_frequencies
    from ringfit.params import BAR

    free = DEFAULT_FREE if free is None else free
    rel = default_relative_std
    if lsq is None:
        lsq = fit_natural_frequencies(table, geometry, initial, free=free, prior=prior, modes=modes,
                                      default_relative_std=rel)
    if data_only is None:
        fit0 = fit_natural_frequencies(table, geometry, initial, free=free, prior="none", modes=modes,
                                       default_relative_std=rel)
        again = profile_natural_frequencies(table, geometry, initial, fit0.names, modes=modes,
                                            default_relative_std=rel,
                                            noise_scale=float(fit0.extra.get("noise_scale", 1.0)))
        data_only = (fit0, identifiability(fit0, profile=("ei",) if "ei" in fit0.names else (), fit_again=again))
    ex = lsq.extra
    meta = dict(
        model="eq18",
        data=dict(n=ex["n"], freq_hz=ex["freq_hz"], sigma_hz=ex["sigma_hz"], sigma_source=ex["sigma_source"],
                  noise=ex.get("noise", "fixed"), noise_scale=float(ex.get("noise_scale", 1.0)),
                  noise_dof=float(ex.get("noise_dof", math.inf)), t_widening=float(ex.get("t_widening", 1.0)),
                  discrepancy=float(ex.get("discrepancy", 0.0))),
        geometry=dict(radius=float(geometry.radius), width=float(geometry.width), pressure=float(geometry.pressure),
                      pressure_bar=float(geometry.pressure) / BAR, name=geometry.name),
        priors={k: dict(median=p.median, sigma_ln=p.sigma_ln, source=p.source) for k, p in ex["priors"].items()},
        source=str(table.source),
        lsq=lsq.to_record(model_hz=np.asarray(ex["model_hz"]).tolist()),
        data_only=data_only[0].to_record(model_hz=np.asarray(data_only[0].extra["model_hz"]).tolist()),
        identifiability=data_only[1].to_record(),
    )
    # the intervals' noise model (docs/physics.md §11 "Noise per block"): the settled σ (in the fit's rows) and
    # the block's Student-t widening per row, as the least-squares covariance has them
    return sample(lsq, walkers=walkers, min_steps=min_steps, max_steps=max_steps, check_every=check_every, seed=seed,
                  progress=progress, meta=meta, sampler=sampler, chains=chains,
                  tables={Path(str(table.source)).name or "modes": slice(None)})


def natural_frequency_predictive(post: Posterior, n, level: float = 0.95, noise: bool = True, seed: int = 0):
    """Posterior predictive natural frequencies (eq. 18) for indices ``n`` ``(p,)`` of a free-tyre posterior.

    **Returns:** dict of ``(p,)`` arrays ``n``, ``median``, ``lo``, ``hi`` [Hz]; with ``noise``
    each draw adds the measurement scatter (σ = the data's relative σ, median over modes, × f),
    i.e. where a new measurement should fall; without it the band is the model's credible band.
    """
    from ringfit.params import TyreGeometry
    from ringfit.physics.natural import natural_frequencies_jit as natural_frequencies

    g = post.meta["geometry"]
    geometry = TyreGeometry(g["radius"], g["width"], g["pressure"])
    n = np.asarray(n, dtype=float)
    f = np.asarray(natural_frequencies(post.ring_samples(), geometry, n[:, None]))  # (p, draws)
    if noise:
        data = post.meta["data"]
        rel = float(np.median(np.asarray(data["sigma_hz"]) / np.asarray(data["freq_hz"])))
        f = f * (1 + rel * np.random.default_rng(seed).standard_normal(f.shape))
    q = np.percentile(f, [(1 - level) / 2 * 100, 50, (1 + level) / 2 * 100], axis=1)
    return dict(n=n, lo=q[0], median=q[1], hi=q[2])


__all__ = ["Posterior", "sample", "predictive_check", "SAMPLERS", "Sampler", "sample_posterior", "run_ensemble", "load_posterior", "log_probability_function",
           "natural_frequency_predictive", "TAU_FACTOR"]
