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
import jax.numpy as jnp
import numpy as np

from ringfit.fit.engine import (LINEAR, LOG, AbstractResiduals, Coordinate, GaussianPrior, Problem, inner_slots,
                                least_squares, linearize)
from ringfit.fit.result import FitResult
from ringfit.gap.problem import GapProblem
#: Solver tolerances (optimistix Cauchy termination on the solver coordinates and the residuals).
RTOL, ATOL = 1e-8, 1e-8
#: Baseline parameters move at most a factor e^3 from the baseline fit in a refit.
BASE_LOG_RANGE = 3.0


#: Suffix of a chain element that is an effect's *computed* variant (parameters fixed by the condition).
COMPUTED = "@computed"


#: Joins the parts of a composite candidate (effects that only act together on some rows, e.g. the rolling
#: model's ``ground_contact+rotation``): one candidate, added to the chain as its parts.
JOIN = "+"


def parts(element: str) -> tuple[str, ...]:
    """The chain elements of a candidate (``"ground_contact@computed+rotation@computed"`` → its two parts)."""
    return tuple(element.split(JOIN))


def effect_of(element: str) -> str:
    """The effect name of a chain element (``"ground_contact@computed"`` → ``"ground_contact"``; a composite
    ``"a@computed+b@computed"`` → ``"a+b"``)."""
    return JOIN.join(p.removesuffix(COMPUTED) for p in parts(element))


class GapResiduals(AbstractResiduals):
    """``ψ((prediction(θ) − y)·w)`` for a gap problem's predictor (ψ: Huber on the robust rows, else identity);
    aux: the prediction of every row."""

    predictor: object = eqx.field(static=True)
    huber: float = eqx.field(static=True, default=0.0)
    #: the solves of mode tables' problems (frequency and damping rows: dozens of rows) compile quickly (the
    #: engine's ``compile_quick``): a one-off diagnosis compiles the frequency problem in ~1.2 s instead of ~3.7 s
    #: and runs its ~65 solves in ~1.1 s instead of ~0.7 s; profile problems (thousands of rows, solves that
    #: dominate their diagnosis) keep XLA's optimised code
    quick: bool = eqx.field(static=True, default=False)

    #: a predictor in two stages (``inner``/``outer``, e.g. the profile predictor: the rolling solve, then each
    #: run's gain and angle offset): the θ indices of its readout (the engine's two-stage model,
    #: :class:`ringfit.fit.engine.AbstractResiduals`); ``()``: one stage
    readout_index: tuple = eqx.field(static=True, default=())

    @property
    def compile_quick(self) -> bool:
        return self.quick

    @property
    def readout(self) -> tuple:
        return self.readout_index

    def inner(self, theta, data):
        """The predictor's expensive stage (the two-stage model of :class:`ringfit.fit.engine.AbstractResiduals`)."""
        return self.predictor.inner(theta, data[0])

    def outer(self, inner, theta, data):
        """The rows from the predictor's cheap stage on ``inner`` (as :meth:`__call__` from the whole prediction)."""
        return self._rows(self.predictor.outer(inner, theta, data[0]), data)

    def __call__(self, theta, data):
        return self._rows(self.predictor(theta, data[0]), data)

    def _rows(self, pred, data):
        _, y, w, robust = data
        z = (pred - y) * w
        if self.huber > 0:
            c = self.huber
            a = jnp.abs(z)
            soft = jnp.sign(z) * jnp.sqrt(jnp.maximum(2.0 * c * a - c * c, 1e-300))
            z = jnp.where(robust & (a > c), soft, z)
        return z, pred


def _engine_problem(problem: GapProblem, train) -> Problem:
    """The engine's problem of a gap refit: residuals ``ψ((prediction − y)/σ)`` on the ``train`` rows."""
    m = problem.m
    w = np.where(train, 1.0 / problem.sigma, 0.0)
    y = problem.y
    robust = np.zeros(m, dtype=bool) if problem.robust is None else np.asarray(problem.robust, dtype=bool)
    pad = int(problem.meta.padded_rows if problem.meta.padded_rows is not None else m) - m  # rows the predictor pads (weight 0)
    if pad:
        y, w = np.concatenate([y, np.zeros(pad)]), np.concatenate([w, np.zeros(pad)])
        robust = np.concatenate([robust, np.zeros(pad, dtype=bool)])
    huber = float(problem.huber) if problem.huber and problem.robust is not None and robust.any() else 0.0
    readout = tuple(getattr(problem.predictor, "readout", ()))
    return Problem(GapResiduals(problem.predictor, huber, problem.domain in ("damping", "modes"), readout),
                   (problem.data, y, w, robust), coordinates(problem), prior=gap_prior(problem), sigma="inflate",
                   data_label="the gap data")


def _pad(problem: GapProblem) -> int:
    return int((problem.meta.tangents if problem.meta.tangents is not None else problem.n_theta))


def predict(problem: GapProblem, theta) -> np.ndarray:
    """Prediction ``(m,)`` of every row at ``theta`` (natural units): the engine's residual model, no fit.

    Evaluated by the refits' own compiled solve (:func:`ringfit.fit.engine.linearize`, the baseline's
    parameters free, padded as every refit): a cold diagnosis compiles no separate program for it.
    """
    eng = _engine_problem(problem, np.ones(problem.m, dtype=bool))
    out = linearize(eng, np.asarray(theta, dtype=np.float64), _free_names(problem, ()), pad_to=_pad(problem))
    return np.asarray(out.aux)[: problem.m]


def predict_and_jacobian(problem: GapProblem, theta: np.ndarray, free) -> tuple[np.ndarray, np.ndarray]:
    """Prediction ``(m,)`` and ∂pred/∂theta for the ``free`` columns ``(m, len(free))`` (natural units of theta).

    Evaluated by the engine's linearisation (:func:`ringfit.fit.engine.linearize`, one forward-mode
    pass), in chunks of the padded free-set size (for a two-stage predictor, each chunk holds at most the
    inner stage's slots of its parameters, the rest readout parameters). Used by the screen.
    """
    free = np.asarray(free, dtype=int)
    names = theta_names(problem)
    coords = coordinates(problem)
    theta = np.asarray(theta, dtype=np.float64)
    eng = _engine_problem(problem, np.ones(problem.m, dtype=bool))
    m, K = problem.m, _pad(problem)
    w = 1.0 / problem.sigma
    pred, cols, done = None, [], []
    for chunk in _chunks(free, K, eng.model.readout, inner_slots(eng.model, K)):
        out = linearize(eng, theta, tuple(names[i] for i in chunk), pad_to=K)
        pred = np.asarray(out.aux)[:m] if pred is None else pred
        dtheta_du = np.array([theta[i] if coords[i].kind == LOG else coords[i].scale for i in chunk])
        cols.append(out.jacobian[:m] / w[:, None] / dtheta_du[None, :])
        done.extend(chunk)
    J = np.concatenate(cols, axis=1)
    if done != list(free):  # chunks grouped by stage: back to the order of ``free``
        J = J[:, [done.index(i) for i in free]]
    if problem.huber and problem.robust is not None:
        # the engine's rows are ψ(z): undo ψ'(z) = c/|ψ(z)| on robust rows beyond c, so J is ∂pred/∂θ
        c = float(problem.huber)
        a = np.abs((pred - problem.y) * w)
        beyond = np.asarray(problem.robust, dtype=bool) & (a > c)
        J = J * np.where(beyond, np.sqrt(np.maximum(2 * c * a - c * c, 0.0)) / c, 1.0)[:, None]
    return pred, J


def _chunks(free, K: int, readout=(), n_inner: int = 0) -> list[list[int]]:
    """``free`` (θ indices) in chunks of at most ``K``; with ``n_inner`` > 0 (a two-stage predictor) each
    chunk takes at most that many non-``readout`` indices, the readout ones filling the chunks' other slots."""
    free = [int(i) for i in free]
    if not n_inner:
        return [free[s : s + K] for s in range(0, max(len(free), 1), K)]
    inner = [i for i in free if i not in readout]
    rest = [i for i in free if i in readout]
    out = []
    while inner or rest or not out:
        chunk, inner = inner[:n_inner], inner[n_inner:]
        chunk, rest = chunk + rest[: K - len(chunk)], rest[K - len(chunk) :]
        out.append(chunk)
    return out


def theta_names(problem: GapProblem) -> tuple[str, ...]:
    """Names of the entries of theta: the baseline's, then ``effect.parameter`` for each effect."""
    return tuple(problem.base) + tuple(f"{e.name}.{p.name}" for e in problem.effects for p in problem.effect_params(e))


def coordinates(problem: GapProblem) -> tuple[Coordinate, ...]:
    """How each entry of theta is solved for (see the module docstring)."""
    out = []
    for i, name in enumerate(problem.base):
        if problem.base_coords and name in problem.base_coords:
            out.append(problem.base_coords[name])
        elif problem.is_linear(i):
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
    """The baseline's parameters and those of the chain's fitted effects (computed ones stay fixed)."""
    names = theta_names(problem)
    sl = problem.slices()
    idx = list(range(len(problem.base)))
    for name in (p for c in chain for p in parts(c)):
        if not name.endswith(COMPUTED):
            idx.extend(range(sl[name].start, sl[name].stop))
    return tuple(names[i] for i in idx)


def chain_start(problem: GapProblem, chain, theta) -> np.ndarray:
    """``theta`` with each chain effect set to its start (fitted) or its condition value (computed)."""
    theta = np.array(theta, dtype=np.float64)
    for element in (p for c in chain for p in parts(c)):
        name = effect_of(element)
        sl = problem.slices()[name]
        e = next(e for e in problem.effects if e.name == name)
        params = problem.effect_params(e)
        theta[sl] = [p.condition for p in params] if element.endswith(COMPUTED) else [p.start for p in params]
    return theta


def fit_chain(problem: GapProblem, chain: tuple[str, ...] = (), train=None, start=None,
              max_steps: int = 60, hold: tuple = ()) -> FitResult:
    """Refit the baseline + ``chain`` on the ``train`` rows (default all) with the engine.

    A chain element ``"name"`` frees the effect's parameters; ``"name@computed"`` holds them
    at the values the measured condition fixes (``Parameter.condition``).

    **Returns:** :class:`~ringfit.fit.result.FitResult` (standard errors inflated by √(χ²/dof)
    when > 1); ``extra``: ``chain``, ``pred`` ``(m,)``, ``train`` ``(m,)`` bool.
    """
    m = problem.m
    train = np.ones(m, dtype=bool) if train is None else np.asarray(train, dtype=bool)
    theta0 = chain_start(problem, chain, problem.null_theta()) if start is None else np.array(start, dtype=np.float64)
    engine_problem = _engine_problem(problem, train)
    for i, c in enumerate(engine_problem.coords):  # a warm start just outside a bound (rounding) comes back inside
        if c.kind == LINEAR:
            theta0[i] = np.clip(theta0[i], c.lo, c.hi)
    free = _free_names(problem, chain)
    pad = _pad(problem)
    if hold:  # held at their start (a held-out fold's own nuisances: no train row sees them)
        names = theta_names(problem)
        # the slots of the whole free set kept (padding in their place): the same compiled solve, and a
        # two-stage model's inner-stage slots unchanged
        pad = max(pad, len(free))
        free = tuple(n for n in free if n not in {names[i] for i in hold})
    # the plain solve, without the engine's active set of bounds: a refit that runs out of steps stays out of the
    # statistic and of its nulls alike, as the calibration (docs/physics.md §6.4) measured it
    fit = least_squares(engine_problem, theta0, free, max_steps=max_steps, rtol=RTOL, atol=ATOL,
                        n_data=int(train.sum()), pad_to=pad, active_set=False)
    fit.extra.update(chain=tuple(chain), pred=np.asarray(fit.extra.pop("aux"))[:m], train=train)
    fit.residuals = fit.residuals[:m]
    return fit


def heldout(problem: GapProblem, fit: FitResult, max_steps: int = 60, variance: bool = False) -> np.ndarray:
    """Held-out predictions ``(m,)``: each fold predicted by a refit on the others (warm start from ``fit``).

    ``fit.extra["heldout_refits"]``: ``{"folds": …, "not_converged": …}`` — how many fold refits stopped short
    of convergence (their predictions are used as they are, and the count is reported).

    ``variance``: also the variance of each held-out prediction from its refit's covariance
    (``fit.extra["heldout_var"]``), for problems whose held-out refits extrapolate (mode tables).
    """
    out = np.full(problem.m, np.nan)
    var = np.zeros(problem.m)
    coords = coordinates(problem)
    folds = np.unique(problem.folds)
    unconverged = 0
    for f in folds:
        test = problem.folds == f
        # the fold's own nuisances (a run's gain and angle offset) are seen by no train row: held at the fit's
        # values in the refit, then fitted to the fold's own rows by one Gauss–Newton step — the same for the
        # baseline and every candidate, and for the nulls' linearised refits (calibration.heldout_linear)
        held = problem.meta.fold_nuisances.get(int(f), ())
        sub = fit_chain(problem, fit.extra["chain"], train=fit.extra["train"] & ~test, start=fit.theta,
                        max_steps=max_steps, hold=held)
        unconverged += not sub.converged
        out[test] = sub.extra["pred"][test]
        if held:  # the held-out run's own calibration (gain, angle offset) fitted to its own rows
            _, Jh = predict_and_jacobian(problem, sub.theta, held)
            out[test] += fold_nuisance_step(Jh[test], problem.y[test] - out[test], 1.0 / problem.sigma[test] ** 2)
        if variance:
            free = sub.free_index
            _, J = predict_and_jacobian(problem, sub.theta, free)
            dtheta_du = np.array([sub.theta[i] if coords[i].kind == LOG else coords[i].scale for i in free])
            Ju = J[test] * dtheta_du[None, :]
            cov = np.where(np.isfinite(sub.covariance_log), sub.covariance_log, 0.0)
            var[test] = np.einsum("ij,jk,ik->i", Ju, cov, Ju)
    fit.extra["heldout_pred"] = out
    # a fold whose refit stops short (its step limit: a parameter the fold's rows do not pin) still predicts
    # from where it stopped; the count goes into the diagnosis's JSON (docs/formats.md §5), never unsaid
    fit.extra["heldout_refits"] = {"folds": int(folds.size), "not_converged": int(unconverged)}
    if variance:
        fit.extra["heldout_var"] = var
    return out


def fold_nuisance_step(J, r, w2):
    """The change of a held-out prediction ``(..., t)`` when the fold's own nuisances are fitted to its rows: one
    weighted Gauss–Newton step ``J (JᵀWJ)⁻¹ JᵀW r`` from the training refit's values (``J`` ``(..., t, h)`` their
    columns on the fold's rows, ``r`` ``(..., t)`` its held-out residuals, ``w2`` = 1/σ²). A run's gain and angle
    offset are near-linear over their small range, and a step has the same form in the held-out refits and in the
    nulls' linearised ones (:func:`ringfit.gap.calibration.heldout_linear`)."""
    Jw = J * w2[..., :, None]
    A = np.swapaxes(Jw, -1, -2) @ J
    A = A + 1e-12 * np.trace(A, axis1=-2, axis2=-1)[..., None, None] * np.eye(J.shape[-1])
    g = np.einsum("...ti,...t->...i", Jw, r)
    d = np.linalg.solve(A, g[..., None])[..., 0]
    return np.einsum("...ti,...i->...t", J, d)


def rms(problem: GapProblem, resid: np.ndarray, mask=None) -> float:
    """RMS of residuals in the problem's unit (``scale`` applied)."""
    r = resid * problem.scale
    if mask is not None:
        r = r[mask]
    return float(np.sqrt(np.mean(r**2)))


def shrink(problem: GapProblem, r_base: np.ndarray, r_cand: np.ndarray, mask=None, heldout: bool = False) -> float:
    """Shrink [%] = 100·(1 − SS_after/SS_before), SS = Σ ψ(r/σ)² over the rows in ``mask`` (default all).

    Each residual is weighted by 1/σ² of its own noise estimate (σ per run and channel for
    profiles, per row family for mode tables) and passed through the Huber function where the
    problem marks rows robust (docs/formats.md §5).
    """
    zb, zc = problem.standardised(r_base, mask, heldout), problem.standardised(r_cand, mask, heldout)
    sb = float(np.sum(zb**2))
    return 100.0 * (1.0 - float(np.sum(zc**2)) / sb) if sb > 0 else 0.0


def shrink_interval(problem: GapProblem, r_base: np.ndarray, r_cand: np.ndarray, n_boot: int = 400,
                    seed: int = 0, mask=None, heldout: bool = True) -> tuple[float, float]:
    """95 % block-bootstrap interval of the held-out :func:`shrink` [%] over rows (blocks of ``meta.block``)."""
    rb2 = problem.standardised(r_base, mask, heldout) ** 2
    rc2 = problem.standardised(r_cand, mask, heldout) ** 2
    m = rb2.size
    block = int(problem.meta.block)
    nb = max(1, math.ceil(m / block))
    rng = np.random.default_rng(seed)
    starts = rng.integers(0, m, size=(n_boot, nb))
    idx = (starts[:, :, None] + np.arange(block)[None, None, :]).reshape(n_boot, -1) % m
    sb, sc = rb2[idx].sum(1), rc2[idx].sum(1)
    s = 100.0 * (1.0 - sc / np.maximum(sb, 1e-300))
    return float(np.percentile(s, 2.5)), float(np.percentile(s, 97.5))


def reference_drift(problem: GapProblem, fit: FitResult, reference: FitResult) -> float | None:
    """How far a refit moved the reference-state predictions: RMS over the reference rows of the
    baseline's prediction (every effect at its null) with the refit's baseline parameters minus that
    with the reference fit's, in units of each row's σ. ``None`` without reference rows."""
    mask = problem.meta.reference_mask
    if mask is None or not np.any(mask):
        return None
    nb = len(problem.base)
    a = problem.null_theta(fit.theta[:nb])
    # the reference is a baseline fit (every effect at its null): its own prediction is the "before"
    d = (predict(problem, a) - reference.extra["pred"])[mask] / problem.sigma[mask]
    return float(np.sqrt(np.mean(d**2)))


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


def prior_distance(problem: GapProblem, theta: np.ndarray, exclude=()) -> tuple[float, int]:
    """Squared Mahalanobis distance of the prior-guarded baseline parameters from their prior.

    The guarded parameters are ``problem.meta.prior_guarded`` (baseline indices whose prior
    comes from independent data — for profiles the ring stiffnesses from the free-table fit),
    less the names in ``exclude`` (an effect's ``baseline_partners``, marginalised out).
    **Returns:** ``(D², k)``; ``(0, 0)`` when nothing is guarded. Under the prior D² ~ χ²_k.
    """
    idx = [i for i in problem.meta.prior_guarded if problem.base[i] not in exclude]
    if not idx or problem.base_prior_cov is None:
        return 0.0, 0
    mean = np.asarray(problem.base_prior_mean if problem.base_prior_mean is not None else problem.base_values)
    d = np.log(np.asarray(theta)[idx]) - np.log(mean[idx])
    cov = np.asarray(problem.base_prior_cov)[np.ix_(idx, idx)]
    return float(d @ np.linalg.solve(cov, d)), len(idx)


def baseline_movement(problem: GapProblem, fit: FitResult, reference: FitResult) -> dict | None:
    """How far the baseline fit moved from what independent data say (docs/formats.md §5 ``baseline.drift``).

    Against the baseline prior where the problem has one from independent data (profiles: the ring
    stiffnesses and damping from the free-table fit, k_trd from ``tyre.toml``): each positive parameter's
    change in σ of that prior (log units) and in per cent, and the squared Mahalanobis distance D² of the
    prior-guarded ones (χ²_k under the prior). Otherwise against the reference fit (mode tables: the fit to
    the reference rows), in its standard errors. ``None`` when there is nothing to compare with.
    """
    from scipy.special import chdtri  # χ² quantile

    from ringfit.gap.verdict import PRIOR_REGION

    nb = len(problem.base)
    guarded = list(problem.meta.prior_guarded)
    if guarded and problem.base_prior_cov is not None and problem.base_prior_mean is not None:
        mean = np.asarray(problem.base_prior_mean, dtype=np.float64)
        sd = np.sqrt(np.diag(np.asarray(problem.base_prior_cov, dtype=np.float64)))
        against = "prior"
    elif reference is not fit:
        mean = np.asarray(reference.theta[:nb], dtype=np.float64)
        sd = np.sqrt(np.maximum(np.diag(reference.covariance_log)[:nb], 1e-300))
        against = "reference_fit"
    else:
        return None
    params = {}
    for i, name in enumerate(problem.base):
        if problem.is_linear(i) or not np.isfinite(sd[i]) or not mean[i] > 0:
            continue
        dlog = math.log(fit.theta[i]) - math.log(mean[i])
        params[name] = {"reference": float(mean[i]), "value": float(fit.theta[i]), "sigma": dlog / sd[i],
                        "pct": 100.0 * (fit.theta[i] / mean[i] - 1.0)}
    out = {"against": against, "parameters": params,
           "max_abs_sigma": max((abs(p["sigma"]) for p in params.values()), default=0.0)}
    if against == "prior":
        d2, k = prior_distance(problem, fit.theta)
        limit = float(chdtri(k, 1.0 - PRIOR_REGION)) if k else math.inf
        out["prior_distance"] = {"d2": d2, "k": k, "limit": limit, "outside": bool(d2 > limit)}
    return out
