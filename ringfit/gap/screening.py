"""Cheap screen of each candidate at the baseline, linearised (:func:`screen`: score and alignment) or, where the
baseline fit left its prior, nonlinear (:func:`nonlinear_screen`: a refit from the reference baseline); docs/physics.md
§6.4 *the screen* and *a baseline that moved*. It only decides which candidates are refitted on the data: the
calibration's nulls refit every candidate of a round whatever it says.

Example (the screen figures of a diagnosed case, as the JSON lists them)::

    from ringfit.gap import diagnose
    d = diagnose("case/", null_draws=0)
    c = d.content["candidates"][0]
    c["effect"], c["evidence"]["screen_score"], c["evidence"]["alignment"], c["screened_out"]
    # e.g. ('sensor_tilt', 5.136, 0.035, True) on a noise-only profile case
"""

from __future__ import annotations

import numpy as np

from ringfit.gap.problem import GapProblem
from ringfit.fit.result import FitResult
from ringfit.gap.ranking import COMPUTED, chain_start, effect_of, fit_chain, parts, predict, predict_and_jacobian

SCREEN_MIN_SCORE = 1.0
STEP = 0.05


def screen(problem: GapProblem, baseline: FitResult, elements=None) -> dict[str, dict]:
    """Score and alignment of the candidates (``elements``: effect names, and ``name@computed`` for an
    effect held at its condition values; default every effect fitted) at ``baseline``.

    ``baseline`` is a :class:`~ringfit.fit.result.FitResult` of :func:`ringfit.gap.ranking.fit_chain`
    (the baseline, or the baseline plus an accepted chain, whose own free parameters are projected out
    too). A computed candidate has no free parameter: its score is the χ² its fixed change Δ removes,
    ``‖r‖² − ‖r − Δ⊥‖²`` (Δ⊥: the part of Δ the baseline cannot mimic).
    """
    th0 = baseline.theta
    p0 = baseline.extra["pred"]
    sig = problem.sigma
    r = (problem.y - p0) / sig
    nb = len(problem.base)
    free = np.asarray(baseline.free_index, dtype=int)
    unit = np.array([1.0 if (i >= nb or problem.is_linear(i)) else th0[i] for i in free])
    Jb = predict_and_jacobian(problem, th0, free)[1] * unit[None, :] / sig[:, None]
    Q, _ = np.linalg.qr(Jb)
    out = {}
    sl = problem.slices()
    if elements is None:
        elements = [e.name for e in problem.effects]
    for element in elements:
        pieces = parts(element)
        if all(p.endswith(COMPUTED) for p in pieces):
            th = chain_start(problem, pieces, th0)
            delta = (predict(problem, th) - p0) / sig
            delta = delta - Q @ (Q.T @ delta)
            score = float(2.0 * r @ delta - delta @ delta)
            out[element] = dict(score=score, alignment=float(np.sqrt(max(score, 0.0) / max(np.sum(r**2), 1e-300))))
            continue
        effs = [next(x for x in problem.effects if x.name == effect_of(p)) for p in pieces]
        if len(effs) > 1:
            out[element] = _composite_score(problem, pieces, effs, th0, p0, r, sig, Q)
            continue
        cols = []
        e = effs[0]
        for j, p in zip(range(sl[e.name].start, sl[e.name].stop), problem.effect_params(e)):
            h = STEP * p.span * (1.0 if p.start >= p.null else -1.0)
            if p.null + h > p.hi or p.null + h < p.lo:
                h = -h
            th = th0.copy()
            th[j] = p.null + h
            pj = predict(problem, th)
            cols.append((pj - p0) / sig / h)
        S = np.stack(cols, 1)
        S = S - Q @ (Q.T @ S)
        norm = np.linalg.norm(S, axis=0)
        ok = norm > 1e-12 * max(1.0, np.linalg.norm(r))
        if not np.any(ok):
            out[element] = dict(score=0.0, alignment=0.0)
            continue
        S = S[:, ok]
        coef, *_ = np.linalg.lstsq(S, r, rcond=None)
        score = float(np.sum((S @ coef) ** 2))
        out[element] = dict(score=score, alignment=float(np.sqrt(score / max(np.sum(r**2), 1e-300))))
    return out


def _composite_score(problem, pieces, effs, th0, p0, r, sig, Q) -> dict:
    """Screen of a composite of fitted effects that acts only when all its parts are on (the rolling model):
    the χ² removed by the jump to its start plus a linearised step of its parameters from there."""
    sl = problem.slices()
    th_s = chain_start(problem, pieces, th0)
    ps = predict(problem, th_s)
    rs = r - (ps - p0) / sig
    rs = rs - Q @ (Q.T @ (rs - r))  # the baseline's own directions are projected out of the jump
    cols = []
    for e in effs:
        for j, p in zip(range(sl[e.name].start, sl[e.name].stop), problem.effect_params(e)):
            h = STEP * p.span * (-1.0 if p.start + STEP * p.span > p.hi else 1.0)
            th = th_s.copy()
            th[j] = p.start + h
            cols.append((predict(problem, th) - ps) / sig / h)
    S = np.stack(cols, 1)
    S = S - Q @ (Q.T @ S)
    coef, *_ = np.linalg.lstsq(S, rs, rcond=None)
    score = float(np.sum(r**2) - np.sum((rs - S @ coef) ** 2))
    return dict(score=score, alignment=float(np.sqrt(max(score, 0.0) / max(np.sum(r**2), 1e-300))))


def objective(problem: GapProblem, fit: FitResult) -> float:
    """What a refit minimises: the data χ² plus the prior's χ² (the baseline prior and the fitted effects'
    priors: the engine's prior rows at the end point, ``fit.extra["prior_chi2"]``)."""
    return fit.chi2 + fit.extra["prior_chi2"]


def reference_start(problem: GapProblem, baseline: FitResult) -> np.ndarray:
    """``baseline.theta`` with every positive baseline parameter that has a prior put back at the prior's
    mean (what independent data say: the free-table ring, ``tyre.toml``'s k_trd); nuisances (the profile
    block's gains and angle offsets, :attr:`~ringfit.gap.problem.GapProblem.base_coords`, whose prior only ties
    the runs together) and effect parameters as in ``baseline``."""
    th = np.array(baseline.theta, dtype=np.float64)
    idx, mean_u, _ = problem.prior_rows()
    for i, mu in zip(idx, mean_u):
        if not problem.is_linear(i) and not (problem.base_coords and problem.base[i] in problem.base_coords):
            th[i] = float(np.exp(mu))
    return th


def nonlinear_screen(problem: GapProblem, baseline: FitResult, elements) -> dict[str, dict]:
    """Each candidate refitted jointly with the baseline from :func:`reference_start` (see the module's
    docstring). **Returns:** ``{element: {"score", "alignment", "fit", "screen": "nonlinear"}}``;
    ``score`` = objective of ``baseline`` − objective of the refit (≤ 0 when the refit does no better);
    a refit that did not converge scores 0."""
    r2 = float(np.sum(((problem.y - baseline.extra["pred"]) / problem.sigma) ** 2))
    base_obj = objective(problem, baseline)
    start = reference_start(problem, baseline)
    out = {}
    for element in elements:
        fit = fit_chain(problem, parts(element), start=chain_start(problem, parts(element), start))
        score = base_obj - objective(problem, fit) if fit.converged else 0.0
        out[element] = dict(score=float(score), alignment=float(np.sqrt(max(score, 0.0) / max(r2, 1e-300))),
                            fit=fit, screen="nonlinear")
    return out
