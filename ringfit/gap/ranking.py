"""Refit baseline + effect(s) and rank candidates by held-out evidence.

One engine for every refit (:func:`ringfit.fit.engine.least_squares`, the
engine of ``ringfit fit``), whatever the data (:class:`~ringfit.gap.problem.GapProblem`):

- **Refit**: the baseline parameters (log, bounded to e^±3 around the baseline
  fit, with the problem's baseline prior — possibly correlated, e.g. the profile
  baseline's ring stiffnesses carry the free-table fit's covariance) and the
  chain's effect parameters (natural units scaled by their range, bounded,
  optional Gaussian prior); every other effect stays at its null. Residuals are
  ``(prediction − y)/σ`` on the train rows (zero weight elsewhere). The free set
  is padded to a fixed size, so one compiled solve serves every candidate, chain
  and fold of a problem.
- **Held-out**: K-fold by ``problem.folds`` (leave-one-speed-out for profiles,
  interleaved leave-modes-out for mode tables); each fold refits on the other
  folds (warm start) and predicts the left-out rows.
- **Evidence**: ΔBIC = Δχ² + Δk·ln m (negative favours the effect).
- **Drift**: how far the baseline parameters moved when the effect was added, in
  standard errors of the reference baseline fit.
- **Intervals**: effect parameters ±1.96 σ (Laplace, σ inflated by √(χ²/dof) when
  > 1); held-out shrink by a block bootstrap of the held-out residuals.

Every fit is a :class:`~ringfit.fit.result.FitResult`; ``extra`` holds ``chain``,
``pred`` (prediction of every row), ``train`` (rows fitted) and, once computed,
``heldout_pred``.
"""

from __future__ import annotations

import math

import equinox as eqx
import numpy as np

from ringfit.fit.engine import (LINEAR, LOG, AbstractResiduals, Coordinate, GaussianPrior, Problem, evaluate,
                                least_squares)
from ringfit.fit.result import FitResult
from ringfit.gap.problem import GapProblem

Z95 = 1.959964
#: Solver tolerances (optimistix Cauchy termination on the solver coordinates and the residuals).
RTOL, ATOL = 1e-8, 1e-8
#: Baseline parameters move at most a factor e^3 from the baseline fit in a refit.
BASE_LOG_RANGE = 3.0


class GapResiduals(AbstractResiduals):
    """``(prediction(θ) − y)·w`` for a gap problem's predictor; aux: the prediction of every row."""

    predictor: object = eqx.field(static=True)

    def __call__(self, theta, data):
        pdata, y, w = data
        pred = self.predictor(theta, pdata)
        return (pred - y) * w, pred


def _engine_problem(problem: GapProblem, train) -> Problem:
    """The engine's problem of a gap refit: residuals ``(prediction − y)/σ`` on the ``train`` rows."""
    m = problem.m
    w = np.where(train, 1.0 / problem.sigma, 0.0)
    y = problem.y
    pad = int(problem.meta.get("padded_rows", m)) - m  # rows the predictor pads (weight 0)
    if pad:
        y, w = np.concatenate([y, np.zeros(pad)]), np.concatenate([w, np.zeros(pad)])
    return Problem(GapResiduals(problem.predictor), (problem.data, y, w), coordinates(problem),
                   prior=gap_prior(problem), sigma="inflate", data_label="the gap data")


def _pad(problem: GapProblem) -> int:
    return int(problem.meta.get("tangents", problem.n_theta))


def predict(problem: GapProblem, theta) -> np.ndarray:
    """Prediction ``(m,)`` of every row at ``theta`` (natural units) — one step of the compiled refit, no fit."""
    out = evaluate(_engine_problem(problem, np.ones(problem.m, dtype=bool)), np.asarray(theta, dtype=np.float64),
                   _free_names(problem, ()), pad_to=_pad(problem), rtol=RTOL, atol=ATOL)
    return np.asarray(out.extra["aux"])[: problem.m]


def predict_and_jacobian(problem: GapProblem, theta: np.ndarray, free) -> tuple[np.ndarray, np.ndarray]:
    """Prediction ``(m,)`` and ∂pred/∂theta for the ``free`` columns ``(m, len(free))`` (natural units of theta).

    Evaluated by the refit's own compiled solve stopped after its first linearisation
    (:func:`ringfit.fit.engine.evaluate`), in chunks of the padded free-set size. Used by the screen.
    """
    free = np.asarray(free, dtype=int)
    names = theta_names(problem)
    coords = coordinates(problem)
    theta = np.asarray(theta, dtype=np.float64)
    eng = _engine_problem(problem, np.ones(problem.m, dtype=bool))
    m, K = problem.m, _pad(problem)
    w = 1.0 / problem.sigma
    pred, cols = None, []
    for start in range(0, max(len(free), 1), K):
        chunk = free[start : start + K]
        out = evaluate(eng, theta, tuple(names[i] for i in chunk), pad_to=K, rtol=RTOL, atol=ATOL)
        pred = np.asarray(out.extra["aux"])[:m] if pred is None else pred
        dtheta_du = np.array([theta[i] if coords[i].kind == LOG else coords[i].scale for i in chunk])
        cols.append(out.jacobian[:m] / w[:, None] / dtheta_du[None, :])
    return pred, np.concatenate(cols, axis=1)


def theta_names(problem: GapProblem) -> tuple[str, ...]:
    """Names of the entries of theta: the baseline's, then ``effect.parameter`` for each effect."""
    return tuple(problem.base) + tuple(f"{e.name}.{p.name}" for e in problem.effects for p in problem.effect_params(e))


def coordinates(problem: GapProblem) -> tuple[Coordinate, ...]:
    """How each entry of theta is solved for (see the module docstring)."""
    out = []
    for i, name in enumerate(problem.base):
        if problem.is_linear(i):
            bound = problem.base_linear_bound[i]
            out.append(Coordinate(name, LINEAR, scale=problem.base_linear_scale[i], lo=-bound, hi=bound))
        else:
            ref = float(problem.base_values[i])
            out.append(Coordinate(name, LOG, lo=ref * math.exp(-BASE_LOG_RANGE), hi=ref * math.exp(BASE_LOG_RANGE)))
    for e in problem.effects:
        for p in problem.effect_params(e):
            out.append(Coordinate(f"{e.name}.{p.name}", LINEAR, center=p.null, scale=p.span, lo=p.lo, hi=p.hi))
    return tuple(out)


def gap_prior(problem: GapProblem) -> GaussianPrior | None:
    """The baseline prior (log units, possibly correlated) and every effect parameter's Gaussian prior."""
    names = theta_names(problem)
    idx, mean, W = problem.prior_rows()
    prior = None
    if idx.size:
        cov = np.linalg.inv(W.T @ W)
        prior = GaussianPrior(tuple(names[i] for i in idx), mean, cov)
    effects = {}
    for e in problem.effects:
        for p in problem.effect_params(e):
            if p.prior is not None:
                effects[f"{e.name}.{p.name}"] = ((p.prior[0] - p.null) / p.span, p.prior[1] / p.span)
    if effects:
        eff = GaussianPrior.independent(effects)
        prior = eff if prior is None else prior.combine(eff)
    return prior


def _free_names(problem: GapProblem, chain) -> tuple[str, ...]:
    names = theta_names(problem)
    sl = problem.slices()
    idx = list(range(len(problem.base)))
    for name in chain:
        idx.extend(range(sl[name].start, sl[name].stop))
    return tuple(names[i] for i in idx)


def fit_chain(problem: GapProblem, chain: tuple[str, ...] = (), train=None, start=None,
              max_steps: int = 60) -> FitResult:
    """Refit the baseline + ``chain`` on the ``train`` rows (default all) with the engine.

    **Returns:** :class:`~ringfit.fit.result.FitResult` (standard errors inflated by √(χ²/dof)
    when > 1); ``extra``: ``chain``, ``pred`` ``(m,)``, ``train`` ``(m,)`` bool.
    """
    m = problem.m
    train = np.ones(m, dtype=bool) if train is None else np.asarray(train, dtype=bool)
    theta0 = problem.null_theta() if start is None else np.array(start, dtype=np.float64)
    if start is None:  # effects of the chain at their interior start
        for name in chain:
            sl = problem.slices()[name]
            e = next(e for e in problem.effects if e.name == name)
            theta0[sl] = [p.start for p in problem.effect_params(e)]
    engine_problem = _engine_problem(problem, train)
    for i, c in enumerate(engine_problem.coords):  # a warm start just outside a bound (rounding) comes back inside
        if c.kind == LINEAR:
            theta0[i] = np.clip(theta0[i], c.lo, c.hi)
    free = _free_names(problem, chain)
    fit = least_squares(engine_problem, theta0, free, max_steps=max_steps, rtol=RTOL, atol=ATOL,
                        n_data=int(train.sum()), pad_to=_pad(problem))
    fit.extra.update(chain=tuple(chain), pred=np.asarray(fit.extra.pop("aux"))[:m], train=train)
    fit.residuals = fit.residuals[:m]
    return fit


def heldout(problem: GapProblem, fit: FitResult, max_steps: int = 60) -> np.ndarray:
    """Held-out predictions ``(m,)``: each fold predicted by a refit on the others (warm start from ``fit``)."""
    out = np.full(problem.m, np.nan)
    for f in np.unique(problem.folds):
        test = problem.folds == f
        sub = fit_chain(problem, fit.extra["chain"], train=fit.extra["train"] & ~test, start=fit.theta,
                        max_steps=max_steps)
        out[test] = sub.extra["pred"][test]
    fit.extra["heldout_pred"] = out
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


def drift(problem: GapProblem, fit: FitResult, reference: FitResult) -> dict[str, float]:
    """Baseline-parameter drift of ``fit`` from ``reference``, in the reference's standard errors."""
    out = {}
    nb = len(problem.base)
    for j in range(nb):
        se_u = math.sqrt(max(reference.covariance_log[j, j], 1e-300))
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
