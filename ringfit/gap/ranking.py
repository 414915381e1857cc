"""Refit baseline + effect(s) and rank candidates by held-out evidence.

One engine for both kinds of data (:class:`~ringfit.gap.problem.GapProblem`):

- **Refit**: bounded least squares (``scipy.optimize.least_squares``, TRF)
  over the baseline parameters (log, with a weak log-normal prior around the
  baseline fit) and the chain's effect parameters (natural units scaled by
  their range, bounded, optional Gaussian prior); every other effect stays at
  its null. The Jacobian comes from the problem's jitted predictor by forward
  differentiation; one compiled predictor and one compiled Jacobian serve every
  candidate and chain.
- **Held-out**: K-fold by ``problem.folds`` (leave-one-speed-out for
  profiles, interleaved leave-modes-out for mode tables); each fold refits on
  the other folds (warm start) and predicts the left-out rows.
- **Evidence**: ΔBIC = Δχ² + Δk·ln m (negative favours the effect).
- **Drift**: how far the baseline parameters moved when the effect was
  added, in standard errors of the reference baseline fit.
- **Intervals**: effect parameters ±1.96 σ (Laplace, σ inflated by
  √(χ²/dof) when > 1); held-out shrink by a block bootstrap of the held-out
  residuals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import least_squares

from ringfit.gap.problem import GapProblem

Z95 = 1.959964
_JAC_CACHE: dict = {}


def _jacobian_fn(problem: GapProblem):
    key = problem.predict
    fn = _JAC_CACHE.get(key)
    if fn is None:
        fn = jax.jit(jax.jacfwd(problem.predict))
        _JAC_CACHE[key] = fn
    return fn


def jacobian_columns(problem: GapProblem, theta: np.ndarray, free) -> np.ndarray:
    """∂pred/∂theta for the ``free`` columns only, ``(m, len(free))`` (natural units of theta).

    Uses the problem's directional-derivative function when it has one (a fixed
    number K of forward-mode tangents, padded with zeros: one compilation for
    every chain), else the full forward-mode Jacobian.
    """
    free = np.asarray(free, dtype=int)
    if problem.jacobian is None:
        return np.asarray(_jacobian_fn(problem)(jnp.asarray(theta), problem.data))[:, free]
    K = int(problem.meta.get("tangents", 8))
    out = []
    for start in range(0, len(free), K):
        cols = free[start : start + K]
        basis = np.zeros((theta.size, K))
        basis[cols, np.arange(cols.size)] = 1.0
        J = np.asarray(problem.jacobian(jnp.asarray(theta), problem.data, jnp.asarray(basis)))
        out.append(J[:, : cols.size])
    return np.concatenate(out, axis=1) if out else np.zeros((problem.m, 0))


@dataclass
class ChainFit:
    """A refit of the baseline plus a chain of effects.

    - ``theta``: full parameter vector (natural units); ``free``: indices fitted.
    - ``pred``: ``(m,)`` prediction on every row; ``train``: bool ``(m,)`` rows fitted.
    - ``cov_u``: covariance of the free parameters in solver units (log for the
      baseline, range-scaled for effects); ``se``: natural-unit standard errors (free).
    - ``chi2``: Σ((pred − y)/σ)² on the train rows; ``k``: number of free parameters.
    """

    chain: tuple[str, ...]
    theta: np.ndarray
    free: np.ndarray
    pred: np.ndarray
    train: np.ndarray
    cov_u: np.ndarray
    se: np.ndarray
    chi2: float
    k: int
    success: bool
    nfev: int
    heldout_pred: np.ndarray | None = None
    extra: dict = field(default_factory=dict)


def _free_indices(problem: GapProblem, chain) -> np.ndarray:
    sl = problem.slices()
    idx = list(range(len(problem.base)))
    for name in chain:
        idx.extend(range(sl[name].start, sl[name].stop))
    return np.asarray(idx, dtype=int)


def _param_table(problem: GapProblem):
    """Per theta entry: (kind, null, lo, hi, prior) with kind 'log' for baseline, 'lin' for effects."""
    out = [("log", None, None, None, None)] * len(problem.base)
    for e in problem.effects:
        for p in problem.effect_params(e):
            out.append(("lin", p.null, p.lo, p.hi, p.prior, p.span))
    return out


def fit_chain(problem: GapProblem, chain: tuple[str, ...] = (), train=None, start=None,
              max_nfev: int = 60) -> ChainFit:
    """Least-squares refit of the baseline + ``chain`` on the ``train`` rows (default all)."""
    m = problem.m
    train = np.ones(m, dtype=bool) if train is None else np.asarray(train, dtype=bool)
    free = _free_indices(problem, chain)
    theta0 = problem.null_theta() if start is None else np.array(start, dtype=np.float64)
    info = _param_table(problem)
    nb = len(problem.base)
    ref_log = np.log(np.where([problem.is_linear(i) for i in range(nb)], 1.0, problem.base_values))
    # starting point: effects of the chain at their interior start unless given
    if start is None:
        for name in chain:
            sl = problem.slices()[name]
            e = next(e for e in problem.effects if e.name == name)
            theta0[sl] = [p.start for p in problem.effect_params(e)]
    u0, lo, hi, spans = [], [], [], []
    for i in free:
        if i < nb and problem.is_linear(i):
            sc, bound = problem.base_linear_scale[i], problem.base_linear_bound[i]
            u0.append(theta0[i] / sc), lo.append(-bound / sc), hi.append(bound / sc)
            spans.append(sc)
        elif i < nb:
            u0.append(math.log(theta0[i])), lo.append(ref_log[i] - 3.0), hi.append(ref_log[i] + 3.0)
            spans.append(None)
        else:
            _, null, plo, phi, _, span = info[i]
            u0.append((theta0[i] - null) / span), lo.append((plo - null) / span), hi.append((phi - null) / span)
            spans.append(span)
    u0 = np.clip(np.asarray(u0), np.asarray(lo) + 1e-12, np.asarray(hi) - 1e-12)
    lo, hi = np.asarray(lo), np.asarray(hi)
    y, sig = problem.y, problem.sigma
    w = train / sig
    predict = problem.predict
    data = problem.data
    # prior rows
    prior_rows = []  # (position in free, mean_u, sd_u)
    for j, i in enumerate(free):
        if i < nb:
            sd = problem.base_prior_sd[i]
            if np.isfinite(sd) and not problem.is_linear(i):
                prior_rows.append((j, ref_log[i], sd))
        else:
            _, null, _, _, prior, span = info[i]
            if prior is not None:
                prior_rows.append((j, (prior[0] - null) / span, prior[1] / span))

    log_cols = [j for j, i in enumerate(free) if i < nb and not problem.is_linear(i)]

    def to_theta(u):
        th = theta0.copy()
        for j, i in enumerate(free):
            if j in log_cols:
                th[i] = math.exp(u[j])
            elif i < nb:
                th[i] = u[j] * spans[j]
            else:
                th[i] = info[i][1] + u[j] * spans[j]
        return th

    def dtheta_du(u, th):
        return np.array([th[i] if j in log_cols else spans[j] for j, i in enumerate(free)])

    cache = {}

    def evaluate(u):
        key = u.tobytes()
        if key not in cache:
            th = to_theta(u)
            p = np.asarray(predict(jnp.asarray(th), data))
            cache.clear()
            cache[key] = (th, p)
        return cache[key]

    def fun(u):
        th, p = evaluate(u)
        r = np.where(train, (p - y) * w, 0.0)
        pr = [(u[j] - mu) / sd for j, mu, sd in prior_rows]
        out = np.concatenate([r[train], np.asarray(pr, dtype=np.float64)])
        return np.where(np.isfinite(out), out, 1e6)

    def jac(u):
        th = to_theta(u)
        J = jacobian_columns(problem, th, free) * dtheta_du(u, th)[None, :]
        Jd = (J * w[:, None])[train]
        Jp = np.zeros((len(prior_rows), len(free)))
        for r, (j, _, sd) in enumerate(prior_rows):
            Jp[r, j] = 1.0 / sd
        out = np.vstack([Jd, Jp])
        return np.where(np.isfinite(out), out, 0.0)

    sol = least_squares(fun, u0, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac",
                        max_nfev=max_nfev, xtol=1e-10, ftol=1e-10, gtol=1e-10)
    th, p = evaluate(sol.x)
    J = jac(sol.x)
    try:
        cov_u = np.linalg.pinv(J.T @ J, rcond=1e-12)
    except np.linalg.LinAlgError:  # pragma: no cover
        cov_u = np.full((len(free), len(free)), np.inf)
    chi2 = float(np.sum(((p - y) / sig)[train] ** 2))
    dof = max(int(train.sum()) - len(free), 1)
    infl = math.sqrt(max(1.0, chi2 / dof))
    se = np.array([
        (th[i] if j in log_cols else spans[j]) * math.sqrt(max(cov_u[j, j], 0.0)) * infl for j, i in enumerate(free)
    ])
    return ChainFit(tuple(chain), th, free, p, train, cov_u, se, chi2, len(free), bool(sol.success),
                    int(sol.nfev))


def heldout(problem: GapProblem, fit: ChainFit, max_nfev: int = 40) -> np.ndarray:
    """Held-out predictions ``(m,)``: each fold predicted by a refit on the others (warm start from ``fit``)."""
    out = np.full(problem.m, np.nan)
    for f in np.unique(problem.folds):
        test = problem.folds == f
        sub = fit_chain(problem, fit.chain, train=fit.train & ~test, start=fit.theta, max_nfev=max_nfev)
        out[test] = sub.pred[test]
    fit.heldout_pred = out
    return out


def rms(problem: GapProblem, resid: np.ndarray, mask=None) -> float:
    """RMS of residuals in the problem's unit (``scale`` applied)."""
    r = resid * problem.scale
    if mask is not None:
        r = r[mask]
    return float(np.sqrt(np.mean(r**2)))


def shrink_interval(problem: GapProblem, r_base: np.ndarray, r_cand: np.ndarray, n_boot: int = 400,
                    seed: int = 0) -> tuple[float, float]:
    """95 % block-bootstrap interval of the shrink ``1 − rms_cand/rms_base`` [%] over rows."""
    rb2, rc2 = (r_base * problem.scale) ** 2, (r_cand * problem.scale) ** 2
    m = rb2.size
    block = int(problem.meta.get("block", 1))
    nb = max(1, math.ceil(m / block))
    rng = np.random.default_rng(seed)
    starts = rng.integers(0, m, size=(n_boot, nb))
    idx = (starts[:, :, None] + np.arange(block)[None, None, :]).reshape(n_boot, -1) % m
    sb, sc = rb2[idx].sum(1), rc2[idx].sum(1)
    s = 100.0 * (1.0 - np.sqrt(sc / np.maximum(sb, 1e-300)))
    return float(np.percentile(s, 2.5)), float(np.percentile(s, 97.5))


def drift(problem: GapProblem, fit: ChainFit, reference: ChainFit) -> dict[str, float]:
    """Baseline-parameter drift of ``fit`` from ``reference``, in the reference's standard errors."""
    out = {}
    nb = len(problem.base)
    for j in range(nb):
        se_u = math.sqrt(max(reference.cov_u[j, j], 1e-300))
        if problem.is_linear(j):
            d = (fit.theta[j] - reference.theta[j]) / problem.base_linear_scale[j] / se_u
        else:
            d = (math.log(fit.theta[j]) - math.log(reference.theta[j])) / se_u
        out[problem.base[j]] = float(d)
    return out


def fit_baseline(problem: GapProblem, mask) -> np.ndarray:
    """Baseline-only fit on the rows in ``mask``; returns the full theta (effects at null)."""
    return fit_chain(problem, (), train=mask).theta
