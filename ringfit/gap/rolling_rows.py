"""Rows of ``rolling`` mode tables in the gap diagnosis: the rolling, loaded tyre's modes (docs/physics.md §3.7,
§6 ``ground_contact + rotation on rolling tables``, §6.4 *which model structure*).

A ``rolling`` table (docs/formats.md §2: ``state = rolling``, ``load_n`` > 0, a speed, a ``frame``) was measured on
a tyre that spins and touches the ground. Its rows are assigned once per case, outside the refits: under the
model structure their frequencies choose (:class:`StructureChoice`: the rolling, loaded model of §3.7 or the free
spinning ring, by a mixture likelihood that does not reward more lines), then each structural row to a branch or
a sensor line by ``ringfit campbell``'s matching (:func:`assign_rolling_rows`), the match stated per row. Inside
the predictor only frequencies are recomputed: :class:`RollingJoint` gives the joint model (patch scale and speed
gain both away from their nulls, one eigen-solve per table) and each effect alone its own rows; the assignment
(mode index, line) stays fixed, a stated limitation when a fitted value far from 1 reorders modes.

Example (``ringfit example rolling --out ex``: a free table and three rolling tables at 20/40/60 km/h)::

    from ringfit.gap import diagnose
    d = diagnose("ex/rolling", null_draws=0)
    d.verdict["effects"]                                  # ['ground_contact', 'rotation']
    next(r["rolling_match"] for r in d.content["rows"] if r.get("rolling_match"))
    # {'structure': 'rolling_loaded', 'model_branch': 2, 'model_n': 1, 'model_direction': 'backward',
    #  'model_tag': 'hort', 'model_k': 1, 'frame': 'rotating', 'model_hz': 110.67, 'z': 0.0034, 'status': 'matched', …}
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy.special import logsumexp

from ringfit._cache import jit

#: Harmonics |k| ≤ K of the Hill basis for the diagnosis's rolling rows (n ≤ 12 branches are
#: kept). K = 24 keeps the 16 lowest modes of the Table 9 tyre (to 290 Hz; 4 kN, 60 km/h) within
#: 3e-4 relative of K = 64, below the identification noise of rolling tables (tests/test_gap_rolling.py),
#: at half the cost of the Campbell default K = 32 (6e-5).
ROLLING_HARMONICS = 24
#: Highest dominant order matched on rolling tables (≤ K/2).
ROLLING_N_MAX = 12
#: The effects the rolling model of docs/physics.md §3.7 combines on rolling rows.
JOINT = ("ground_contact", "rotation")


def is_rolling(table) -> bool:
    """Whether a mode table is a ``rolling`` table the joint model predicts (state rolling, load and speed > 0)."""
    c = table.condition
    return (table.state == "rolling" and float(c.get("load_n") or 0) > 0
            and (float(c.get("speed_kmh") or 0) > 0 or float(c.get("rotation_hz") or 0) > 0))


@dataclass
class RollingConditions:
    """Per table ``(T,)``: Ω [rad/s], patch edges [rad] of the steady rolling solution (0 for other tables),
    and the diagnosis's notes per rolling table (``table index → sentence``)."""

    omega: np.ndarray
    leading: np.ndarray
    trailing: np.ndarray
    notes: dict


def assign_rolling_rows(tables, rows, ring, geometry, patches):
    """Match the structural rows of the rolling tables to the model's lines; fills the row dicts.

    **The model structure is chosen once per case, by the data** (:class:`StructureChoice`,
    docs/physics.md §6.4): the rows are matched under both structures at their computed
    conditions — the rolling, loaded model (:data:`LOADED`: the steady patch of the sidecar's load,
    Ω = V/R_e) and the free spinning ring (:data:`FREE`: eq. 25/26 at the same Ω, no contact) — and the
    structure whose lines explain the rows better (the line-density-fair mixture likelihood of
    :func:`structure_loglik`) gives the one assignment the baseline and every candidate share.
    Under :data:`FREE` the rows carry the ring's n and wave and no mode of the rolling model
    (``joint`` = 0): the composite ``ground_contact+rotation`` has no line to follow, and contact
    has nothing to predict on these rows.

    **Arguments:** ``tables`` — the case's tables (free first); ``rows`` — the row dicts of
    :mod:`ringfit.gap.modal` (keys ``table``, ``i``, ``n``, ``tag``, ``branch``, ``contact``,
    ``freq``, ``fixed``, …; modified in place: ``n`` where missing, ``spin``, ``joint``,
    ``mode_index``, ``line_k``, ``wave``, ``contact``, ``patch``, ``line_hz``, ``structure_fields``);
    ``ring``, ``geometry`` — the ring fitted to ``free.modes.csv`` (``k_tread`` of the diagnosis);
    ``patches`` — ``(a, σ_a)`` of each table's static contact solve.

    **Returns:** ``(conditions, notes, records, choice)``: :class:`RollingConditions` (``None``
    without rolling tables), ``{row position: match sentence}``, ``{row position:
    structured match}`` (n, direction, tag, line k, frame, model frequency, z, status; of the chosen
    structure) and the :class:`StructureChoice` (``None`` without rolling tables): both structures'
    lines per table, for the random-line null of :mod:`ringfit.gap.calibration` (which repeats the
    choice per draw) and the ambiguity of a match.
    """
    from ringfit.gap.campbell import MODEL_TOLERANCE, assign_rows, diagram_candidates, diagram_group_key, row_labels, match_tables

    T = len(tables)
    sel = [ti for ti, t in enumerate(tables) if is_rolling(t)]
    if not sel:
        return None, {}, {}, None
    omega, lead, trail = np.zeros(T), np.zeros(T), np.zeros(T)
    table_notes, notes, records = {}, {}, {}
    lines = {LOADED: {}, FREE: {}}
    per_row: dict = {}  # row position → {structure: (fields or None, record or None, note)}
    choice_tables: dict = {}
    by_drum: dict = {}
    for ti in sel:
        by_drum.setdefault(tables[ti].condition.get("drum_diameter_m"), []).append(ti)
    position = {(r["table"], r["i"]): j for j, r in enumerate(rows)}
    for drum, idx in by_drum.items():
        # the assignment only: the diagnosis weighs the rows with its own noise model (docs/formats.md §5)
        match = match_tables([tables[ti] for ti in idx], ring, geometry, drum_diameter_m=drum,
                             model_tolerance=MODEL_TOLERANCE, n_max=ROLLING_N_MAX, harmonics=ROLLING_HARMONICS)
        offset = 0
        for ti, cond in zip(idx, match.conditions):
            t = tables[ti]
            d = match.diagrams[diagram_group_key(cond.contact, cond.load_n, drum)]
            s = int(np.argmin(np.abs(d.speed_kmh - round(cond.speed_kmh, 9))))
            omega[ti] = cond.omega
            lead[ti], trail[ti] = math.radians(d.leading_deg[s]), math.radians(d.trailing_deg[s])
            patch = patches[ti][0]
            cands = diagram_candidates(d, s, cond.frame)
            free_cands = _free_ring_candidates(ring, geometry, cond.omega, cond.frame == "fixed")
            lines[LOADED][ti] = [dict(hz=c.hz, cost=-2.0 * math.log(max(c.weight, 1e-12)), weight=c.weight,
                                      sigma=MODEL_TOLERANCE * c.hz,
                                      fields=line_fields(c.n, c.direction, c.tag, int(d.mode_index[s, c.branch]),
                                                         float(c.k or 0), patch))
                                 for c in cands]
            lines[FREE][ti] = [dict(hz=c.hz, cost=0.0, weight=1.0, sigma=MODEL_TOLERANCE * c.hz,
                                    fields=free_line_fields(c.n, c.direction))
                               for c in free_cands]
            table_notes[ti] = (f"rolling model (docs/physics.md §3.7): Ω = {cond.omega:.4g} rad/s from "
                               f"{cond.source_speed}, contact arc {d.leading_deg[s]:.2f}…{d.trailing_deg[s]:.2f} deg "
                               f"of the steady rolling solution at {cond.load_n:g} N, {cond.frame} frame, "
                               f"K = {ROLLING_HARMONICS} harmonics")
            labs = [row_labels(t, i) for i in range(len(t))]
            free_assign = assign_rows(t, labs, free_cands, MODEL_TOLERANCE)
            js, structural = [], []
            for i in range(len(t)):
                rec = match.rows[offset + i]
                j = position.get((ti, i))
                if j is None:  # acoustic rows are not part of the frequency problem
                    continue
                js.append(j)
                structural.append(i)
                rows[j]["spin"] = float(cond.omega)
                per_row[j] = {LOADED: _loaded_option(rows[j], rec, patch), FREE: _free_option(free_assign[i])}
            if js:
                std = np.nan_to_num(np.asarray(t.freq_std_hz, dtype=np.float64)[structural])
                freq = np.asarray(t.freq_hz, dtype=np.float64)[structural]
                choice_tables[ti] = dict(
                    rows=np.asarray(js), freq=freq, std=std, lo=float(freq.min()), hi=float(freq.max()),
                    pen={LOADED: _penalties([labs[i] for i in structural], cands),
                         FREE: _penalties([labs[i] for i in structural], free_cands)},
                    hz={LOADED: np.array([c.hz for c in cands]), FREE: np.array([c.hz for c in free_cands])},
                    weight={LOADED: np.array([c.weight for c in cands]), FREE: np.ones(len(free_cands))})
            offset += len(t)
    choice = StructureChoice(lines=lines, tables=choice_tables)
    chosen = choice.chosen
    for j, options in per_row.items():
        r = rows[j]
        before = {k: r.get(k) for k in ROW_FIELDS}
        fields = {}
        for name, (f, _, _) in options.items():  # each structure's full row fields (the null swaps them per draw)
            if f is not None and name == FREE and before["n"] >= 1:
                f["n"] = before["n"]  # a given n stays the row's n (as under the loaded model)
            fields[name] = {**before, **(f or {})}
        r["structure_fields"] = fields
        f, rec, note = options[chosen]
        if f is None:  # no line of the chosen structure: the row keeps the single-effect predictions
            notes[j] = note
            continue
        r.update(f)
        r["rolling_matched"] = True
        notes[j] = note
        if rec is not None:
            records[j] = rec
    for ti in table_notes:
        table_notes[ti] += "; " + choice.sentence()
    _single_effect_labels(rows, ring, geometry, patches, notes, sel)
    return RollingConditions(omega, lead, trail, table_notes), notes, records, choice


#: The two model structures the rows of rolling tables can be assigned to (:class:`StructureChoice`).
LOADED = "rolling_loaded"
FREE = "free_spinning"
#: Row fields an assignment sets (the null swaps them per draw with the structure chosen).
ROW_FIELDS = ("n", "wave", "contact", "patch", "joint", "mode_index", "line_k", "line_hz")
#: Share of the background component in a row's mixture likelihood: a row no line explains (a spurious
#: pole, a mode of something else) costs the same under both structures instead of deciding the choice.
BACKGROUND = 0.05
#: Relative model σ over which each structure's mixture likelihood is maximised (the same grid for both:
#: from the smallest σ the matching takes from data to its default, ringfit.gap.campbell's MIN_TOLERANCE
#: and MODEL_TOLERANCE).
TOLERANCE_GRID = tuple(np.geomspace(0.002, 0.02, 9).tolist())


def _loaded_option(r: dict, rec: dict, patch: float):
    """A row's fields, structured match and note under the rolling, loaded model (``ringfit campbell``'s match)."""
    a = rec["_assignment"]
    if a["mode_index"] < 0:
        return None, None, "rolling model: no branch to match (the row keeps the single-effect predictions)"
    trial = dict(r, joint=1.0, mode_index=int(a["mode_index"]), line_k=float(a["k"]), line_hz=float(rec["model_hz"]))
    shared = _shared_assignment(trial, rec, patch)
    record = {"structure": LOADED, "model_branch": rec["model_branch"], "model_n": rec["model_n"],
              "model_direction": rec["model_direction"], "model_tag": rec["model_tag"],
              "model_k": rec["model_k"], "frame": rec["frame"], "model_hz": _num(rec["model_hz"]),
              "z": _num(rec["z"]), "status": rec["status"], "label_conflicts": rec.get("label_conflicts", "")}
    note = f"rolling model: {rec['note']}".rstrip(".")
    if shared:
        note += "; " + shared
    return {k: trial[k] for k in ROW_FIELDS}, record, note


def _free_option(a):
    """A row's fields, structured match and note under the free spinning ring (eq. 25/26 at the table's Ω)."""
    if a is None:
        return None, None, "free spinning ring: no wave to match (the row keeps the single-effect predictions)"
    c, z, sig, bad = a
    f = free_line_fields(c.n, c.direction)
    record = {"structure": FREE, "model_branch": None, "model_n": c.n, "model_direction": c.direction,
              "model_tag": "", "model_k": c.k, "frame": "fixed" if c.k is None else "rotating",
              "model_hz": _num(c.hz), "z": _num(z), "status": "matched" if abs(z) <= 3 and not bad else
              ("label_conflict" if abs(z) <= 3 else "unexplained"), "label_conflicts": ",".join(bad)}
    note = (f"free spinning ring: the {c.direction} wave n={c.n} at {c.hz:.1f} Hz (z = {z:+.1f}); n and wave from "
            "the matched wave (one assignment, shared by the baseline and every candidate)")
    return {**f, "line_hz": float(c.hz)}, record, note


def free_line_fields(n: int, direction: str) -> dict:
    """The row fields a row assigned to a wave of the free spinning ring takes: its n and wave, no contact type,
    no mode of the rolling model (``joint`` = 0)."""
    return dict(n=int(n), wave=direction, contact=0, patch=0.0, joint=0.0, mode_index=0, line_k=0.0)


@functools.cache
def _free_ring_program(fixed: bool):
    """eq. 26 (fixed observer) or eq. 25 (co-rotating sensor), jitted once per process."""
    from ringfit.physics.natural import fixed_frame_frequencies, rotating_natural_frequencies

    return jit(fixed_frame_frequencies if fixed else rotating_natural_frequencies)


def _free_ring_candidates(ring, geometry, omega: float, fixed: bool):
    """The waves n = 1 … :data:`ROLLING_N_MAX` of the free spinning ring at Ω (eq. 25 co-rotating, eq. 26 fixed)
    as matching candidates (weight 1; a travelling wave: no symmetry about a patch)."""
    from ringfit.gap.campbell import Candidate

    n_all = np.arange(1, ROLLING_N_MAX + 1, dtype=float)
    w = np.abs(np.asarray(_free_ring_program(fixed)(ring, geometry, n_all, omega)))  # [Hz], (n, 2): backward, forward
    out = []
    for k, n in enumerate(n_all.astype(int)):
        for b, direction in enumerate(("backward", "forward")):
            line_k = None if fixed else (int(n) if direction == "backward" else -int(n))
            out.append(Candidate(-1, line_k, float(w[k, b]), int(n), direction, math.nan, "", 1.0))
    return out


def _penalties(labs, cands) -> np.ndarray:
    """``(r, L)`` label penalties of ``ringfit campbell``'s matching cost (n, branch, tag) of each row on each line."""
    from ringfit.gap.campbell import label_penalties

    return np.array([[label_penalties(lab, c)[0] for c in cands] for lab in labs]).reshape(len(labs), len(cands))


def structure_loglik(f, std, hz, weight, pen, lo: float, hi: float) -> np.ndarray:
    """Log-likelihood ``(B, G)`` of one table's row frequencies ``f`` ``(B, r)`` under one model structure, per
    relative model σ τ of :data:`TOLERANCE_GRID` (docs/physics.md §6.4).

    Each row is drawn from one of the structure's lines within the table's span (widened by 2 τ_max),
    chosen with probability ∝ its line weight, and scattered about it with σ = √(std² + (τ f̂)²); a contradicted
    label costs ``exp(−penalty/2)`` (the matching's penalty); with probability :data:`BACKGROUND` the row is
    uniform over the span. The line prior is normalised over the lines within the span, so a structure with
    more lines spreads the same probability thinner: uniform random frequencies get about the same likelihood
    under a dense and a sparse structure, and line density alone does not win."""
    f = np.atleast_2d(np.asarray(f, dtype=np.float64))
    tau_max = max(TOLERANCE_GRID)
    keep = (hz >= lo * (1 - 2 * tau_max)) & (hz <= hi * (1 + 2 * tau_max))
    span = max(hi - lo, 1e-9) * (1 + 4 * tau_max)
    background = np.log(BACKGROUND / span)
    if not np.any(keep):
        return np.full((f.shape[0], len(TOLERANCE_GRID)), f.shape[1] * background)
    hz, w, pen = hz[keep], weight[keep], np.asarray(pen, dtype=np.float64)[..., keep]  # (r, L) or (B, r, L)
    log_prior = np.log(w / np.sum(w))  # (L,)
    out = []
    for tau in TOLERANCE_GRID:
        sig = np.sqrt(std[:, None] ** 2 + (tau * hz[None, :]) ** 2)  # (r, L)
        z = (f[..., None] - hz) / sig  # (B, r, L)
        comp = log_prior - 0.5 * z * z - np.log(sig) - 0.5 * math.log(2 * math.pi) - 0.5 * pen
        lines = logsumexp(comp, axis=-1)  # (B, r)
        row = np.logaddexp(math.log(1 - BACKGROUND) + lines, background)
        out.append(np.sum(row, axis=-1))
    return np.stack(out, axis=-1)


@dataclass
class StructureChoice:
    """The model structure the rolling tables' rows are assigned to, chosen once per case by the data.

    ``lines``: ``{structure: {table: [line dicts]}}`` (``hz``, ``cost``, ``weight``, ``sigma``, ``fields``);
    ``tables``: ``{table: dict(rows, freq, std, lo, hi, pen, hz, weight)}`` — what :meth:`costs` needs to score
    new frequencies (the random-line null repeats the choice for every draw)."""

    lines: dict
    tables: dict

    def costs(self, freqs: dict | None = None, pens: dict | None = None) -> dict:
        """``{structure: (B,) cost}``, cost = −2 × the log-likelihood of :func:`structure_loglik` summed over the
        rolling tables and maximised over τ (one τ per structure and case); ``freqs`` ``{table: (B, r)}`` (default:
        the measured rows, B = 1); ``pens`` ``{structure: {table: (B, r, L)}}`` label penalties per draw (the
        label-permutation test's shuffled labels; default: the table's own)."""
        out, tau = {}, {}
        for name in (LOADED, FREE):
            total = 0.0
            for ti, tb in self.tables.items():
                f = tb["freq"][None, :] if freqs is None else freqs[ti]
                pen = tb["pen"][name] if pens is None else pens[name][ti]
                total = total + structure_loglik(f, tb["std"], tb["hz"][name], tb["weight"][name], pen,
                                                 tb["lo"], tb["hi"])
            total = np.atleast_2d(total)
            out[name] = -2.0 * np.max(total, axis=-1)
            tau[name] = np.asarray(TOLERANCE_GRID)[np.argmax(total, axis=-1)]
        self._tau = tau
        return out

    def choose(self, freqs: dict | None = None, pens: dict | None = None) -> np.ndarray:
        """``(B,)`` True where the rolling, loaded model is chosen (its cost not above the free ring's)."""
        c = self.costs(freqs, pens)
        return c[LOADED] <= c[FREE]

    @property
    def chosen(self) -> str:
        """The structure the measured rows choose."""
        return LOADED if bool(self.choose()[0]) else FREE

    def record(self) -> dict:
        """The choice for the diagnosis JSON (``baseline.rolling_structure``, docs/formats.md §5)."""
        c = self.costs()
        tau = self._tau
        return {"chosen": self.chosen,
                "cost": {k: round(float(v[0]), 3) for k, v in c.items()},
                "tolerance_pct": {k: round(100 * float(v[0]), 3) for k, v in tau.items()},
                "lines_in_span": {k: int(sum(np.sum((tb["hz"][k] >= tb["lo"] * 0.96) & (tb["hz"][k] <= tb["hi"] * 1.04))
                                             for tb in self.tables.values())) for k in (LOADED, FREE)},
                "rows": int(sum(tb["rows"].size for tb in self.tables.values())),
                "rule": "the structure with the lower cost −2 ln L: each row a mixture over the structure's lines "
                        "within its table's span (prior ∝ line weight, normalised over those lines), σ maximised on "
                        f"a common grid, a {100 * BACKGROUND:g} % uniform background; repeated for every draw of "
                        "the random-line null"}

    def sentence(self) -> str:
        """One sentence for the report: the chosen structure and both costs."""
        c = self.costs()
        name = {LOADED: "the rolling, loaded model", FREE: "the free spinning ring (no contact)"}
        other = FREE if self.chosen == LOADED else LOADED
        return (f"rows assigned to {name[self.chosen]}: its lines explain them better (cost −2 ln L "
                f"{float(c[self.chosen][0]):.1f} against {float(c[other][0]):.1f} for {name[other]}, "
                "docs/physics.md §6.4)")


def line_fields(n: int, direction: str, tag: str, mode_index: int, line_k: float, patch: float) -> dict:
    """The row fields a row assigned to one line of the rolling model takes (the shared assignment).

    One assignment serves the baseline and every candidate: the line's harmonic |k| of a sensor line
    ω + kΩ (k ≠ 0), else the mode's dominant order ``n`` (eq. 18 of that n is the baseline), its travelling direction as the wave of eq. 25/26
    (``rotation`` alone; none for a standing mode), its loaded-mode type from its symmetry about
    the patch (``ground_contact`` alone: ``extr``/``vert`` the cos type, ``0``/``hort`` the sin
    type; none for a travelling mode), and its mode and sensor line (the joint model).
    """
    contact = 1 if tag in ("extr", "vert") else 2 if tag in ("0", "hort") else 0
    # a sensor line ω + kΩ (k ≠ 0) is what the co-rotating sensor sees of winding |k|: without contact a mode of
    # order n shows only its lines k = ±n, so the baseline and the single effects take n = |k| there
    n = abs(int(line_k)) if line_k else int(n)
    return dict(n=int(n), wave=direction if direction in ("backward", "forward") else "", contact=contact,
                patch=patch if contact else 0.0, joint=1.0, mode_index=int(mode_index), line_k=float(line_k))


def _shared_assignment(r: dict, rec: dict, patch: float) -> str:
    """Fill the labels a row lacks (n, wave, loaded-mode type) from the line it was matched to
    (:func:`line_fields`), so that the baseline and every candidate see the same assignment
    (never each model its own nearest line). **Returns** the sentence that says so ('' if nothing was missing)."""
    if rec.get("model_n") is None:
        return ""
    f = line_fields(int(rec["model_n"]), rec.get("model_direction", ""), rec.get("model_tag", ""), r["mode_index"],
                    r["line_k"], patch)
    said = []
    if r["n"] < 1:
        r["n"] = f["n"]
        said.append(f"n matched to {f['n']}")
    if not r["branch"] and not r["wave"] and f["wave"]:
        r["wave"] = f["wave"]
        said.append(f"{f['wave']} wave")
    if r["contact"] == 0 and f["contact"] and patch > 0:
        r["contact"], r["patch"] = f["contact"], patch
        said.append("cos-type (extr)" if f["contact"] == 1 else "sin-type (0)")
    return (", ".join(said) + " from the matched line (one assignment, shared by the baseline and every candidate)"
            if said else "")


def _num(x):
    x = float(x)
    return round(x, 4) if math.isfinite(x) else None


def _single_effect_labels(rows, ring, geometry, patches, notes, sel):
    """Rows of rolling tables the rolling model could not match (no line): the nearer wave of eq. 25/26
    (for ``rotation`` alone) and the nearer cos/sin-type loaded mode (for ``ground_contact`` alone), stated.
    Matched rows take their labels from their line (:func:`_shared_assignment`)."""
    from ringfit.physics.loaded import loaded_natural_frequencies
    from ringfit.physics.natural import fixed_frame_frequencies, rotating_natural_frequencies

    loaded = {}
    n_all = np.arange(1, ROLLING_N_MAX + 1, dtype=float)
    for j, r in enumerate(rows):
        if r["table"] not in sel or r.get("rolling_matched"):
            continue  # a row matched to a line of the rolling model takes that line's labels (shared assignment)
        said = []
        if r["n"] < 1 and r["spin"] > 0:
            # no n in the table: the nearest wave of eq. 25/26 over n = 1 … ROLLING_N_MAX gives the n of
            # the baseline and the single-effect predictions (the joint model keeps its own match)
            fn = fixed_frame_frequencies if r["fixed"] else rotating_natural_frequencies
            w = np.abs(np.asarray(fn(ring, geometry, n_all, r["spin"])))  # [Hz], (n, 2)
            k, b = np.unravel_index(int(np.argmin(np.abs(w - r["freq"]))), w.shape)
            r["n"], r["wave"] = int(k) + 1, ("backward", "forward")[b]
            said.append(f"n matched to {r['n']} by eq. {'26' if r['fixed'] else '25'} ({r['wave']} wave at "
                        f"{w[k, b]:.1f} Hz)")
        if r["n"] < 1:
            continue
        if not r["branch"] and not r["wave"] and r["spin"] > 0:
            fn = fixed_frame_frequencies if r["fixed"] else rotating_natural_frequencies
            w = np.abs(np.asarray(fn(ring, geometry, float(r["n"]), r["spin"])))  # [Hz]
            b = int(np.argmin(np.abs(w - r["freq"])))
            r["wave"] = ("backward", "forward")[b]
            said.append(f"rotation alone: the {r['wave']} wave of eq. {'26' if r['fixed'] else '25'} "
                        f"({w[b]:.1f} Hz)")
        a = patches[r["table"]][0]
        if r["contact"] == 0 and a > 0:
            if r["table"] not in loaded:
                loaded[r["table"]] = [np.asarray(x) for x in loaded_natural_frequencies(ring, geometry, a)]
            cos_t, sin_t = loaded[r["table"]]
            if r["n"] <= cos_t.size:
                fc, fs = float(cos_t[r["n"] - 1]), float(sin_t[r["n"] - 1])
                r["contact"] = 1 if abs(fc - r["freq"]) <= abs(fs - r["freq"]) else 2
                r["patch"] = a
                kind = "cos-type (extr)" if r["contact"] == 1 else "sin-type (0)"
                said.append(f"ground_contact alone: the {kind} loaded mode ({fc if r['contact'] == 1 else fs:.1f} Hz)")
        if said:
            notes[j] = "; ".join(([notes[j]] if j in notes else []) + said)


class RollingJoint(eqx.Module):
    """The joint prediction of ``ground_contact`` and ``rotation`` on rolling rows (module docstring).

    Static: ``tables`` (indices of the rolling tables), ``contact_at`` / ``rotation_at``
    (positions of ``patch_scale`` and ``speed_gain`` in theta), ``harmonics``.
    """

    tables: tuple = eqx.field(static=True)
    contact_at: int = eqx.field(static=True)
    rotation_at: int = eqx.field(static=True)
    harmonics: int = eqx.field(static=True, default=ROLLING_HARMONICS)

    def active(self, theta, rows):
        """``(m,)`` bool: rolling rows with an assignment while both effects are away from their nulls."""
        both = (theta[self.contact_at] > 0) & (theta[self.rotation_at] > 0)
        return both & (rows.joint > 0)

    def angular_frequencies(self, theta, ring, geometry, rows):
        """ω [rad/s] each assigned row's observer sees in the joint model (0 on the other rows), ``(m,)``."""
        from ringfit.physics.rolling_modes import ContactArc, observed_frequencies, rolling_modes

        s, g = theta[self.contact_at], theta[self.rotation_at]

        tables = jnp.asarray(self.tables, dtype=jnp.int32)

        def one(t):  # every row seen at table t's condition, (m,)
            arc = ContactArc(s * rows.table_leading[t], s * rows.table_trailing[t], ring.k_tread,
                             jnp.zeros((), dtype=jnp.float64))
            modes = rolling_modes(ring, geometry, g * rows.table_omega[t], arc, harmonics=self.harmonics)
            N = modes.angular_frequency.shape[0]
            f = observed_frequencies(modes, jnp.clip(rows.mode_index, 0, N - 1), rows.line_k, rows.fixed_frame > 0)
            return 2.0 * jnp.pi * f

        def compute(_):
            # a sequential loop over the rolling tables (lax.map: one eigen-solve compiled once, run per
            # table; batched eigen-solves under forward-mode differentiation are avoided on purpose)
            every = jax.lax.map(one, tables)  # (R, m)
            return jnp.sum(jnp.where(rows.table[None, :] == tables[:, None], every, 0.0), axis=0)

        # the eigen-solves run only when both effects are on (every other candidate skips them)
        return jax.lax.cond((s > 0) & (g > 0), compute, lambda _: jnp.zeros_like(rows.freq_hz), None)


def joint_for(effects, sizes, i0, tables) -> RollingJoint | None:
    """The :class:`RollingJoint` of a predictor whose effects include both of :data:`JOINT`, else ``None``."""
    if not tables:
        return None
    pos, i = {}, i0
    for e, k in zip(effects, sizes):
        pos[e.name] = i
        i += k
    if not all(name in pos for name in JOINT):
        return None
    return RollingJoint(tables=tuple(tables), contact_at=pos["ground_contact"], rotation_at=pos["rotation"])


__all__ = ["ROLLING_HARMONICS", "JOINT", "is_rolling", "assign_rolling_rows", "RollingConditions", "RollingJoint",
           "joint_for", "StructureChoice", "structure_loglik", "LOADED", "FREE"]
