"""The candidate model lines of the mode-table rows: the random-line null and the label rules (docs/physics.md §6.4).

:class:`LineSets` (per row its candidate lines; the rolling tables' assignment), rows without n matched to the
nearest line, the ambiguity widening (:func:`mixture_sigma`), the line problem of the random-line null
(:func:`line_problem`) and the label counts (:func:`label_counts`: which rows the assignment may override).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ringfit.gap.modal_conditions import table_label
from ringfit.gap.modal_rows import (TEST_SIGMA_FLOOR_REL, ModalData, ModalPredictor, rows_module, pad_rows,
                                   rolling_tables)
from ringfit.gap.problem import UNSET, GapProblem
from ringfit.gap.rolling_rows import joint_for
from ringfit.physics.natural import natural_frequencies_jit


#: Rows of a line problem (the random-line null, :func:`line_problem`) are padded to a multiple of this.
LINE_BUCKET = 128


#: Largest n a row without n is matched to.
MATCH_N_MAX = 15


@dataclass
class LineSets:
    """What the random-line null of :mod:`ringfit.gap.calibration` needs to match new frequencies by the
    diagnosis's own rule: the frequency problem's row dicts, the rolling tables' lines under both model
    structures and the rule that chooses between them (``rolling_lines``: the
    :class:`~ringfit.gap.rolling_rows.StructureChoice` of :func:`ringfit.gap.rolling_rows.assign_rolling_rows`,
    ``None`` without rolling tables), and per row without n of another test
    table the lines of the model its condition computes (:func:`missing_n_lines`, n = 1 … MATCH_N_MAX)."""

    rows: list
    rolling_lines: object
    row_lines: dict
    cavity_hz: float
    table_patch: list
    rolling: object


def missing_n_lines(r: dict, ring, geometry) -> tuple[np.ndarray, str]:
    """The frequencies [Hz] of n = 1 … :data:`MATCH_N_MAX` in the model a row's condition computes (the loaded
    modes of its type at the computed patch, eq. 25/26 of its branch, else eq. 18), and the model's name."""
    from ringfit.physics.loaded import loaded_natural_frequencies
    from ringfit.physics.natural import fixed_frame_frequencies, rotating_natural_frequencies

    n_all = np.arange(1, MATCH_N_MAX + 1, dtype=float)
    if r["contact"] and r["patch"] > 0:
        c, s = (np.asarray(x)[:MATCH_N_MAX] for x in loaded_natural_frequencies(ring, geometry, r["patch"]))
        return (c if r["contact"] == 1 else s), "loaded modes at the computed patch"
    if r["spin"] > 0 and r["branch"]:
        fn = fixed_frame_frequencies if r["fixed"] else rotating_natural_frequencies
        waves = np.abs(np.asarray(fn(ring, geometry, n_all, r["spin"])))
        return waves[:, 0 if r["branch"] == "backward" else 1], ("eq. 26" if r["fixed"] else "eq. 25")
    return np.asarray(natural_frequencies_jit(ring, geometry, n_all)), "eq. 18"  # one program, not one per op


#: Two lines within this many σ of a row's frequency: its assignment is ambiguous (docs/formats.md §5).
AMBIGUOUS_Z = 2.0


def mixture_sigma(f, sigma, hz_assigned, hz_lines):
    """σ of rows whose frequency ``f`` lies within :data:`AMBIGUOUS_Z` σ of a line other than the one assigned:
    √(σ² + (Δ/2)²), Δ the spacing from the assigned line to the nearest such line (the two-line mixture in moment
    form); ``σ`` elsewhere. Arrays broadcast over rows; ``hz_lines`` ``(L,)``. **Returns** ``(σ', ambiguous, alt)``."""
    f, sigma, hz_assigned = (np.asarray(x, dtype=np.float64) for x in (f, sigma, hz_assigned))
    hz = np.asarray(hz_lines, dtype=np.float64)
    near = (np.abs(hz - f[..., None]) <= AMBIGUOUS_Z * sigma[..., None]) & (np.abs(hz - hz_assigned[..., None]) > 1e-9)
    gap = np.where(near, np.abs(hz - hz_assigned[..., None]), np.inf)
    j = np.argmin(gap, axis=-1)
    ambiguous = np.any(near, axis=-1)
    alt = np.take_along_axis(np.broadcast_to(hz, gap.shape), j[..., None], -1)[..., 0]
    half = np.where(ambiguous, np.min(gap, axis=-1) / 2.0, 0.0)
    return np.sqrt(sigma**2 + half**2), ambiguous, alt


def ambiguity(problem: GapProblem, rows, choice):
    """Rows of rolling tables whose frequency lies within :data:`AMBIGUOUS_Z` σ of a second line of their table
    (of the model structure the case chose, :class:`ringfit.gap.rolling_rows.StructureChoice`): the data cannot
    decide between the two, so the row carries the two-line mixture (equal weights) in moment form —
    the matched line's prediction with σ² widened by (Δ/2)², Δ the lines' spacing — instead of a free choice."""
    problem.meta.sigma_matched = problem.sigma.copy()  # before any widening (the random-line null widens alike)
    if choice is None:
        return
    line_sets = choice.lines[choice.chosen]
    rec = problem.labels["rolling"]
    for j, r in enumerate(rows):
        if not r.get("rolling_matched") or r["table"] not in line_sets or r.get("line_hz") is None:
            continue
        sig, amb, other = mixture_sigma(r["freq"], problem.sigma[j], r["line_hz"],
                                        [ln["hz"] for ln in line_sets[r["table"]]])
        if not amb:
            continue
        problem.sigma[j] = float(sig)
        label = problem.labels["label"][j]
        if label in rec:
            rec[label].update(ambiguous=True, alternative_hz=round(float(other), 4),
                              mixture_sigma_hz=round(float(sig), 4))


def match_missing_n(rows, ring, geometry):
    """Assign n to rows without one: nearest mode of the model their condition computes.

    **Returns:** ``(notes, lines)``: the match sentence and the model's lines (:func:`missing_n_lines`) of each
    matched row, by row position. Rows that see the same model (same table condition and mode type) share one
    evaluation of it.
    """
    notes, lines, seen = {}, {}, {}
    for j, r in enumerate(rows):
        if r["n"] >= 0:
            continue
        key = (r["contact"], r["patch"]) if r["contact"] and r["patch"] > 0 else \
            (r["spin"], r["branch"], r["fixed"]) if r["spin"] > 0 and r["branch"] else "eq18"
        if key not in seen:
            seen[key] = missing_n_lines(r, ring, geometry)
        cand, model = lines[j] = seen[key]
        k = int(np.argmin(np.abs(cand - r["freq"])))
        r["n"] = k + 1
        notes[j] = (f"n matched to {k + 1} by frequency ({r['freq']:.1f} Hz vs {cand[k]:.1f} Hz of {model})")
    return notes, lines


def line_problem(problem: GapProblem):
    """The *line problem* of a frequency problem whose test rows were matched by frequency (the random-line null
    of :mod:`ringfit.gap.calibration`): the problem's rows followed by one row per line a new frequency of such a
    row could be matched to (each rolling table's lines, with the labels the shared assignment gives; for a row
    of another table, n = 1 … :data:`MATCH_N_MAX` of the model its condition computes), predicted by the same
    predictor. ``None`` when no row was matched by frequency.

    **Returns:** ``(line_problem, groups, spans)``: ``groups`` — per rolling table (or per row elsewhere)
    its row positions ``rows``, ``kind`` and ``assign(f) -> (B, r)`` line-problem row indices for
    frequencies ``f`` ``(B, r)`` by the diagnosis's rule (one assignment per rolling table by the matching
    cost of ``ringfit campbell``; the nearest line elsewhere); ``spans`` — ``{table: (lowest, highest)}``
    measured frequency. Cached in ``problem.meta``.
    """
    if problem.meta.line_problem is not UNSET:
        return problem.meta.line_problem

    L = problem.meta.lines
    rows = L.rows if L is not None else []
    m = len(rows)
    matchable = [j for j, r in enumerate(rows) if r.get("matchable") or _label_free(r, L.rolling_lines)]
    if not matchable:
        problem.meta.line_problem = None
        return None
    spans = {t: (min(r["freq"] for r in rows if r["table"] == t), max(r["freq"] for r in rows if r["table"] == t))
             for t in {rows[j]["table"] for j in matchable}}
    extra, groups = [], []
    if L.rolling_lines is not None:
        g = _rolling_group(L.rolling_lines, rows, matchable, extra, m)
        if g is not None:
            groups.append(g)
    for j in matchable:
        if j not in L.row_lines:
            continue
        hz = np.asarray(L.row_lines[j], dtype=np.float64)
        start = m + len(extra)
        extra += [{**rows[j], "n": k + 1, "freq": float(h), "matchable": False} for k, h in enumerate(hz)]
        groups.append(dict(kind="nearest", table=rows[j]["table"], rows=np.asarray([j]),
                           assign=lambda f, hz=hz, start=start: start + np.argmin(np.abs(f[..., None] - hz), axis=-1)))
    if not groups:
        problem.meta.line_problem = None
        return None
    every = list(rows) + extra
    mrows = rows_module(every, 1.0, L.cavity_hz, L.table_patch, L.rolling)
    # a coarser bucket than the problem's: line problems of different cases (a few hundred rows) then share
    # one compiled linearisation per candidate structure instead of compiling per 32-row step
    data = ModalData(rows=pad_rows(mrows, LINE_BUCKET), ring=problem.data.ring, geometry=problem.data.geometry)
    p = problem.predictor
    # the joint rolling model only where the problem has it (a case whose rows chose the free spinning ring has none)
    predictor = ModalPredictor(effects=p.effects, base=p.base, sizes=p.sizes,
                               joint=None if p.joint is None else
                               joint_for(p.effects, p.sizes, len(p.base), rolling_tables(every)))
    y = np.array([r["freq"] for r in every])
    M = len(every)
    lp = dataclasses.replace(
        problem, y=y, sigma=np.concatenate([problem.sigma, TEST_SIGMA_FLOOR_REL * y[m:]]),
        robust=np.concatenate([np.asarray(problem.robust, dtype=bool), np.ones(M - m, dtype=bool)]),
        scale=np.ones(M), folds=np.zeros(M, dtype=int), data=data, predictor=predictor, sigma_heldout=None,
        meta=dataclasses.replace(problem.meta, padded_rows=int(data.rows.n.shape[0]), line_problem=None))
    problem.meta.line_problem = (lp, groups, spans)
    return problem.meta.line_problem


def _label_free(r: dict, choice) -> bool:
    """Whether the data choose a row's line although the table may label it: a structural row of a rolling table
    assigned by the matching cost, where a contradicted label costs a finite penalty (``ringfit campbell``'s
    :data:`~ringfit.gap.campbell.LABEL_PENALTY`) — the assignment may override its n, tag or branch. Such a row
    is redrawn by the random-line null like a row without labels (its labels kept, docs/physics.md §6.4)."""
    return bool(choice is not None and r.get("rolling_matched") and r["table"] in choice.tables)


def _line_row(r: dict, name: str, ln: dict) -> dict:
    """The row ``r`` (labels as the table gave them) assigned to the line ``ln`` of structure ``name``: the fields
    the measured assignment gives it (:func:`ringfit.gap.rolling_rows.assign_rolling_rows`) — the line's mode,
    sensor line, n, wave and loaded-mode type, except where the row's own label says otherwise (a given n stays
    the row's n; a given branch its wave; a given tag its loaded-mode type)."""
    from ringfit.gap.rolling_rows import LOADED

    f = dict(ln["fields"])
    n0 = r.get("label_n", r["n"])
    if n0 >= 1:
        f["n"] = n0
    if name == LOADED:
        if r["branch"]:
            f["wave"] = ""
        c0 = r.get("label_contact", 0)
        if c0:
            f["contact"], f["patch"] = c0, r.get("label_patch", f["patch"])
    return {**r, **f, "freq": ln["hz"], "matchable": False, "line_hz": ln["hz"]}


def _rolling_group(choice, rows, matchable, extra, m):
    """The random-line null's group of the rolling tables' rows whose line the data choose (:func:`line_problem`):
    rows without labels and rows whose labels the assignment may override (:func:`_label_free`: every matched row
    of a rolling table), redrawn uniformly over their table's span with their labels kept. The model structure is
    chosen per draw by the case's own rule (:class:`ringfit.gap.rolling_rows.StructureChoice`, its τ maximised per
    draw, the rows' label penalties included), then one assignment per table under that structure by the matching
    cost of ``ringfit campbell`` (Hungarian; z² + the line's weight cost + the row's label penalties, τ of the
    measured assignment). Adds to ``extra`` one line-problem row per line of either structure and per distinct
    label set of a table's rows (the prediction of a labelled row on a line depends on its labels), and per other
    labelled rolling row its copy with the other structure's assignment (swapped in on draws that choose the other
    structure). ``None`` without such rows."""
    from scipy.optimize import linear_sum_assignment

    from ringfit.gap.campbell import matching_cost
    from ringfit.gap.rolling_rows import FREE, LOADED

    per_table: dict = {}
    for j in matchable:
        if rows[j].get("rolling_matched") and rows[j]["table"] in choice.tables:
            per_table.setdefault(rows[j]["table"], []).append(j)
    if not per_table:
        return None
    chosen = choice.chosen
    segments = []  # per table: its rows, and per structure (start per row, hz, sigma, cost, penalties) of its lines
    for t, js in per_table.items():
        tb = choice.tables[t]
        pos = {int(j): k for k, j in enumerate(tb["rows"])}
        where = np.array([pos[j] for j in js])
        mine = [r["freq"] for r in rows if r["table"] == t]  # the table's span, as every random-line draw
        seg = {"table": t, "rows": np.asarray(js), "lo": min(mine), "hi": max(mine), "std": tb["std"][where]}
        for name in (LOADED, FREE):
            lines = choice.lines[name][t]
            starts, by_key = [], {}
            for j in js:
                r = rows[j]
                key = (r.get("label_n", r["n"]), r.get("label_contact", 0), r["branch"], r["tag"])
                if key not in by_key:
                    by_key[key] = m + len(extra)
                    extra.extend(_line_row(r, name, ln) for ln in lines)
                starts.append(by_key[key])
            hz = np.array([ln["hz"] for ln in lines])
            seg[name] = (np.asarray(starts), hz, np.array([ln["cost"] for ln in lines]),
                         np.asarray(tb["pen"][name], dtype=np.float64)[where])
        segments.append(seg)
    # labelled rows of the rolling tables the groups leave alone: their assignment under the structure the
    # measured rows did not choose
    in_groups = {int(j) for s in segments for j in s["rows"]}
    other = FREE if chosen == LOADED else LOADED
    labelled, swapped = [], []
    for j, r in enumerate(rows):
        if "structure_fields" in r and j not in in_groups:
            labelled.append(j)
            swapped.append(m + len(extra))
            extra.append({**r, **r["structure_fields"][other], "matchable": False})
    labelled, swapped = np.asarray(labelled, dtype=int), np.asarray(swapped, dtype=int)
    all_rows = np.concatenate([s["rows"] for s in segments])

    def hungarian(f, std, starts, hz, cost, pen):
        c = matching_cost(f[..., None], std[:, None], hz, cost, pen)  # (B, r, L): ringfit campbell's cost
        col = np.argmin(c, axis=-1)  # rows the assignment leaves without a line: their nearest
        for b in range(f.shape[0]):
            ri, ci = linear_sum_assignment(np.minimum(c[b], 1e6))
            col[b, ri] = ci
        return np.broadcast_to(starts, col.shape) + col

    def draw(rng, B):
        # per table, uniform over its span at its row count (sorted, as a table lists its rows)
        return np.concatenate([np.sort(rng.uniform(s["lo"], s["hi"], (B, s["rows"].size)), axis=1)
                               for s in segments], axis=1)

    def choose(ystar):
        """``(idx (B, r), [(positions, idx (B, l))], loaded (B,))`` for the drawn data ``ystar`` ``(B, m)``."""
        loaded = choice.choose({t: ystar[:, tb["rows"]] for t, tb in choice.tables.items()})
        out = []
        for s in segments:
            f = ystar[:, s["rows"]]
            out.append(np.where(loaded[:, None], hungarian(f, s["std"], *s[LOADED]),
                                hungarian(f, s["std"], *s[FREE])))
        same = loaded if chosen == LOADED else ~loaded
        lab = np.where(same[:, None], labelled[None, :], swapped[None, :])
        return np.concatenate(out, axis=1), [(labelled, lab)], loaded

    def sigma(f, s_rows, idx_rows, loaded):
        """The two-line mixture's σ of each drawn row under the structure its draw chose (as the measured rows)."""
        out, col = np.array(s_rows, dtype=np.float64), 0
        for sg in segments:
            k = sg["rows"].size
            sl = slice(col, col + k)
            res = []
            for name in (LOADED, FREE):
                starts, hz, _, _ = sg[name]
                ix = np.clip(idx_rows[:, sl] - starts[None, :], 0, hz.size - 1)
                res.append(mixture_sigma(f[:, sl], out[:, sl], hz[ix], hz)[0])
            out[:, sl] = np.where(loaded[:, None], res[0], res[1])
            col += k
        return out

    def overrides(idx_rows, loaded, perms=None):
        """``(B,)`` labels the drawn assignment overrode (the null's count beside the measured one); ``perms``: per
        segment ``(B, k)`` the label permutation the draws were assigned with (the label-permutation test)."""
        total, col = np.zeros(idx_rows.shape[0], dtype=int), 0
        for si, sg in enumerate(segments):
            k = sg["rows"].size
            sl = slice(col, col + k)
            for name, on in ((LOADED, loaded), (FREE, ~loaded)):
                starts, hz, _, pen = sg[name]
                if perms is None:
                    start_b = np.broadcast_to(starts, (idx_rows.shape[0], k))
                    pen_b = np.broadcast_to(pen, (idx_rows.shape[0],) + pen.shape)
                else:
                    start_b, pen_b = starts[perms[si]], pen[perms[si]]
                ix = np.clip(idx_rows[:, sl] - start_b, 0, hz.size - 1)
                bad = np.take_along_axis(pen_b, ix[..., None], -1)[..., 0]
                total += np.where(on, np.sum(bad > LABEL_OVERRIDE, axis=1), 0)
            col += k
        return total

    def permuted(rng, B, y):
        """The label-permutation test's draws: the measured frequencies ``y`` ``(m,)`` kept, the labels of each
        table's rows shuffled among them (B permutations); the structure chosen and the rows assigned again with
        the shuffled labels' penalties. **Returns** ``(idx (B, r), swaps, loaded (B,), overridden (B,))``: as
        :func:`choose`, and the shuffled labels each draw's assignment overrode."""
        perms = []
        pens = {name: {} for name in (LOADED, FREE)}
        for s_ in segments:
            k = s_["rows"].size
            perms.append(np.argsort(rng.random((B, k)), axis=1))
        for t, tb in choice.tables.items():
            for name in (LOADED, FREE):
                pens[name][t] = np.broadcast_to(np.asarray(tb["pen"][name], dtype=np.float64),
                                                (B,) + np.shape(tb["pen"][name])).copy()
        for s_, perm in zip(segments, perms):
            tb = choice.tables[s_["table"]]
            pos = {int(j): k for k, j in enumerate(tb["rows"])}
            where = np.array([pos[int(j)] for j in s_["rows"]])
            for name in (LOADED, FREE):
                pens[name][s_["table"]][:, where] = s_[name][3][perm]
        loaded = choice.choose({t: np.broadcast_to(y[tb["rows"]], (B, tb["rows"].size))
                                for t, tb in choice.tables.items()}, pens)
        out = []
        for s_, perm in zip(segments, perms):
            f = np.broadcast_to(y[s_["rows"]], perm.shape)
            res = []
            for name in (LOADED, FREE):
                starts, hz, cost, pen = s_[name]
                res.append(hungarian(f, s_["std"], starts[perm], hz, cost, pen[perm]))
            out.append(np.where(loaded[:, None], res[0], res[1]))
        same = loaded if chosen == LOADED else ~loaded
        lab = np.where(same[:, None], labelled[None, :], swapped[None, :])
        idx = np.concatenate(out, axis=1)
        return idx, [(labelled, lab)], loaded, overrides(idx, loaded, perms)

    return dict(kind="rolling tables", table=segments[0]["table"], rows=all_rows, draw=draw, choose=choose,
                sigma=sigma, chosen=chosen, overrides=overrides, permuted=permuted,
                labelled_rows=int(sum(1 for j in all_rows if _has_label(rows[j]))))


#: A label penalty above this on the assigned line counts as an overridden label (half of ``ringfit campbell``'s
#: LABEL_PENALTY: a contradicted n or branch, or a tag whose symmetry share is over 1/2).
LABEL_OVERRIDE = 2.0


def _has_label(r: dict) -> bool:
    """Whether a row came with any label (n, tag or branch)."""
    return r.get("label_n", r["n"]) >= 0 or bool(r["tag"]) or bool(r["branch"])


def label_counts(tables, rows, records, choice) -> dict:
    """Per rolling table, the labels its assignment kept and overrode (docs/formats.md §5 ``verdict.labels``):
    ``{table name: {"rows", "labelled", "kept", "overridden", "unlabelled"}}``. A label is overridden when the
    row's line contradicts it (its n, branch, or a tag whose symmetry the line does not share: the matching's
    ``label_conflicts``)."""
    out = {}
    for t in sorted(choice.tables):
        js = [j for j, r in enumerate(rows) if r["table"] == t and r.get("rolling_matched")]
        lab = [j for j in js if _has_label(rows[j])]
        over = [j for j in lab if (records or {}).get(j, {}).get("label_conflicts")]
        out[table_label(tables[t], t)] = {"rows": len(js), "labelled": len(lab), "kept": len(lab) - len(over),
                                          "overridden": len(over), "unlabelled": len(js) - len(lab)}
    return out


__all__ = ["LineSets", "missing_n_lines", "match_missing_n", "ambiguity", "mixture_sigma", "line_problem",
           "label_counts", "AMBIGUOUS_Z", "LABEL_OVERRIDE", "LINE_BUCKET", "MATCH_N_MAX"]
