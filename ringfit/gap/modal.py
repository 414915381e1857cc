"""The mode-table side of the gap diagnosis: the ``eq18-free`` baseline's frequency and damping problems
(docs/physics.md §6 *baselines*; docs/formats.md §2, §5, §6).

Frequencies and damping are two problems, because they are measured on different scales and a damping residual
must never decide a structural verdict. The ring comes from the free table alone (``ringfit fit``'s fit); test
tables see it through a stop-gradient, so with no effect their rows are pure predictions. What a table's condition
fixes (the patch from ``load_n``, the speed from ``rotation_hz``) is computed, not fitted; loaded-tyre tags pick the
cos- or sin-type mode; σ is a relative level per table (second differences and MAD of the free fit's residual, or
``freq_std_hz``); test rows enter through Huber's function. Each rule, its floor and why it is so: docs/physics.md
§6 (``eq18-free``). Row building is :mod:`ringfit.gap.modal_rows`, line matching :mod:`ringfit.gap.modal_lines`,
computed conditions :mod:`ringfit.gap.modal_conditions`.

Example (the mode-table problems of ``ringfit example case --out ex``; docs/formats.md §6)::

    from ringfit.gap import effects
    from ringfit.gap.case import read_case
    from ringfit.gap.modal import build_modal_problems

    case = read_case("ex/case")
    problems = build_modal_problems([case.free, *case.tables], case.tyre,
                                    tuple(effects.get(n) for n in effects.available()))
    print([(p.domain, p.baseline_model, p.y.size) for p in problems])   # frequencies, then damping rows
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from ringfit.errors import InputError
from ringfit.gap.effects.base import Effect
from ringfit.gap.modal_conditions import (DEFAULT_K_TREAD, K_TREAD_FITTED_SD, K_TREAD_PRIOR_SD, cavity_split,
                                         is_reference_state, spin_of, static_contact, table_label, table_rows,
                                         wheel_note)
from ringfit.gap.modal_lines import LineSets, ambiguity, label_counts, match_missing_n
from ringfit.gap.modal_rows import (ROW_BUCKET, TEST_SIGMA_FLOOR_REL, DampingPredictor, ModalData, ModalPredictor,
                                   pad_rows, rolling_tables, rows_module)
from ringfit.gap.problem import GapProblem, ProblemMeta
from ringfit.gap.rolling_rows import assign_rolling_rows, joint_for
from ringfit.io.modes import ModeTable
from ringfit._cache import jit

#: Absolute floor of a frequency's σ [Hz].
FREQ_SIGMA_FLOOR_HZ = 0.02


#: Relative floor: a frequency is rarely identified better than this.
FREQ_SIGMA_FLOOR_REL = 2e-4




#: Floor of the damping noise (ln ζ): modal damping is rarely identified better than 10 %.
DAMPING_SIGMA_FLOOR = 0.10


#: Huber threshold on standardised residuals of test rows (refits and statistics).
HUBER = 2.0


#: A row whose held-out standardised residual exceeds this is named an outlier.
OUTLIER_Z = 3.0


#: Baseline parameters of the frequency side: the ring of eq. 18 (``ringfit fit``'s default free set).
BASE = ("rho_a", "ei", "kw", "kv")


#: Effect parameters a chain frees at most besides the baseline (the refit's padded free-set size).
MAX_CHAIN_PARAMETERS = 4


def second_difference_sigma(residual: np.ndarray, sequence, n: np.ndarray) -> tuple[float, int]:
    """Robust noise σ from second differences along n within each sequence; returns ``(σ, count)``."""
    d2 = []
    seq = np.asarray(sequence)
    for s in dict.fromkeys(seq.tolist()):
        idx = np.flatnonzero(seq == s)
        idx = idx[np.argsort(n[idx])]
        r = residual[idx]
        if r.size >= 3:
            d2.extend(np.abs(r[2:] - 2 * r[1:-1] + r[:-2]))
    if not d2:
        return math.nan, 0
    return float(1.4826 * np.median(d2) / math.sqrt(6.0)), len(d2)


def damping_sigma(rows, table, n, own) -> np.ndarray:
    """σ ``(B, m)`` of ln ζ rows ``(B, m)`` by the damping problem's noise rule: per table, second differences of
    ln ζ along n (:func:`second_difference_sigma`; twice :data:`DAMPING_SIGMA_FLOOR` for a table too short for
    them), floored at :data:`DAMPING_SIGMA_FLOOR`; a row whose own identification σ ``own`` (δζ/ζ, ``ringfit
    ssi``'s jackknife) is wider takes that. A function of the rows alone: the parametric null applies it to
    every draw (``ProblemMeta.noise_rule``), so a σ that chance made small in the data is as likely in the null."""
    rows = np.atleast_2d(np.asarray(rows, dtype=np.float64))
    out = np.empty_like(rows)
    zeros = {}
    for i in np.unique(table):
        sel = np.flatnonzero(table == i)
        z = zeros.setdefault(sel.size, np.zeros(sel.size))
        for b in range(rows.shape[0]):
            s_, _ = second_difference_sigma(rows[b, sel], z, n[sel])
            out[b, sel] = max(s_ if math.isfinite(s_) else 2 * DAMPING_SIGMA_FLOOR, DAMPING_SIGMA_FLOOR)
    wider = np.isfinite(own) & (own[None, :] > out)
    return np.where(wider, own[None, :], out)


def _damping_rule(rows, center=None, *, table, n, own) -> np.ndarray:
    """:func:`damping_sigma` as the problem's ``noise_rule`` (rows alone: the draw's ``center`` is not needed)."""
    return damping_sigma(rows, table, n, own)


def _baseline_covariance(fit, tyre) -> None:
    """A given baseline's uncertainty: the tyre file's ``[ring.covariance]`` (ln θ) for the parameters it holds."""
    cov = getattr(tyre, "covariance", None)
    if cov is None:
        fit.message = "the tyre file's ring, evaluated (not refitted); its uncertainty from the free table"
        return
    idx = [j for j, n in enumerate(fit.names) if n in cov.names]
    src = [cov.names.index(fit.names[j]) for j in idx]
    fit.covariance_log[np.ix_(idx, idx)] = cov.ln[np.ix_(src, src)]
    for j in idx:
        name = fit.names[j]
        fit.stderr[name] = fit.values[name] * math.sqrt(fit.covariance_log[j, j])
    fit.message = "the tyre file's ring, evaluated (not refitted), with its [ring.covariance]"


def _reference_fit(free: ModeTable, geometry, ring, user_sigma_hz=None, fixed: bool = False):
    """``ringfit fit``'s fit of the ring to the free table, with the relative σ estimated from its own residual.

    ``fixed``: no fit, the ring as given (evaluated at ``ring``).

    **Returns:** ``(fit, sigma_rel, method)``; ``sigma_rel`` NaN when ``freq_std_hz`` is complete.
    """
    import functools

    from ringfit.fit.least_squares import DEFAULT_RELATIVE_STD, frequency_data
    from ringfit.fit.least_squares import fit_natural_frequencies as _fit

    # the σ found here (stated, user, or the robust scales below) is the noise, taken as known: the free block's
    # scale from the residual (fit's default) would take an effect's misfit in the free table for noise, and the
    # nulls are calibrated on this σ (docs/physics.md §11 "Noise per block", §6 eq18-free)
    fit_natural_frequencies = functools.partial(_fit, at_initial=fixed, noise="fixed")

    base = frequency_data(free)
    if base.sigma_source == "freq_std_hz":
        return fit_natural_frequencies(free, geometry, ring, prior="physical"), math.nan, "freq_std_hz of the table"
    if user_sigma_hz is not None:
        rel = float(user_sigma_hz) / float(np.median(base.freq_hz))
        fit = fit_natural_frequencies(free, geometry, ring, prior="physical", default_relative_std=rel)
        return fit, rel, f"user value {float(user_sigma_hz):.3g} Hz"
    rel = DEFAULT_RELATIVE_STD
    for _ in range(2):  # σ weights the fit, the fit's residual gives σ
        fit = fit_natural_frequencies(free, geometry, ring, prior="physical", default_relative_std=rel)
        r = (fit.extra["model_hz"] - fit.extra["freq_hz"]) / fit.extra["freq_hz"]
        s2, cnt = second_difference_sigma(r, np.zeros(r.size), fit.extra["n"])
        mad = 1.4826 * float(np.median(np.abs(r - np.median(r)))) * math.sqrt(r.size / max(r.size - len(BASE), 1))
        rel = max(s2 if math.isfinite(s2) else 0.0, mad, FREQ_SIGMA_FLOOR_REL)
    fit = fit_natural_frequencies(free, geometry, ring, prior="physical", default_relative_std=rel)
    which = "second differences along n" if math.isfinite(s2) and s2 >= mad else "the MAD (dof-corrected)"
    return fit, rel, (f"relative σ {rel:.3g}, the larger of two robust scales of the reference fit's relative "
                      f"residual (second differences along n {s2:.3g}, MAD {mad:.3g}): {which}")


def _identification_spread(tables, ref_index=0) -> tuple[float, str] | None:
    """Relative σ of one identification from two tables of the reference state (docs/physics.md §6 *baselines*):
    the second differences along n of their relative difference Δf/f over matched n
    (:func:`second_difference_sigma`, the free table's own rule), divided by √2.

    Two identifications of the same modes differ mode by mode; a smooth difference along n is what a test
    table of the reference state that carries an effect shows (a sensor's mass, a uniform shift), and the
    second differences do not count it as noise (a MAD or RMS of Δf/f would, and the effect would widen the σ it
    is judged against)."""
    ref = tables[ref_index]
    for t in tables[1:]:
        if not is_reference_state(t):
            continue
        d, ns = [], []
        for n in sorted(set(ref.n[(ref.kind == "structural") & (ref.n >= 0)].tolist())):
            a = ref.freq_hz[(ref.n == n) & (ref.kind == "structural")]
            b = t.freq_hz[(t.n == n) & (t.kind == "structural")]
            if a.size == 1 and b.size == 1:
                d.append((b[0] - a[0]) / a[0])
                ns.append(n)
        if len(d) >= 3:
            s2, count = second_difference_sigma(np.asarray(d), np.zeros(len(d)), np.asarray(ns))
            s = s2 / math.sqrt(2.0)
            name = str(t.source).rsplit("/", 1)[-1]
            return s, (f"identification spread {s:.3g} (relative) between free.modes.csv and {name} "
                       f"(second differences of their Δf/f along n, {count} values)")
    return None


def build_modal_problems(tables: list[ModeTable], tyre, effects: tuple[Effect, ...],
                         noise: dict | None = None, baseline: bool = False) -> list[GapProblem]:
    """The frequency problem and (when there are damping rows) the damping problem of a case's mode tables.

    **Arguments:** ``tables`` — the free table first, then test tables; ``tyre`` — the case's
    :class:`~ringfit.io.tyre.Tyre` (geometry; starting ring; ``k_tread`` if known);
    ``effects`` — candidates; ``noise`` — optional user σ (``freq_hz`` [Hz], ``damping`` [ln ζ]);
    ``baseline`` — ``tyre``'s ring *is* the baseline (``diagnose --tyre``: identified or fitted before),
    evaluated on the free table, not refitted; its ``[ring.covariance]`` replaces the fit's where it has one.
    """
    noise = noise or {}
    geometry = tyre.geometry
    free = tables[0]
    fit, sigma_rel, sigma_method = _reference_fit(free, geometry, tyre.ring, noise.get("freq_hz"), fixed=baseline)
    if baseline:
        _baseline_covariance(fit, tyre)
    if fit.status not in ("converged", "evaluated"):
        raise InputError(f"the ring fit to free.modes.csv did not converge ({fit.status}): the baseline is "
                         "undefined; check the table with `ringfit fit`", source=free.source or None)
    has_kt = "k_tread" in getattr(tyre, "ring_values", {})
    ring_ref = tyre.ring.replace(**{k: fit.values[k] for k in BASE})
    if not has_kt:
        ring_ref = ring_ref.replace(k_tread=DEFAULT_K_TREAD)
    kt_sd = K_TREAD_FITTED_SD if has_kt else K_TREAD_PRIOR_SD
    spins = [spin_of(t, geometry.outer_radius) for t in tables]
    patches, conditions, splits = [], [], []
    for t in tables:
        load = t.condition.get("load_n")
        if t.state in ("loaded", "rolling") and load:
            a, sa, sol = static_contact(ring_ref, geometry, float(load), t.condition.get("drum_diameter_m"), kt_sd)
            patches.append((a, sa))
            # the loaded cavity's split W_2/h_c (docs/physics.md §6) from the same static solve
            splits.append(float(cavity_split(sol, geometry)) if t.state == "loaded" else None)
            conditions.append(f"patch half-angle {math.degrees(a):.2f} ± {math.degrees(sa):.2f} deg from "
                              f"load_n = {float(load):g} N (k_trd {ring_ref.k_tread:.3g} N/m^2"
                              f"{'' if has_kt else ', tyre.toml has none: its prior'})")
        else:
            patches.append((0.0, 0.0))
            conditions.append("")
            splits.append(None)
    for ti, t in enumerate(tables):  # the wheel on its suspension (docs/physics.md §6 wheel_suspension)
        note = wheel_note(t)
        if note:
            conditions[ti] = "; ".join(x for x in (conditions[ti], note) if x)
    rows, cavity_hz = table_rows(tables, geometry, patches, spins, splits)
    for r in rows:  # rows whose n (and type) the table leaves to matching by frequency: the random-line null's rows
        r["matchable"] = (not r["reference"]) and r["n"] < 0
        # the labels as the table gave them (the assignment of a rolling table may override them: the random-line
        # null re-assigns such rows with these labels and their penalties, calibration.py)
        r["label_n"], r["label_contact"], r["label_patch"] = r["n"], r["contact"], r["patch"]
    rolling, rolling_notes, rolling_records, choice = assign_rolling_rows(tables, rows, ring_ref, geometry, patches)
    if rolling is not None:
        for ti, note in rolling.notes.items():
            conditions[ti] = "; ".join(x for x in (conditions[ti], note) if x)
    match_notes, matched_lines = match_missing_n(rows, ring_ref, geometry)
    row_lines = {j: cand for j, (cand, _) in matched_lines.items() if rows[j]["matchable"] and rows[j]["joint"] == 0}
    for j, note in rolling_notes.items():
        match_notes[j] = "; ".join(x for x in (note, match_notes.get(j)) if x)
    problems = [_frequency_problem(tables, rows, cavity_hz, geometry, ring_ref, fit, sigma_rel, sigma_method,
                                   match_notes, patches, conditions, effects, noise, rolling, rolling_records)]
    problems[0].meta.lines = LineSets(rows=rows, rolling_lines=choice, row_lines=row_lines,
                                         cavity_hz=cavity_hz, table_patch=[p[0] for p in patches], rolling=rolling)
    if choice is not None:  # the model structure the rolling rows were assigned to (docs/formats.md §5)
        problems[0].meta.rolling_structure = choice.record()
        problems[0].meta.label_counts = label_counts(tables, rows, rolling_records, choice)
    ambiguity(problems[0], rows, choice)
    meta = problems[0].meta
    meta.table_names, meta.patches = [table_label(t, i) for i, t in enumerate(tables)], patches
    meta.spins, meta.outer_radius_m = spins, float(geometry.outer_radius)
    damp = [r for r in rows if math.isfinite(r["damping"]) and r["damping"] > 0]
    if len(damp) >= 4:
        problems.append(_damping_problem(tables, damp, cavity_hz, geometry, ring_ref, effects, noise))
    return problems


def _labels(rows, suffix=""):
    """One label per row; rows a table labels alike (e.g. two n = 5 rows of a rolling table without tags)
    are told apart by their measured frequency, so that every per-row record keyed by label stays unique."""
    out = []
    for r in rows:
        qual = " ".join(x for x in (r["tag"], r["branch"]) if x)
        out.append(f"{r['tlabel']} n={r['n']}{' ' + qual if qual else ''}")
    seen: dict = {}
    for lab in out:
        seen[lab] = seen.get(lab, 0) + 1
    return [f"{lab} at {r['freq']:.1f} Hz{suffix}" if seen[lab] > 1 else lab + suffix for lab, r in zip(out, rows)]


def _short_labels(rows, tables):
    """Plot labels: state and n (``loaded 4 extr``, ``rolling 3 b``); the table number only where two
    test tables share a state (``loaded#2 4 extr``)."""
    states = [("free" if i == 0 else t.state) for i, t in enumerate(tables)]
    out = []
    for r in rows:
        st = states[r["table"]]
        if states.count(st) > 1 and not r["reference"]:
            st = f"{st}#{r['table']}"
        qual = r["tag"] or {"backward": "b", "forward": "f"}.get(r["branch"], "")
        out.append(f"{st} {r['n']}{' ' + qual if qual else ''}")
    return out


#: What the model takes for a row (``rows[*].model_mode`` of the diagnosis JSON), by its contact tag.
CONTACT_BRANCH = {1: "contact-symmetric (cos-type) mode", 2: "contact-antisymmetric (sin-type) mode"}


def _model_modes(rows) -> list[str]:
    """Per row, the model mode it is compared with: n and branch (contact character, travelling direction)."""
    out = []
    for r in rows:
        what = f"n={r['n']}"
        if r["contact"]:
            what += " " + CONTACT_BRANCH[r["contact"]]
        elif r["branch"] in ("backward", "forward"):
            what += f" {r['branch']} wave ({'fixed' if r['fixed'] else 'co-rotating'} frame)"
        else:
            what += " (eq. 18)"
        out.append(what)
    return out


#: Up to this many rows, the held-out predictions are leave-one-out (few rows: every fold matters).
LEAVE_ONE_OUT_ROWS = 12


def _folds(rows, m):
    K = m if m <= LEAVE_ONE_OUT_ROWS else int(min(5, max(2, m // 4)))
    order = np.lexsort(([r["n"] for r in rows], [r["table"] for r in rows]))
    folds = np.empty(m, dtype=int)
    folds[order] = np.arange(m) % K
    return folds


def _usable(effects, mrows, domain_note):
    usable, dropped = [], {}
    for e in effects:
        mask = e.modal_mask(mrows)
        if mask is None:
            dropped[e.name] = "does not act on mode tables"
        elif not np.any(mask):
            # the damping problem's note stays its own; the frequency problem says what would make the effect apply
            dropped[e.name] = e.applies_when if e.applies_when and domain_note.startswith("no row") else domain_note
        else:
            usable.append(e)
    return tuple(usable), dropped


@jit
def _eq18_log_jacobian(log_base, ring, geometry, n):
    """∂f_n/∂log θ [Hz] of eq. 18 (docs/physics.md §2.1) w.r.t. the base ring parameters, rows ``n``."""
    from ringfit.physics.natural import natural_frequencies

    def f(u):
        return natural_frequencies(ring.replace(**{k: jnp.exp(u[i]) for i, k in enumerate(BASE)}), geometry, n)

    return jax.jacfwd(f)(log_base)


def _frequency_problem(tables, rows, cavity_hz, geometry, ring_ref, fit, sigma_rel, sigma_method, match_notes,
                       patches, conditions, effects, noise, rolling=None, rolling_records=None) -> GapProblem:
    from ringfit.fit.priors import PHYSICAL_PRIORS

    m = len(rows)
    mrows = rows_module(rows, 1.0, cavity_hz, [p[0] for p in patches], rolling)
    y = np.array([r["freq"] for r in rows])
    n = np.array([r["n"] for r in rows], dtype=float)
    ref = np.array([r["reference"] for r in rows])
    std = np.array([r["std"] for r in rows])
    usable, dropped = _usable(effects, mrows, "no row of these mode tables is affected")
    sizes = tuple(len(e.params_for("modes")) for e in usable)
    # --- noise
    spread = _identification_spread(tables)
    notes = [f"free.modes.csv: {sigma_method}"]
    rel = sigma_rel
    if spread is not None:
        if not math.isfinite(rel) or spread[0] > rel:
            notes.append(spread[1] + " (raises the measurement σ of every table)")
            rel = spread[0]
        else:
            notes.append(spread[1] + f" (below the reference fit's {rel:.3g}: kept)")
    ref_sigma = np.where(np.isfinite(std) & (std > 0), std, (rel if math.isfinite(rel) else 0.0) * y)
    user = noise.get("freq_hz")
    meas = np.where(np.isfinite(std) & (std > 0), std,
                    float(user) if user is not None else (rel if math.isfinite(rel) else 0.0) * y)
    own = np.isfinite(std) & (std > 0)
    meas = np.where(ref | own | (user is not None), meas, np.maximum(meas, TEST_SIGMA_FLOOR_REL * y))
    meas = np.where(ref, ref_sigma, meas)
    # prediction uncertainty of the reference fit at each test row (eq. 18, its covariance)
    n_pad = np.concatenate([n, np.ones((-m) % ROW_BUCKET)])  # one compilation per row bucket
    J = np.asarray(_eq18_log_jacobian(np.log([fit.values[k] for k in BASE]), ring_ref, geometry, n_pad))[:m]
    cov = fit.covariance_log * max(1.0, fit.chi2 / max(fit.dof, 1))
    pred_sd = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", J, cov, J), 0.0, None))
    sigma = np.where(ref, meas, np.sqrt(meas**2 + pred_sd**2))
    sigma = np.maximum(np.maximum(sigma, FREQ_SIGMA_FLOOR_HZ), FREQ_SIGMA_FLOOR_REL * y)
    if any(not r["reference"] for r in rows):
        notes.append("test rows: sqrt(measurement σ^2 + the reference fit's prediction σ^2), measurement σ from "
                     f"freq_std_hz where given, else the free table's (at least {TEST_SIGMA_FLOOR_REL:.1%} of the "
                     "frequency)")
    notes.append(f"Huber weighting of test rows beyond |z| = {HUBER:g}; outliers named at |z| > {OUTLIER_Z:g}")
    # --- problem
    labels = _labels(rows)
    for j, note in match_notes.items():
        if "n matched" in note:
            labels[j] += " (n matched)"
    prior_mean = np.array([fit.values[k] for k in BASE])
    prior_sd = np.full(len(BASE), np.inf)
    ei = PHYSICAL_PRIORS["ei"]
    prior_mean[1], prior_sd[1] = ei.median, ei.sigma_ln
    data = ModalData(rows=pad_rows(mrows), ring=ring_ref, geometry=geometry)
    meta_labels = dict(
        table=np.array([r["table"] for r in rows]), group=np.full(m, "frequency"), label=labels,
        short=_short_labels(rows, tables), family=[r["tlabel"] for r in rows], model_mode=_model_modes(rows),
        sequence=[f"{r['table']}|{r['tag']}|{r['branch']}" for r in rows],
        matched={labels[j]: note for j, note in match_notes.items()},
        rolling={labels[j]: rec for j, rec in (rolling_records or {}).items()},
        cavity_hz=cavity_hz, measured_freq=y)
    problem = GapProblem(
        domain="modes", data_files=[str(t.source).rsplit("/", 1)[-1] for t in tables], y=y, sigma=sigma,
        unit="Hz", scale=np.ones(m), folds=_folds(rows, m), fold_kind="leave-modes-out (free rows); test rows are "
        "predictions of the free-table fit", labels=meta_labels, base=BASE, base_values=prior_mean.copy(),
        base_prior_sd=prior_sd, effects=usable, data=data, noise_method="; ".join(notes),
        baseline_model="eq18-free (ringfit fit on free.modes.csv)", not_applicable=dropped,
        meta=ProblemMeta(reference_mask=ref, block=1, tangents=len(BASE) + MAX_CHAIN_PARAMETERS,
                         padded_rows=int(data.rows.n.shape[0]), files=[str(t.source).rsplit("/", 1)[-1] for t in tables],
                         reference_fit=fit.to_record(sigma_rel=sigma_rel, sigma_method=sigma_method),
                         conditions={table_label(t, i): c for i, (t, c) in enumerate(zip(tables, conditions)) if c},
                         reference_result=fit, condition_sd=_condition_sd(patches)),
        base_prior_mean=prior_mean,
        predictor=ModalPredictor(effects=usable, base=BASE, sizes=sizes,
                                 joint=joint_for(usable, sizes, len(BASE), rolling_tables(rows))),
        robust=~ref, huber=HUBER,
    )
    problem.base_values = np.array([fit.values[k] for k in BASE])
    return problem


def _condition_sd(patches) -> dict:
    """σ of the condition-fixed effect parameters: the patch scale's from the k_trd uncertainty (RMS over tables)."""
    rel = [sa / a for a, sa in patches if a > 0]
    return {"ground_contact": {"patch_scale": float(np.sqrt(np.mean(np.square(rel))))}} if rel else {}


def _damping_problem(tables, rows, cavity_hz, geometry, ring_ref, effects, noise) -> GapProblem:
    m = len(rows)
    table_ids = sorted({r["table"] for r in rows})
    remap = {t: i for i, t in enumerate(table_ids)}
    mrows = rows_module([dict(r, table=remap[r["table"]]) for r in rows], 0.0, cavity_hz, np.zeros(len(table_ids)))
    y = np.log(np.array([r["damping"] for r in rows]) / 100.0)
    n = np.array([r["n"] for r in rows], dtype=float)
    tab = np.array([remap[r["table"]] for r in rows])
    usable, dropped = _usable(effects, mrows, "no damping rows")
    sizes = tuple(len(e.params_for("modes")) for e in usable)
    base = tuple(f"damping_ratio:{table_label(tables[t], t)}" for t in table_ids)
    levels = np.array([math.exp(float(np.median(y[tab == i]))) for i in range(len(table_ids))])
    notes = []
    user = noise.get("damping")
    own = np.array([r.get("damping_std", math.nan) / r["damping"] for r in rows])
    rule = None
    if user is not None:
        sigma = np.full(m, max(float(user), DAMPING_SIGMA_FLOOR))
        notes += [f"{table_label(tables[t], t)}: user value {float(user):.3g}" for t in table_ids]
    else:
        # the noise rule, a function of the rows alone: the parametric null applies it to every draw
        rule = functools.partial(_damping_rule, table=tab, n=n, own=own)
        sigma = rule(y[None, :])[0]
        for i, t in enumerate(table_ids):
            sel = tab == i
            cnt = second_difference_sigma(y[sel], np.zeros(int(sel.sum())), n[sel])[1]
            notes.append(f"{table_label(tables[t], t)}: " + (f"too few modes for second differences, "
                                                             f"{2 * DAMPING_SIGMA_FLOOR:.3g}" if cnt == 0 else
                                                             f"{float(np.median(sigma[sel])):.3g} from second differences "
                                                             f"of ln(damping) along n ({cnt} values)"))
        wider = np.isfinite(own) & (own > damping_sigma(y[None, :], tab, n, np.full(m, np.nan))[0])
        if wider.any():
            notes.append(f"{int(wider.sum())} rows widened to their own damping_std_pct / damping_pct")
    notes.append(f"one damping level per table; Huber weighting beyond |z| = {HUBER:g}")
    labels = _labels(rows, " damping")
    data = ModalData(rows=pad_rows(mrows), ring=ring_ref, geometry=geometry)
    problem = GapProblem(
        domain="damping", data_files=[str(tables[t].source).rsplit("/", 1)[-1] for t in table_ids], y=y,
        sigma=sigma, unit="ln(damping ratio)", scale=np.ones(m), folds=_folds(rows, m), fold_kind="leave-modes-out",
        labels=dict(table=tab, group=np.full(m, "damping"), label=labels, short=_short_labels(rows, tables),
                    family=[r["tlabel"] + " damping" for r in rows],
                    sequence=[f"{r['table']}|{r['tag']}|{r['branch']}" for r in rows], matched={},
                    measured_freq=np.array([r["freq"] for r in rows])),
        base=base, base_values=levels, base_prior_sd=np.full(len(base), np.inf), effects=usable, data=data,
        noise_method="; ".join(notes), baseline_model="one damping ratio per table", not_applicable=dropped,
        meta=ProblemMeta(block=1, tangents=len(base) + MAX_CHAIN_PARAMETERS, padded_rows=int(data.rows.n.shape[0]),
                         files=[str(tables[t].source).rsplit("/", 1)[-1] for t in table_ids], tables=table_ids,
                         noise_rule=rule),
        predictor=DampingPredictor(effects=usable, base=base, sizes=sizes),
        robust=np.ones(m, dtype=bool), huber=HUBER,
    )
    return problem


__all__ = ["build_modal_problems", "second_difference_sigma", "HUBER", "OUTLIER_Z", "BASE", "FREQ_SIGMA_FLOOR_HZ",
           "FREQ_SIGMA_FLOOR_REL", "DAMPING_SIGMA_FLOOR"]
