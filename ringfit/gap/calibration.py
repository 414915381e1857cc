"""The null of a verdict: how much held-out shrink the diagnosis's own selection finds when no effect is there
(docs/physics.md §6.4; docs/formats.md §5 ``null``).

A held-out shrink is evidence only if chance rarely produces it, and chance includes every choice the diagnosis
makes on the data: the best of several candidates, the model lines rows are matched to, the labels the assignment
may override. So an accepted candidate's statistic T (the round's best held-out shrink, ``1 − SS_c/SS_current``)
is compared with T over N draws of data with no effect, ``p = (1 + #{T* ≥ T})/(N + 1)``, and stands only when
p < α (:data:`ALPHA`). The nulls: **parametric** (rows redrawn from the current model with the row noise model,
:func:`parametric_null`), **random-line** (rows whose line the data choose redrawn uniformly over their table's
span with their labels, and matched again by the diagnosis's own rule, :func:`random_line_null`), **rig
nuisances** for profiles; beside them :func:`label_permutation_test`. Refits are linearised at each candidate's
fit and vectorised over draws (:func:`linearise`, :func:`heldout_linear`), so observed and null statistics are
computed by one formula. Each null, what it repeats, and the audit of freedoms: docs/physics.md §6.4.

Example (the nulls behind an accepted candidate of ``ringfit example case --effect rotation --out ex``)::

    from ringfit.gap import diagnose

    d = diagnose("ex/case", null_draws=200)
    for c in d.content["candidates"]:
        if c["accepted"]:
            print(c["effect"], c["p_value"], c["null_sentence"])
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ringfit.fit.engine import LOG
from ringfit.gap.problem import GapProblem
from ringfit.gap.ranking import coordinates, fold_nuisance_step, gap_prior, parts, predict_and_jacobian, theta_names

#: Default significance level of an acceptance (``ringfit diagnose --alpha``).
ALPHA = 0.01
#: Default number of null draws (per null).
DRAWS = 200


@dataclass
class Linearised:
    """One fit's prediction, Jacobian in solver coordinates and prior at its optimum (see module docstring)."""

    pred: np.ndarray  # (M,)
    J: np.ndarray  # (M, k)
    u_hat: np.ndarray  # (k,)
    lam: np.ndarray  # (k, k) prior precision
    prior_grad: np.ndarray  # (k,) Λ(û − μ)
    #: {fold: columns of J} — nuisances fitted to the held-out fold's own rows (``ProblemMeta.fold_nuisances``)
    held: dict = None


def linearise(problem: GapProblem, fit) -> Linearised:
    """:class:`Linearised` of ``fit`` (a :func:`~ringfit.gap.ranking.fit_chain` result) on ``problem``'s rows."""
    free = np.asarray(fit.free_index, dtype=int)
    theta = np.asarray(fit.theta, dtype=np.float64)
    pred, J = predict_and_jacobian(problem, theta, free)
    coords = coordinates(problem)
    dth_du = np.array([theta[i] if coords[i].kind == LOG else coords[i].scale for i in free])
    u_hat = np.array([float(coords[i].to_u(theta[i])) for i in free])
    names = theta_names(problem)
    prior = gap_prior(problem)
    k = free.size
    if prior is not None:
        W, mean = prior.rows(tuple(names[i] for i in free), k)
    else:
        W, mean = np.zeros((k, k)), np.zeros(k)
    lam = W.T @ W
    cols = list(free)
    held = {f: [cols.index(i) for i in idx if i in cols] for f, idx in problem.meta.fold_nuisances.items()}
    return Linearised(pred, J * dth_du[None, :], u_hat, lam, lam @ (u_hat - mean), {f: c for f, c in held.items() if c})


def heldout_linear(lin: Linearised, y, w2, folds, idx=None) -> np.ndarray:
    """Held-out residuals ``(B, m)`` of the linearised refits to ``y`` ``(B, m)`` (``w2`` = 1/σ², ``(B, m)`` or
    ``(m,)``), fold by fold; ``idx`` ``(B, m)``: the line-problem row each row is matched to (None: row i).

    The train rows' normal equations of each fold are formed one of three ways, the same equations each:
    *shared* (every draw the same rows and weights: one ``(k, k)`` matrix), *grouped* (every draw the same rows,
    each draw's weights constant within a few row groups — a profile null's σ re-estimated per run and channel:
    ``Σ_g w_g JᵀJ`` over the groups' rows, no ``(B, m, k)`` Jacobian) or *per draw*."""
    y = np.atleast_2d(np.asarray(y, dtype=np.float64))
    B, m = y.shape
    shared = idx is None and np.ndim(w2) <= 1
    groups = None
    if idx is None and not shared:
        groups = _weight_groups(np.broadcast_to(w2, (B, m)))
    if idx is None:
        pred, J = lin.pred[:m], lin.J[:m]
        if not shared and groups is None:
            J = np.broadcast_to(J, (B, m, J.shape[1]))
    else:
        pred, J = lin.pred[idx], lin.J[idx]
    w2 = np.broadcast_to(w2, (m,) if shared else (B, m))
    batched = not shared and groups is None  # J carries the draws' axis
    r = y - pred
    e = np.empty_like(r)
    k = J.shape[-1]
    ridge = 1e-10 * np.eye(k)
    for f in np.unique(folds):
        te = folds == f
        tr = ~te
        if k == 0:
            e[:, te] = r[:, te]
            continue
        h = (lin.held or {}).get(int(f)) or []
        keep = np.array([c for c in range(k) if c not in h], dtype=int)  # the fold's own nuisances held
        Jt = J[..., tr, :][..., keep]
        lam = lin.lam[np.ix_(keep, keep)] + ridge[: keep.size, : keep.size] * (1.0 + np.trace(lin.lam[np.ix_(keep, keep)]))
        # normal equations of the fold's train rows: A (k, k) or (B, k, k), right-hand sides g (B, k)
        if groups is not None:
            A, g = _grouped_normal(Jt, w2[:, tr], r[:, tr], groups[tr])
        else:
            wt = w2[..., tr]
            A = np.einsum("...mi,...m,...mj->...ij", Jt, wt, Jt)
            g = (wt * r[:, tr]) @ Jt if shared else np.einsum("bmi,bm->bi", Jt, wt * r[:, tr])
        A, g = A + lam, g - lin.prior_grad[keep]
        Jte = J[..., te, :][..., keep]
        if A.ndim == 2:
            d = np.linalg.solve(A, g.T).T
        else:
            d = np.linalg.solve(A, g[..., None])[..., 0]
        e[:, te] = r[:, te] - (np.einsum("bmi,bi->bm", Jte, d) if batched else d @ Jte.T)
        if h:  # the fold's own nuisances fitted to its rows, as the held-out refits do (ranking.heldout)
            e[:, te] -= fold_nuisance_step(J[..., te, :][..., h], e[:, te], w2[..., te])
    return e


#: Most distinct weight patterns over the rows for which :func:`heldout_linear` takes the grouped path.
MAX_WEIGHT_GROUPS = 64


def _weight_groups(w2: np.ndarray) -> np.ndarray | None:
    """Group index ``(m,)`` of rows whose weight is the same in every draw (``w2`` ``(B, m)``), or None when there
    are more than :data:`MAX_WEIGHT_GROUPS` such groups."""
    _, inverse = np.unique(np.ascontiguousarray(w2.T), axis=0, return_inverse=True)
    inverse = np.asarray(inverse).reshape(-1)
    return inverse if inverse.max(initial=0) < MAX_WEIGHT_GROUPS else None


def _grouped_normal(Jt, wt, rt, groups):
    """``(A (B, k, k), g (B, k))`` of rows ``Jt`` ``(t, k)`` shared by every draw, weighted per draw by one value
    per group (``wt`` ``(B, t)``, ``groups`` ``(t,)``): ``A_b = Σ_g w_bg J_gᵀJ_g``, ``g_b = Σ_g w_bg J_gᵀ r_bg``."""
    labels = np.unique(groups)
    first = np.array([np.flatnonzero(groups == gi)[0] for gi in labels])
    wg = wt[:, first]  # (B, G)
    gram = np.stack([Jt[groups == gi].T @ Jt[groups == gi] for gi in labels])
    rhs = np.stack([rt[:, groups == gi] @ Jt[groups == gi] for gi in labels], axis=1)  # (B, G, k)
    return np.einsum("bg,gij->bij", wg, gram), np.einsum("bg,bgi->bi", wg, rhs)


def sum_of_squares(problem: GapProblem, e, sigma) -> np.ndarray:
    """``(B,)`` Σ ψ(e/σ)² with the problem's Huber function on its robust rows."""
    return np.sum(_psi2(problem, e, sigma), axis=-1)


@dataclass
class NullResult:
    """One null of one round: its ``kind``, the null statistic per draw ``t_null`` (fractions), the observed
    statistic and p-value per candidate element."""

    kind: str
    t_null: np.ndarray
    observed: dict
    p: dict
    note: str
    #: what else the null's draws did (the random-line null: labels its assignments overrode per draw)
    extra: dict = None

    @property
    def draws(self) -> int:
        """Number of null draws."""
        return int(self.t_null.size)

    def summary(self, element: str) -> dict:
        """This null for one candidate ``element``: kind, draws, the statistic's quantiles and the p-value."""
        p = self.p[element]
        return {"kind": self.kind, "draws": self.draws, "statistic": self.note,
                "median_pct": round(100 * float(np.median(self.t_null)), 2),
                "q95_pct": round(100 * float(np.quantile(self.t_null, 0.95)), 2),
                "mean_pct": round(100 * float(np.mean(self.t_null)), 2),
                "sd_pct": round(100 * float(np.std(self.t_null)), 2),
                "observed_pct": round(100 * self.observed[element], 2),
                "p_value": p, "p_mc_error": round(math.sqrt(p * (1 - p) / self.draws), 4),
                **({"labels_overridden_in_draws": self.extra} if self.extra else {})}


def _p_values(t_null: np.ndarray, observed: dict) -> dict:
    n = t_null.size
    return {c: float((1 + np.sum(t_null >= t - 1e-12)) / (n + 1)) for c, t in observed.items()}


def _phase_randomised(res: np.ndarray, series, rng, B: int) -> np.ndarray:
    """``(B, m)`` surrogates of ``res``: per series, Fourier amplitudes kept, phases drawn at random."""
    out = np.empty((B, res.size))
    for s in np.unique(series):
        sel = np.flatnonzero(series == s)
        x = res[sel]
        F = np.fft.rfft(x - x.mean())
        ph = rng.uniform(0, 2 * np.pi, (B, F.size))
        ph[:, 0] = 0.0
        if x.size % 2 == 0:
            ph[:, -1] = 0.0
        out[:, sel] = np.fft.irfft(F[None, :] * np.exp(1j * ph), n=x.size) + x.mean()
    return out


#: The rig's nuisances carried by the nuisance null of profiles (:func:`parametric_null` ``nuisances=True``; the
#: baseline fits each run's gain and angle offset — the profile block's nuisances — and so does every linearised
#: refit, so the null repeats that choice on data that hold them): a per-revolution gain that drifts linearly over
#: the session (runs in speed order) by up to this much end to end, either sign (a slow sensor/DAQ gain drift: 1–4 %) …
GAIN_DRIFT_MAX = 0.04
#: … and a per-run angle jitter of this σ [deg] (the recorded angle's trigger uncertainty between runs).
ANGLE_JITTER_DEG = 0.2


#: Fewest redrawn rows whose residuals make the resampling pool of the mode tables' noise null; fewer: every row's.
RESAMPLE_MIN_ROWS = 8


def _nuisances(problem: GapProblem, pred: np.ndarray, rng, B: int) -> np.ndarray:
    """``(B, m)`` the current prediction as the rig's nuisances move it per draw: a gain ``1 + d·(rank − ½)`` per
    run (rank 0 … 1 in speed order, d uniform in ±:data:`GAIN_DRIFT_MAX`) and a shift of each run by a random angle
    (σ :data:`ANGLE_JITTER_DEG`, the prediction's angular derivative, spectral, per run and channel)."""
    lab = problem.labels
    prof = np.asarray(lab["profile"])
    series = np.asarray(lab["series"])
    P = int(prof.max()) + 1
    speeds = np.array([float(np.asarray(lab["speed_kmh"])[prof == p][0]) for p in range(P)])
    rank = np.argsort(np.argsort(speeds, kind="stable"), kind="stable") / max(P - 1, 1)
    d = rng.uniform(-GAIN_DRIFT_MAX, GAIN_DRIFT_MAX, (B, 1))
    gain = 1.0 + d * (rank[None, :] - 0.5)  # (B, P)
    jitter = np.radians(ANGLE_JITTER_DEG) * rng.standard_normal((B, P))
    deriv = np.empty_like(pred)
    for s_ in np.unique(series):
        sel = np.flatnonzero(series == s_)
        x = pred[sel]
        k = np.fft.rfftfreq(x.size, d=1.0 / x.size)  # revolution harmonics
        deriv[sel] = np.fft.irfft(1j * k * np.fft.rfft(x), n=x.size)  # d/dφ, φ over one revolution (2π)
    return gain[:, prof] * pred[None, :] + jitter[:, prof] * deriv[None, :]


def _resampled(pool: np.ndarray, m: int, rng, B: int) -> np.ndarray:
    """``(B, m)`` standardised residuals drawn from ``pool`` with replacement, each with a random sign: the
    measured rows' own noise distribution (its tails, its scale against the stated σ), not a normal one."""
    pool = np.asarray(pool, dtype=np.float64)
    pool = pool[np.isfinite(pool)]
    return rng.choice(pool, size=(B, m)) * rng.choice([-1.0, 1.0], size=(B, m))


def parametric_null(problem: GapProblem, current, fits: dict, chain: tuple, elements, draws: int = DRAWS,
                    seed: int = 0, nuisances: bool = False) -> NullResult:
    """The parametric null of one round (module docstring): data from ``current`` (the fit of ``chain``), the
    candidates ``elements`` (each fitted in ``fits[chain + parts(element)]``) refitted linearly. ``nuisances`` —
    the null the rule where the null decides instead of a bar is judged by: for profiles the current model moved
    by the rig's nuisances per draw (:func:`_nuisances`: gain drift over the session, angle jitter per run) before
    the phase-randomised residual (coloured, heteroscedastic per run and channel as measured) is added; for mode
    tables the redrawn rows' noise resampled from their own standardised residuals about the current model
    (:func:`_resampled`: heavy tails and a σ stated too small are in the draws, as they are in the data)."""
    rng = np.random.default_rng(seed)
    y = problem.y
    m = problem.m
    pred = np.asarray(current.extra["pred"])
    if problem.domain == "profiles":
        base = _nuisances(problem, pred, rng, draws) if nuisances else pred[None, :]
        ystar = base + _phase_randomised(y - pred, np.asarray(problem.labels["series"]), rng, draws)
        kind = ("parametric: the current model plus its residual phase-randomised per run and channel"
                + (f"; with the rig's nuisances: a gain drifting by up to ±{100 * GAIN_DRIFT_MAX:g} % over the "
                   f"session (runs in speed order) and a per-run angle jitter of {ANGLE_JITTER_DEG:g} deg"
                   if nuisances else ""))
    else:
        ref = problem.meta.reference_mask
        redraw = np.ones(m, dtype=bool) if ref is None else ~np.asarray(ref, dtype=bool)
        if nuisances:
            z = (y - pred) / problem.sigma
            eps = _resampled(z[redraw] if np.count_nonzero(redraw) >= RESAMPLE_MIN_ROWS else z, m, rng, draws)
        else:
            eps = rng.standard_normal((draws, m))
        ystar = np.where(redraw[None, :], pred[None, :] + problem.sigma[None, :] * eps, y[None, :])
        kind = (("parametric (resampled residuals): rows redrawn from the current model with their own "
                 "standardised residuals resampled (random signs)" if nuisances else
                 "parametric: rows redrawn from the current model with each row's σ") + ", labels kept"
                + ("; the reference table held as measured" if ref is not None else ""))
    lin_cur = linearise(problem, current)
    lins = [linearise(problem, fits[chain + parts(el)]) for el in elements]
    rule = problem.meta.noise_rule
    sigma_star = None
    if rule is not None:  # the noise estimate repeated on every draw, as it was made on the data
        sigma_star = np.asarray(rule(ystar, pred), dtype=np.float64)
        kind += "; σ re-estimated from every draw by the problem's own noise rule"
    t_null = np.max(candidate_shrinks(problem, lin_cur, lins, ystar, sigma_star), axis=1, initial=-np.inf)
    obs = candidate_shrinks(problem, lin_cur, lins, y)[0]
    observed = {el: float(t) for el, t in zip(elements, obs)}
    return NullResult(kind, t_null, observed, _p_values(t_null, observed),
                      "held-out shrink of the best candidate of the round over the current model (linearised refits)")


def candidate_shrinks(problem: GapProblem, lin_cur: Linearised, lins: list, y, sigma=None) -> np.ndarray:
    """``(B, C)`` held-out shrink ``1 − SS_c/SS_current`` of each linearised candidate on data ``y`` ``(B, m)`` (or
    ``(m,)``), the problem's σ and folds: the statistic of the parametric null and of the measured data alike.

    Where the problem has several row groups (profiles: the channels), a candidate may be accepted on the
    shrink of one group (:func:`ringfit.gap.verdict.acceptance`), so its statistic is the largest of its
    shrink over all rows and over each group — in the null as in the data.

    ``sigma``: optional ``(B, m)`` σ of each draw's rows (the problem's noise rule applied to the draw), in place
    of the problem's (the held-out σ scaled with it)."""
    sig = problem.sigma_heldout if problem.sigma_heldout is not None else problem.sigma
    w2 = 1.0 / problem.sigma**2
    if sigma is not None:
        sig = sigma * (sig / problem.sigma)[None, :]
        w2 = 1.0 / sigma**2
    groups = np.asarray(problem.labels.get("group", np.zeros(problem.m)))
    masks = [np.ones(problem.m, dtype=bool)]
    if len(set(groups.tolist())) > 1:
        masks += [groups == g for g in dict.fromkeys(groups.tolist())]

    def ss(e):
        z2 = _psi2(problem, e, sig)
        return [np.sum(np.where(mk, z2, 0.0), axis=-1) for mk in masks]

    ss_cur = ss(heldout_linear(lin_cur, y, w2, problem.folds))
    cols = []
    for lin in lins:
        ss_c = ss(heldout_linear(lin, y, w2, problem.folds))
        cols.append(np.max([1.0 - a / np.maximum(b, 1e-300) for a, b in zip(ss_c, ss_cur)], axis=0))
    return np.stack(cols, axis=1) if cols else np.zeros((np.atleast_2d(y).shape[0], 0))


def _psi2(problem: GapProblem, e, sigma) -> np.ndarray:
    """ψ(e/σ)² per row (:meth:`~ringfit.gap.problem.GapProblem.psi`: Huber on the problem's robust rows)."""
    return problem.psi(np.asarray(e) / sigma) ** 2


def random_line_null(problem: GapProblem, fits: dict, chain: tuple, elements, draws: int = DRAWS,
                     seed: int = 1, frequencies=None) -> NullResult | None:
    """The random-line null (module docstring) of a frequency problem whose rows were matched by frequency;
    ``None`` when it has none. Statistic: total shrink of ``chain`` + each candidate against the baseline.

    ``frequencies``: optional ``f(rows) -> (draws, len(rows))`` giving the drawn frequencies of a group of rows
    instead of uniform draws (a test feeds the measured ones back: the null's statistic must then equal the
    observed one)."""
    from ringfit.gap.modal_lines import line_problem, mixture_sigma

    setup = line_problem(problem)
    if setup is None:
        return None
    lp, groups, tables = setup
    rng = np.random.default_rng(seed)
    m = problem.m
    y = problem.y
    sig = problem.sigma_heldout if problem.sigma_heldout is not None else problem.sigma
    base_lin = linearise(lp, fits[()])
    # draws: matched rows uniform over their table's span, labelled test rows from the baseline
    ref = np.asarray((problem.meta.reference_mask if problem.meta.reference_mask is not None else np.zeros(m, dtype=bool)), dtype=bool)
    ystar = np.where(ref[None, :], y[None, :],
                     base_lin.pred[None, :m] + problem.sigma[None, :] * rng.standard_normal((draws, m)))
    idx = np.broadcast_to(np.arange(m), (draws, m)).copy()
    s_meas = np.broadcast_to(problem.sigma, (draws, m)).copy()
    s_ho = np.broadcast_to(sig, (draws, m)).copy()
    base_sigma = (problem.meta.sigma_matched if problem.meta.sigma_matched is not None else problem.sigma)
    loaded_draws = None
    overridden = np.zeros(draws, dtype=int)
    labelled = 0
    for g in groups:
        rows = g["rows"]
        if frequencies is not None:
            f = np.asarray(frequencies(rows), dtype=np.float64)
        elif "draw" in g:  # rolling tables: each table's rows over its own span
            f = g["draw"](rng, draws)
        else:
            lo, hi = tables[g["table"]]
            f = np.sort(rng.uniform(lo, hi, (draws, rows.size)), axis=1)
        ystar[:, rows] = f
        s = base_sigma[rows] * f / y[rows]  # each row's relative σ, at its new frequency
        if "choose" in g:  # rolling tables: the model structure chosen per draw by the case's own rule
            idx[:, rows], swaps, loaded_draws = g["choose"](ystar)
            for where, ix in swaps:
                idx[:, where] = ix
            s = g["sigma"](f, s, idx[:, rows], loaded_draws)
            if "overrides" in g:
                overridden += g["overrides"](idx[:, rows], loaded_draws)
                labelled += g.get("labelled_rows", 0)
        else:
            idx[:, rows] = g["assign"](f)
            if "hz" in g:  # two lines within reach → the mixture, as in the measured table
                s = mixture_sigma(f, s, g["hz"][idx[:, rows] - g["start"]], g["hz"])[0]
        s_meas[:, rows] = s
        s_ho[:, rows] = s * (sig[rows] / problem.sigma[rows])  # the held-out σ's share of prediction variance
    sig_b = s_ho
    w2 = 1.0 / s_meas**2
    folds = problem.folds
    ss_base = sum_of_squares(problem, heldout_linear(base_lin, ystar, w2, folds, idx), sig_b)
    ss_base_obs = sum_of_squares(problem, heldout_linear(base_lin, y, 1.0 / problem.sigma**2, folds), sig)[0]
    t_null = np.full(draws, -np.inf)
    observed = {}
    for el in elements:
        lin = linearise(lp, fits[chain + parts(el)])
        ss = sum_of_squares(problem, heldout_linear(lin, ystar, w2, folds, idx), sig_b)
        t_null = np.maximum(t_null, 1.0 - ss / np.maximum(ss_base, 1e-300))
        ss_o = sum_of_squares(problem, heldout_linear(lin, y, 1.0 / problem.sigma**2, folds), sig)[0]
        observed[el] = float(1.0 - ss_o / max(ss_base_obs, 1e-300))
    n_rows = int(sum(g["rows"].size for g in groups))
    kind = (f"random-line: the {n_rows} rows whose line the data choose (no label, or a label the assignment may "
            "override) redrawn uniformly over their table's span, labels kept, and matched by the diagnosis's "
            "rule; rows pinned by their labels drawn from the baseline")
    if loaded_draws is not None:
        kind += (f"; the rolling rows' model structure chosen per draw by the same rule as the measured rows "
                 f"(the rolling, loaded model in {int(np.sum(loaded_draws))} of {draws} draws, else the free "
                 "spinning ring)")
    extra = {}
    if labelled:
        extra = {"labelled_rows": labelled, "overridden_median": float(np.median(overridden)),
                 "overridden_q05": float(np.quantile(overridden, 0.05)),
                 "overridden_q95": float(np.quantile(overridden, 0.95))}
    return NullResult(kind, t_null, observed, _p_values(t_null, observed),
                      "held-out shrink of the chain plus the best candidate over the baseline (linearised refits)",
                      extra)


def label_permutation_test(problem: GapProblem, draws: int = DRAWS, seed: int = 2) -> dict | None:
    """The label-permutation test (docs/physics.md §6.4, docs/formats.md §5 ``verdict.labels``): do the labels of
    the rolling tables carry information the model agrees with? The measured frequencies are kept; the labels (n,
    tag, branch) of each rolling table's rows are shuffled among them, and the whole assignment is repeated exactly
    as for the measured rows (the model structure chosen with the shuffled labels' penalties, its τ maximised, then
    the Hungarian assignment). Statistic: the number of labels the assignment keeps (its line agrees with them);
    ``p = (1 + #{kept* ≥ kept})/(N + 1)`` — small when the model agrees with the labels as given far more often
    than with the same labels put on other rows. (The held-out shrink against the baseline is not the statistic
    here: the baseline reads the labels too, so shuffled labels make the baseline worse rather than the candidates
    better; and the candidates' own held-out fit favours whichever assignment takes the nearest lines, which shuffled
    labels, all overridden, do.) ``None`` where no rolling table's rows carry labels the assignment may override."""
    from ringfit.gap.modal_lines import line_problem

    setup = line_problem(problem)
    if setup is None:
        return None
    _, groups, _ = setup
    g = next((g for g in groups if "permuted" in g), None)
    if g is None or not g.get("labelled_rows"):
        return None
    rng = np.random.default_rng(seed)
    y = problem.y
    _, _, _, over = g["permuted"](rng, draws, y)
    kept_null = g["labelled_rows"] - over  # each draw's own (shuffled) labels kept
    idx_obs, _, loaded_obs = g["choose"](np.asarray(y, dtype=np.float64)[None, :])
    kept = int(g["labelled_rows"] - g["overrides"](idx_obs, loaded_obs)[0])
    p = float((1 + np.sum(kept_null >= kept)) / (draws + 1))
    return {"draws": int(draws), "labelled_rows": int(g["labelled_rows"]),
            "statistic": "labels the assignment keeps, with the labels as given against the labels shuffled among "
                         "each rolling table's rows (frequencies kept, the structure choice and assignment repeated)",
            "observed_kept": kept, "null_kept_median": float(np.median(kept_null)),
            "null_kept_q95": float(np.quantile(kept_null, 0.95)),
            "p_value": round(p, 5), "p_mc_error": round(math.sqrt(p * (1 - p) / draws), 4)}


def verdict_sentence(effect: str, null: NullResult, element: str, alpha: float) -> str:
    """"random tables of this line density get 38 % ± 6 %; these get 64 %: p = 0.002" (docs/formats.md §5)."""
    s = null.summary(element)
    what = ("random tables of this line density" if null.kind.startswith("random-line")
            else "data with no effect in it (the current model plus its noise)")
    verdict = "accepted" if s["p_value"] < alpha else "not accepted"
    return (f"{effect}: {what} get {s['mean_pct']:.0f} % ± {s['sd_pct']:.0f} % (95 % quantile {s['q95_pct']:.0f} %); "
            f"these get {s['observed_pct']:.0f} %: p = {s['p_value']:.3g} over {s['draws']} draws "
            f"(α = {alpha:g}, {verdict})")


__all__ = ["ALPHA", "DRAWS", "Linearised", "linearise", "heldout_linear", "sum_of_squares", "candidate_shrinks", "NullResult",
           "parametric_null", "random_line_null", "label_permutation_test", "verdict_sentence"]
