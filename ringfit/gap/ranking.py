"""Refit baseline + effect(s) and rank candidates by held-out evidence.

One engine for both kinds of data (:class:`~ringfit.gap.problem.GapProblem`):

- **Refit**: bounded least squares (``scipy.optimize.least_squares``, TRF)
  over the baseline parameters (log, with a weak log-normal prior around the
  baseline fit) and the chain's effect parameters (natural units scaled by
  their range, bounded, optional Gaussian prior); every other effect stays at
  its null. The baseline prior may be correlated (the profile baseline's ring
  stiffnesses carry the free-table fit's covariance): it enters as whitened
  residual rows. Prediction and Jacobian come from one jitted forward-mode
  pass of the problem (:func:`predict_and_jacobian`): one compiled function
  serves every candidate, chain and fold.
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
#: Least-squares tolerances (relative change of the cost / of the parameters; gradient).
#: 1e-8 of a χ² of thousands is far below any difference the verdict looks at.
FTOL, XTOL, GTOL = 1e-8, 1e-8, 1e-8
#: Trust-region subproblem solver of TRF: ``"lsmr"`` (iterative, products with J only) rather than an SVD
#: of the (rows × parameters) Jacobian at every step, which dominated the refits of thousands of rows.
TR_SOLVER = "lsmr"
_JAC_CACHE: dict = {}


def _jacobian_fn(problem: GapProblem):
    key = problem.predict
    fn = _JAC_CACHE.get(key)
    if fn is None:
        fn = jax.jit(jax.jacfwd(problem.predict))
        _JAC_CACHE[key] = fn
    return fn


def predict_and_jacobian(problem: GapProblem, theta: np.ndarray, free) -> tuple[np.ndarray, np.ndarray]:
    """Prediction ``(m,)`` and ∂pred/∂theta for the ``free`` columns ``(m, len(free))`` (natural units of theta).

    Uses the problem's one-pass forward-mode function when it has one (a fixed
    number K of tangents, padded with zeros: one compilation for every chain),
    else ``predict`` and its full forward-mode Jacobian.
    """
    free = np.asarray(free, dtype=int)
    th = jnp.asarray(theta)
    if problem.jacobian is None:
        pred = np.asarray(problem.predict(th, problem.data))
        return pred, np.asarray(_jacobian_fn(problem)(th, problem.data))[:, free]
    K = int(problem.meta.get("tangents", 8))
    out, pred = [], None
    for start in range(0, max(len(free), 1), K):
        cols = free[start : start + K]
        basis = np.zeros((theta.size, K))
        basis[cols, np.arange(cols.size)] = 1.0
        p, J = problem.jacobian(th, problem.data, jnp.asarray(basis))
        pred = np.asarray(p) if pred is None else pred
        out.append(np.asarray(J)[:, : cols.size])
    return pred, np.concatenate(out, axis=1)


def jacobian_columns(problem: GapProblem, theta: np.ndarray, free) -> np.ndarray:
    """∂pred/∂theta for the ``free`` columns only, ``(m, len(free))`` (see :func:`predict_and_jacobian`)."""
    return predict_and_jacobian(problem, theta, free)[1]


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
    # prior rows: baseline (possibly correlated, whitened) and each effect's Gaussian prior
    pidx, pmean, pW = problem.prior_rows()
    col_of = {int(i): j for j, i in enumerate(free)}
    base_prior = [(col_of[int(i)]) for i in pidx]
    eff_prior = []  # (position in free, mean_u, sd_u)
    for j, i in enumerate(free):
        if i >= nb:
            _, null, _, _, prior, span = info[i]
            if prior is not None:
                eff_prior.append((j, (prior[0] - null) / span, prior[1] / span))
    n_prior = len(base_prior) + len(eff_prior)
    Jp = np.zeros((n_prior, len(free)))
    if base_prior:
        Jp[: len(base_prior), base_prior] = pW
    for r, (j, _, sd) in enumerate(eff_prior):
        Jp[len(base_prior) + r, j] = 1.0 / sd

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

    def evaluate(u, need_jac=False):
        """(theta, pred, J or None) at u; one forward pass gives pred and J where the problem allows."""
        key = u.tobytes()
        hit = cache.get(key)
        if hit is None or (need_jac and hit[2] is None):
            th = to_theta(u)
            if need_jac or problem.jacobian is not None:
                p, J = predict_and_jacobian(problem, th, free)
            else:
                p, J = np.asarray(predict(jnp.asarray(th), data)), None
            cache.clear()
            cache[key] = hit = (th, p, J)
        return hit

    def prior_resid(u):
        out = [pW @ (u[base_prior] - pmean)] if base_prior else []
        out.append(np.asarray([(u[j] - mu) / sd for j, mu, sd in eff_prior], dtype=np.float64))
        return np.concatenate(out)

    def fun(u):
        th, p, _ = evaluate(u)
        r = np.where(train, (p - y) * w, 0.0)
        out = np.concatenate([r[train], prior_resid(u)])
        return np.where(np.isfinite(out), out, 1e6)

    def jac(u):
        th, _, J = evaluate(u, need_jac=True)
        J = J * dtheta_du(u, th)[None, :]
        Jd = (J * w[:, None])[train]
        out = np.vstack([Jd, Jp])
        return np.where(np.isfinite(out), out, 0.0)

    sol = least_squares(fun, u0, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac", tr_solver=TR_SOLVER,
                        max_nfev=max_nfev, xtol=XTOL, ftol=FTOL, gtol=GTOL)
    th, p, _ = evaluate(sol.x)
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
    scale = problem.scale if problem.scale.shape == r_base.shape else 1.0  # a subset of rows: already scaled
    rb2, rc2 = (r_base * scale) ** 2, (r_cand * scale) ** 2
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


def prior_distance(problem: GapProblem, theta: np.ndarray, exclude=()) -> tuple[float, int]:
    """Squared Mahalanobis distance of the prior-guarded baseline parameters from their prior.

    The guarded parameters are ``problem.meta["prior_guarded"]`` (baseline indices whose prior
    comes from independent data — for profiles the ring stiffnesses from the free-table fit),
    less the names in ``exclude`` (an effect's ``baseline_partners``, marginalised out).
    **Returns:** ``(D², k)``; ``(0, 0)`` when nothing is guarded. Under the prior D² ~ χ²_k.
    """
    idx = [i for i in problem.meta.get("prior_guarded", ()) if problem.base[i] not in exclude]
    if not idx or problem.base_prior_cov is None:
        return 0.0, 0
    mean = np.asarray(problem.base_prior_mean if problem.base_prior_mean is not None else problem.base_values)
    d = np.log(np.asarray(theta)[idx]) - np.log(mean[idx])
    cov = np.asarray(problem.base_prior_cov)[np.ix_(idx, idx)]
    return float(d @ np.linalg.solve(cov, d)), len(idx)
