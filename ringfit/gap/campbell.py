"""Measured mode tables matched to the branches of the Campbell diagram (docs/physics.md §3.7, *measured rows
matched to the diagram*).

The diagram itself (the model's modes against speed, tracked into branches) is a model view in
:mod:`ringfit.physics.campbell`, re-exported here. This module brings the measurements to it:
:func:`match_tables` matches every row of measured mode tables to a branch (fixed frame) or a line of a branch
(co-rotating frame) at the table's speed (z against the model's tolerance, label penalties, one-to-one per
table), names the rows no branch explains and, across speeds, the trends and labels that contradict every branch;
:func:`label_identified_modes` labels the modes ``ringfit cleat --ssi`` identifies; :func:`compare_with_ring`
puts the free spinning ring's eq. 25/26 beside a table.

Example (``ringfit example rolling --out ex``: three rolling tables at 20/40/60 km/h)::

    from ringfit.io.modes import read_mode_table
    from ringfit.io.tyre import read_tyre
    tyre = read_tyre("ex/rolling/tyre.toml")
    tables = [read_mode_table(f"ex/rolling/roll{v}.modes.csv") for v in (20, 40, 60)]
    match = match_tables(tables, tyre.ring, tyre.geometry)
    match.summary()        # '27 rows: 27 matched' (else: label or trend conflicts, unexplained rows)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ringfit.errors import InputError
from ringfit.io.files import sidecar_of
from ringfit.io.modes import ModeTable, check_test_condition
from ringfit.physics.campbell import (  # the diagram: a model view (also importable from here, as before)
    CAMPBELL_COLUMNS, DEFAULT_N_MAX, FRAMES, SPEED_BUCKET, TRAVELLING_RATIO, CampbellDiagram,  # noqa: F401
    campbell_diagram, frame_name, track_branches)
from ringfit.physics.operating import KMH, road_from_drum_diameter

#: Relative σ of the model's frequencies in the first matching pass, and where the rows cannot give one.
MODEL_TOLERANCE = 0.02
#: Smallest relative σ of the model taken from the rows (rows copied from the model itself must not
#: make a 0.3 % deviation "unexplained").
MIN_TOLERANCE = 0.002
#: Rows needed to estimate the model's σ from the data (fewer: :data:`MODEL_TOLERANCE`).
MIN_ROWS_FOR_TOLERANCE = 4
#: Consistency factor of the median absolute deviation for a normal distribution.
MAD_TO_SIGMA = 1.4826
#: |z| up to which a row counts as explained.
EXPLAINED_Z = 3.0
#: Cost of each contradicted label, in units of z² (a label is worth 2σ of frequency).
LABEL_PENALTY = 4.0
#: Sensor lines weaker than this share of their mode's strongest line are not candidates.
MIN_LINE_WEIGHT = 0.05


# ----------------------------------------------------------------------------------------------- conditions
@dataclass
class TableCondition:
    """A table's operating condition as the matching uses it.

    ``speed_kmh`` (km/h, for the diagram), ``omega`` Ω [rad/s], ``load_n``, ``contact``
    (loaded/rolling), ``frame`` (``rotating``/``fixed``), ``frame_given`` (from the sidecar),
    ``source_speed`` (what Ω came from).
    """

    speed_kmh: float
    omega: float
    load_n: float
    contact: bool
    frame: str
    frame_given: bool
    source_speed: str


def diagram_group_key(contact: bool, load_n: float, drum: float | None):
    """The key under which tables share one Campbell diagram: contact, the load when in contact, the drum."""
    return (bool(contact), round(float(load_n), 6) if contact else 0.0, drum)


def table_conditions(tables, ring, geometry, *, load_n: float | None = None, drum_diameter_m: float | None = None):
    """Resolve each table's speed, load, contact and frame (docs/formats.md §2).

    Ω is ``2π·rotation_hz`` when the sidecar gives it, else ``V/R_e`` with
    ``R_e = R_out − δ/3`` (δ of the standing tyre at the table's load; R_out for a free
    tyre). ``load_n`` (the sidecar's, else the argument) is required for ``loaded``
    and ``rolling`` tables. ``loaded`` tables stand (Ω = 0). ``frame`` defaults to
    ``rotating`` for a spinning tyre and ``fixed`` for a standing one (as the diagnosis does).

    **Returns:** list of :class:`TableCondition`; raises :class:`InputError` naming the table.
    """
    out = []
    radii = {}
    for t in tables:
        c = t.condition
        src = t.source or "<table>"
        check_test_condition(c, source=sidecar_of(t.source) if t.source else src)
        state = t.state
        contact = state in ("loaded", "rolling")
        load = c.get("load_n") if c.get("load_n") else load_n
        if contact and not (load and load > 0):
            raise InputError(f"{state} table without 'load_n' in its sidecar; give the load (--load)", source=src)
        load = float(load) if contact else 0.0
        key = diagram_group_key(contact, load, drum_diameter_m)
        if key not in radii:
            radii[key] = _rolling_radius(ring, geometry, load, drum_diameter_m, contact)
        r_e = radii[key]
        rot, speed = c.get("rotation_hz"), c.get("speed_kmh")
        if state == "loaded":
            omega, v, how = 0.0, 0.0, "loaded: standing"
        elif rot:
            omega = 2 * math.pi * float(rot)
            v, how = omega * r_e / KMH, "rotation_hz"
        elif speed:
            v = float(speed)
            omega, how = v * KMH / r_e, f"speed_kmh / R_e (R_e = {r_e:.4f} m)"
        else:
            if state == "rolling":
                raise InputError("rolling table without 'speed_kmh' or 'rotation_hz' in its sidecar", source=src)
            omega, v, how = 0.0, 0.0, "standing"
        frame = c.get("frame")
        given = frame is not None
        if frame is None:
            frame = "rotating" if omega > 0 else "fixed"
        out.append(TableCondition(speed_kmh=v, omega=omega, load_n=load, contact=contact, frame=frame,
                                  frame_given=given, source_speed=how))
    return out


def _rolling_radius(ring, geometry, load, drum, contact) -> float:
    if not contact:
        return float(geometry.outer_radius)
    from ringfit.physics.contact import solve_rolling_jit
    from ringfit.physics.operating import OperatingPoint, rolling_radius

    sol = solve_rolling_jit(ring, geometry, OperatingPoint(0.0, float(load), road_from_drum_diameter(drum)))
    if not bool(sol.ok):
        raise InputError(f"the standing contact solve at {load:g} N did not converge (patch outside its window)")
    return float(rolling_radius(float(geometry.outer_radius), float(sol.deflection)))


# ----------------------------------------------------------------------------------------------- candidates
@dataclass
class Candidate:
    """One model line a measured row can be matched to: a branch of the diagram at one speed, in the fixed
    frame or as one sensor line ω + kΩ (docs/physics.md §3.7), with its order, direction and line weight."""

    branch: int  # 0-based
    k: int | None  # sensor line harmonic (None: fixed frame)
    hz: float
    n: int
    direction: str  # backward / forward / standing
    symmetry: float
    tag: str
    weight: float  # line weight relative to the mode's strongest line (1 in the fixed frame)

    def describe(self, frame: str) -> str:
        """One line for reports: the branch, its order and direction, the line and its frequency."""
        qual = self.direction if self.direction != "standing" else (f"standing, {self.tag}" if self.tag else "standing")
        if frame == "fixed" or self.k is None:
            return f"branch {self.branch + 1} (n={self.n} {qual}) at {self.hz:.1f} Hz"
        return (f"the ω{self.k:+d}Ω line of branch {self.branch + 1} (n={self.n} {qual}) at {self.hz:.1f} Hz")


def diagram_candidates(d: CampbellDiagram, s: int, frame: str) -> list[Candidate]:
    """Every :class:`Candidate` of diagram ``d`` at its speed index ``s`` in ``frame`` (``fixed``/``rotating``)."""
    out = []
    direction, tag = d.direction(), d.tag()
    for b in range(d.branches):
        if frame == "fixed":
            out.append(Candidate(b, None, float(d.fixed_hz[s, b]), int(d.order[s, b]), direction[s, b],
                                  float(d.symmetry[s, b]), tag[s, b], 1.0))
            continue
        w = d.line_weight[s, b]
        if not np.any(np.isfinite(w)):
            continue
        top = np.nanmax(w)
        for j in np.flatnonzero(np.nan_to_num(w) >= MIN_LINE_WEIGHT * top):
            k = int(d.k[j])
            line = float(d.line_hz[s, b, j])  # signed (ω + kΩ)/2π
            sense = "standing" if k == 0 else ("backward" if k * line > 0 else "forward")  # k(ω + kΩ) > 0: backward
            # every line of the branch is a candidate and carries the branch's labels: its n is the mode's
            # dominant order (the line ω + 2Ω of an n = 1 mode is still that n = 1 mode); a row labelled with
            # the line's own harmonic |k| (what a shape seen by the co-rotating sensor gives) agrees too
            out.append(Candidate(b, k, abs(line), int(d.order[s, b]), sense, float(d.symmetry[s, b]), tag[s, b],
                                  float(w[j] / top)))
    return out


def _sigma(f_pred: float, std: float, tol: float) -> float:
    sd = std if math.isfinite(std) else 0.0
    return math.sqrt(sd**2 + (tol * f_pred) ** 2)


def matching_cost(f, std, hz, line_cost, pen, tol: float = MODEL_TOLERANCE) -> np.ndarray:
    """The matching's cost of rows at ``f`` (σ ``std``, NaN as 0) on lines at ``hz`` (broadcast: e.g. ``f``
    ``(B, r, 1)``, ``std`` ``(r, 1)``, ``hz`` ``(L,)``): z² with σ = √(std² + (τ f̂)²), plus each line's weight cost
    −2 ln w (``line_cost``) and the row's label penalties on it (``pen``) — :func:`_score` for many rows, lines
    and draws at once (the diagnosis's random-line null re-assigns with it, ``ringfit.gap.modal``)."""
    sd = np.nan_to_num(np.asarray(std, dtype=np.float64))
    hz = np.asarray(hz, dtype=np.float64)
    z = (np.asarray(f, dtype=np.float64) - hz) / np.sqrt(sd**2 + (tol * hz) ** 2)
    return z * z + line_cost + pen


def row_labels(table: ModeTable, i: int) -> dict:
    """The labels row ``i`` of a mode table states (order n, tag, branch) as the matching's penalties read them."""
    n = int(table.n[i])
    tag = table.tag[i]
    if n < 0 and tag in ("vert", "hort"):
        n = 1
    return {"n": n, "tag": tag, "branch": table.branch[i]}


def _n_agrees(n: int, c: Candidate) -> bool:
    """A row's n agrees with a candidate naming its mode's dominant order, or, for a sensor line ω + kΩ,
    the line's own harmonic |k| (the winding a co-rotating measurement sees at that line)."""
    return n == c.n or (c.k is not None and n == abs(c.k))


def label_penalties(lab: dict, c: Candidate) -> tuple[float, list[str]]:
    """Penalty and the list of contradicted labels."""
    pen, bad = 0.0, []
    if lab["n"] >= 0 and not _n_agrees(lab["n"], c):
        pen += LABEL_PENALTY
        bad.append("n")
    if lab["branch"]:
        if c.direction == "standing":
            pen += 1.0
        elif c.direction != lab["branch"]:
            pen += LABEL_PENALTY
            bad.append("direction")
    if lab["tag"]:
        s = c.symmetry if math.isfinite(c.symmetry) else 0.5
        share = (1.0 - s) if lab["tag"] in ("extr", "vert") else s
        pen += LABEL_PENALTY * share
        if share > 0.5:
            bad.append("tag")
    return pen, bad


def _score(f: float, std: float, lab: dict, c: Candidate, tol: float, use_labels: bool = True):
    sig = _sigma(c.hz, std, tol)
    z = (f - c.hz) / sig
    pen, bad = label_penalties(lab, c) if use_labels else (0.0, [])
    line = -2.0 * math.log(max(c.weight, 1e-12))
    return z * z + pen + line, z, sig, bad


# ----------------------------------------------------------------------------------------------- matching
@dataclass
class CampbellMatch:
    """Measured tables matched to the branches of the model (docs/physics.md §3.7).

    - ``rows``: one dict per measured row (the columns of ``*.matched.csv``, docs/formats.md).
    - ``diagrams``: the diagrams used, one per (contact, load, drum) group, keyed by group.
    - ``conditions``: the :class:`TableCondition` of each table.
    """

    rows: list[dict]
    diagrams: dict
    conditions: list
    tolerance: float = MODEL_TOLERANCE
    tolerance_note: str = ""

    def assignment(self) -> dict:
        """Each row's (mode, line) at its speed, for a diagnosis that refits through it (issue 13 item 5).

        **Returns:** dict of arrays, one entry per row (``match.rows`` order): ``omega`` Ω [rad/s],
        ``load_n``, ``contact`` (bool), ``fixed_frame`` (bool), ``mode_index`` (index among the
        modes of :func:`ringfit.physics.rolling_modes.rolling_modes` at that speed, ascending
        frequency; −1 when unmatched), ``k`` (sensor line harmonic; 0 in the fixed frame),
        ``explained`` (bool). Evaluate with :func:`ringfit.physics.rolling_modes.observed_frequencies`.
        """
        keys = ("omega", "load_n", "contact", "fixed_frame", "mode_index", "k", "explained")
        out = {k: [] for k in keys}
        for r in self.rows:
            a = r["_assignment"]
            for k in keys:
                out[k].append(a[k])
        dtypes = {"contact": bool, "fixed_frame": bool, "explained": bool, "mode_index": int, "k": int}
        return {k: np.asarray(v, dtype=dtypes.get(k, np.float64)) for k, v in out.items()}

    @property
    def unexplained(self) -> list[dict]:
        return [r for r in self.rows if r["status"] == "unexplained"]

    def summary(self) -> str:
        """One line: how many rows matched, conflict in label or trend, or stay unexplained."""
        st = [r["status"] for r in self.rows]
        parts = [f"{st.count(s)} {s}" for s in ("matched", "label_conflict", "trend_conflict", "unexplained") if s in st]
        return f"{len(self.rows)} rows: " + ", ".join(parts)


MATCH_COLUMNS = ("source", "row", "speed_kmh", "rotation_hz", "load_n", "frame", "freq_hz", "sigma_hz", "n", "tag",
                 "branch", "status", "explained", "model_branch", "model_hz", "model_n", "model_direction",
                 "model_tag", "model_k", "line_weight", "error_hz", "error_pct", "z", "label_conflicts", "note")


def match_tables(
    tables,
    ring,
    geometry,
    *,
    load_n: float | None = None,
    drum_diameter_m: float | None = None,
    model_tolerance: float | None = None,
    speeds_kmh=None,
    n_max: int = DEFAULT_N_MAX,
    harmonics: int | None = None,
) -> CampbellMatch:
    """Match every row of ``tables`` to the model's branches (docs/physics.md §3.7; issue 13 items 3–4).

    **Arguments:**

    - ``tables``: :class:`~ringfit.io.modes.ModeTable` list (condition from each sidecar:
      state, load_n, speed_kmh or rotation_hz, frame; see :func:`table_conditions`).
    - ``ring``, ``geometry``: the fitted tyre.
    - ``load_n``: load for tables whose sidecar lacks one; ``drum_diameter_m``: None = flat road.
    - ``model_tolerance``: relative σ τ of the model; ``None`` (default): from the data
      (:func:`data_tolerance`: a first pass at :data:`MODEL_TOLERANCE`, then τ from the
      explained rows' residuals in excess of their ``freq_std_hz``, a robust scale).
    - ``speeds_kmh``: extra speeds for the tracking between the tables' speeds
      (default: every 10 km/h up to the fastest table).
    - ``n_max``, ``harmonics``: as :func:`campbell_diagram`.

    **Returns:** :class:`CampbellMatch`. Acoustic rows are matched like the others
    (the ring has no cavity mode: they come out unexplained, as they should).
    """
    tables = list(tables)
    if not tables:
        raise InputError("no mode table to match")
    if model_tolerance is not None and not (math.isfinite(model_tolerance) and model_tolerance > 0):
        raise InputError(f"model tolerance {model_tolerance}: expected a positive relative σ")
    conds = table_conditions(tables, ring, geometry, load_n=load_n, drum_diameter_m=drum_diameter_m)
    groups: dict = {}
    for ti, c in enumerate(conds):
        groups.setdefault(diagram_group_key(c.contact, c.load_n, drum_diameter_m), []).append(ti)
    diagrams = {}
    for key, idx in groups.items():
        top = max(conds[i].speed_kmh for i in idx)
        grid = np.arange(0.0, top + 10.0, 10.0) if speeds_kmh is None else np.asarray(speeds_kmh, dtype=np.float64)
        sp = np.unique(np.round(np.concatenate([grid[grid <= top + 1e-9], [conds[i].speed_kmh for i in idx]]), 9))
        diagrams[key] = campbell_diagram(ring, geometry, key[1], sp, drum_diameter_m=drum_diameter_m,
                                         contact=key[0], n_max=n_max, harmonics=harmonics)
    if model_tolerance is None:
        first, _ = _match_rows(tables, conds, diagrams, drum_diameter_m, MODEL_TOLERANCE)
        tol, note = data_tolerance(first)
    else:
        tol, note = float(model_tolerance), f"model σ {100 * model_tolerance:.3g} % (given)"
    rows, ctx = _match_rows(tables, conds, diagrams, drum_diameter_m, tol)
    _explain(rows, ctx, diagrams, tol)
    return CampbellMatch(rows=rows, diagrams=diagrams, conditions=conds, tolerance=tol, tolerance_note=note)


def _match_rows(tables, conds, diagrams, drum_diameter_m, tol):
    rows: list[dict] = []
    ctx: list[tuple] = []  # (diagram key, speed index, table, row index, labels)
    for ti, t in enumerate(tables):
        c = conds[ti]
        key = diagram_group_key(c.contact, c.load_n, drum_diameter_m)
        d = diagrams[key]
        s = int(np.argmin(np.abs(d.speed_kmh - round(c.speed_kmh, 9))))
        if not d.ok[s]:
            raise InputError(f"the model did not converge at {c.speed_kmh:.4g} km/h ({c.load_n:g} N)", source=t.source)
        cands = diagram_candidates(d, s, c.frame)
        labs = [row_labels(t, i) for i in range(len(t))]
        assign = assign_rows(t, labs, cands, tol)
        for i in range(len(t)):
            row = _row_record(t, i, c, d, s, labs[i], assign[i], tol)
            rows.append(row)
            ctx.append((key, s, t, i, labs[i], c))
    return rows, ctx


def data_tolerance(rows) -> tuple[float, str]:
    """The model's relative σ τ from matched rows (a first pass at :data:`MODEL_TOLERANCE`), and a note.

    Rows explained in that pass without a label conflict give relative residuals
    ``r = (f − f̂)/f̂`` and relative measurement σ ``u = freq_std_hz/f̂`` (0 when empty); τ is
    the robust scale of r in excess of the measurement: ``τ² = (1.4826·median|r|)² − median(u²)``,
    kept within [:data:`MIN_TOLERANCE`, :data:`MODEL_TOLERANCE`]. A bias of the model counts in
    τ (|r| is not centred). Fewer than :data:`MIN_ROWS_FOR_TOLERANCE` such rows: τ = MODEL_TOLERANCE.
    """
    r, u = [], []
    for rec in rows:
        if rec["status"] == "matched" and math.isfinite(rec["error_pct"]):
            r.append(rec["error_pct"] / 100.0)
            std = rec.get("_std", math.nan)
            u.append(std / rec["model_hz"] if math.isfinite(std) else 0.0)
    if len(r) < MIN_ROWS_FOR_TOLERANCE:
        return MODEL_TOLERANCE, (f"model σ {100 * MODEL_TOLERANCE:.3g} % (default: {len(r)} matched rows, fewer "
                                 f"than {MIN_ROWS_FOR_TOLERANCE} to estimate it from)")
    scale2 = (MAD_TO_SIGMA * float(np.median(np.abs(r)))) ** 2 - float(np.median(np.square(u)))
    raw = math.sqrt(max(scale2, 0.0))
    tol = min(max(raw, MIN_TOLERANCE), MODEL_TOLERANCE)
    bound = " (at its floor)" if tol > raw else (" (at its cap)" if tol < raw else "")
    return tol, (f"model σ {100 * tol:.3g} %{bound} from the residuals of {len(r)} matched rows "
                 "(1.4826·median |relative error|, less the rows' freq_std_hz)")


def assign_rows(table, labs, cands, tol):
    """One candidate per row (Hungarian on the cost), or None."""
    from scipy.optimize import linear_sum_assignment

    m = len(table)
    if not cands:
        return [None] * m
    cost = np.empty((m, len(cands)))
    info = {}
    for i in range(m):
        for j, c in enumerate(cands):
            val, z, sig, bad = _score(float(table.freq_hz[i]), float(table.freq_std_hz[i]), labs[i], c, tol)
            cost[i, j] = val
            info[i, j] = (z, sig, bad)
    r, col = linear_sum_assignment(np.minimum(cost, 1e6))
    out = [None] * m
    for i, j in zip(r, col):
        out[i] = (cands[j], *info[i, j])
    return out


def _row_record(t, i, c: TableCondition, d, s, lab, a, tol) -> dict:
    f = float(t.freq_hz[i])
    rec = {
        "source": str(t.source), "row": i + 1, "speed_kmh": round(float(c.speed_kmh), 6),
        "rotation_hz": float(c.omega / (2 * math.pi)), "load_n": float(c.load_n), "frame": c.frame, "freq_hz": f,
        "sigma_hz": math.nan, "n": lab["n"] if lab["n"] >= 0 else None, "tag": lab["tag"], "branch": lab["branch"],
        "status": "unexplained", "explained": False, "model_branch": None, "model_hz": math.nan, "model_n": None,
        "model_direction": "", "model_tag": "", "model_k": None, "line_weight": math.nan, "error_hz": math.nan,
        "error_pct": math.nan, "z": math.nan, "label_conflicts": "", "note": "",
    }
    rec["_std"] = float(t.freq_std_hz[i])
    rec["_assignment"] = {"omega": float(c.omega), "load_n": float(c.load_n), "contact": bool(c.contact),
                          "fixed_frame": c.frame == "fixed", "mode_index": -1, "k": 0, "explained": False}
    if a is None:
        return rec
    cand, z, sig, bad = a
    rec["_assignment"].update(mode_index=int(d.mode_index[s, cand.branch]), k=int(cand.k or 0),
                              explained=abs(z) <= EXPLAINED_Z)
    rec.update({
        "sigma_hz": sig, "model_branch": cand.branch + 1, "model_hz": cand.hz, "model_n": cand.n,
        "model_direction": cand.direction, "model_tag": cand.tag, "model_k": cand.k, "line_weight": cand.weight,
        "error_hz": f - cand.hz, "error_pct": 100.0 * (f - cand.hz) / cand.hz, "z": z, "label_conflicts": ",".join(bad),
    })
    rec["explained"] = abs(z) <= EXPLAINED_Z
    rec["status"] = "matched" if rec["explained"] and not bad else ("label_conflict" if rec["explained"] else "unexplained")
    rec["_cand"] = cand
    return rec


def _best(f, std, lab, cands, tol, *, use_labels=True, require=None):
    best = None
    for c in cands:
        if require is not None and not require(c):
            continue
        val, z, sig, bad = _score(f, std, lab, c, tol, use_labels)
        if best is None or val < best[0]:
            best = (val, c, z, bad)
    return best


def _alternatives(f, std, lab, d, s, frame, tol) -> str:
    """Test a frame mix-up, a line of another mode and a different n; a clause for the first that explains the row."""
    other = "fixed" if frame == "rotating" else "rotating"
    oc = diagram_candidates(d, s, other)
    b = _best(f, std, lab, oc, tol)
    if b is not None and abs(b[2]) <= EXPLAINED_Z and not b[3]:
        return f"a frame mix-up explains it: seen in the {other} frame it is {b[1].describe(other)} (z = {b[2]:+.1f})"
    cands = diagram_candidates(d, s, frame)
    if frame == "rotating":
        weak = _best(f, std, lab, cands, tol, require=lambda c: c.weight < 0.999)
        if weak is not None and abs(weak[2]) <= EXPLAINED_Z and not weak[3]:
            return f"it is a secondary line: {weak[1].describe(frame)} (z = {weak[2]:+.1f})"
    free_n = dict(lab, n=-1)
    b = _best(f, std, free_n, cands, tol)
    if b is not None and abs(b[2]) <= EXPLAINED_Z and lab["n"] >= 0 and not _n_agrees(lab["n"], b[1]):
        return f"a different n explains it: {b[1].describe(frame)} (z = {b[2]:+.1f})"
    nolab = _best(f, std, lab, cands, tol, use_labels=False)
    if nolab is not None and abs(nolab[2]) <= EXPLAINED_Z:
        return f"only by ignoring its labels: {nolab[1].describe(frame)} (z = {nolab[2]:+.1f})"
    near = min(cands + oc, key=lambda c: abs(c.hz - f), default=None)
    if near is None:
        return "the model has no branch in this frame"
    fr = frame if near in cands else other
    return f"no frame mix-up, other line or other n explains it (nearest: {near.describe(fr)}, {f - near.hz:+.1f} Hz)"


def _explain(rows, ctx, diagrams, tol):
    """Notes for every row: match, label conflicts, speed-trend conflicts, alternatives (issue 13 item 4)."""
    for rec, (key, s, t, i, lab, c) in zip(rows, ctx):
        d = diagrams[key]
        f, std = rec["freq_hz"], float(t.freq_std_hz[i])
        cand = rec.get("_cand")
        where = f"{c.speed_kmh:.4g} km/h, {c.frame} frame"
        if rec["status"] == "matched":
            rec["note"] = (f"matched to {cand.describe(c.frame)}: error {rec['error_hz']:+.2f} Hz "
                           f"({rec['error_pct']:+.1f} %, z = {rec['z']:+.1f}).")
        elif rec["status"] == "label_conflict":
            near = [x for x in diagram_candidates(d, s, c.frame) if abs((f - x.hz) / _sigma(x.hz, std, tol)) <= EXPLAINED_Z]
            what = ", ".join(sorted({x.describe(c.frame).split(" at ")[0] for x in near})[:4])
            bad = rec["label_conflicts"].split(",")
            conflict = " and ".join(bad) + (" labels contradict" if len(bad) > 1 else " label contradicts")
            rec["note"] = (f"its {conflict} every branch within {EXPLAINED_Z:g}σ at {where} "
                           f"({what}); {_alternatives(f, std, lab, d, s, c.frame, tol)}.")
        else:
            rec["note"] = (f"unexplained at {where}: no branch within {EXPLAINED_Z:g}σ; "
                           f"{_alternatives(f, std, lab, d, s, c.frame, tol)}.")
    _trend_checks(rows, ctx, diagrams, tol)
    for rec in rows:
        rec.pop("_cand", None)
        rec.pop("_std", None)


def _trend_checks(rows, ctx, diagrams, tol):
    """Rows of one label across speeds must follow one branch (or one line of it).

    Rows with the same labels (n, tag, branch, a) in tables of one group at different
    speeds are chained by speed. A pair is consistent when both rows are matched with
    their labels, or when a branch (a line of it, in the rotating frame) within 3σ of the
    first row passes within 3σ of the second. Otherwise the row that is not consistent
    with its other neighbour becomes a ``trend_conflict``, with the branches' course and
    the alternatives (frame mix-up, other line, other n) in its note.
    """
    groups: dict = {}
    for ri, (key, s, t, i, lab, c) in enumerate(ctx):
        if lab["n"] < 0 and not lab["tag"] and not lab["branch"]:
            continue
        gk = (key, c.frame, lab["n"], lab["tag"], lab["branch"], round(float(t.a[i])))
        groups.setdefault(gk, []).append(ri)
    for gk, members in groups.items():
        speeds = {ctx[r][1] for r in members}
        if len(speeds) < 2:
            continue
        members = sorted(members, key=lambda r: ctx[r][1])
        # one row per speed: the one best explained at that speed
        by_speed: dict = {}
        for r in members:
            s = ctx[r][1]
            if s not in by_speed or abs(rows[r]["z"] if math.isfinite(rows[r]["z"]) else 1e9) < abs(
                    rows[by_speed[s]]["z"] if math.isfinite(rows[by_speed[s]]["z"]) else 1e9):
                by_speed[s] = r
        chain = [by_speed[s] for s in sorted(by_speed)]
        ok_pairs = []
        for a, b in zip(chain[:-1], chain[1:]):
            if rows[a]["status"] == "matched" and rows[b]["status"] == "matched":
                # both rows carry their labels on a branch: the label may pass from one branch to another
                # between the speeds (contact and rotation exchange content), which is no contradiction
                ok_pairs.append(True)
                continue
            ok_pairs.append(_pair_consistent(rows[a], rows[b], ctx[a], ctx[b], diagrams, tol))
        for j, (a, b) in enumerate(zip(chain[:-1], chain[1:])):
            if ok_pairs[j] is True:
                continue
            # blame the row that is not consistent with its other neighbour
            nxt_ok = j + 1 < len(ok_pairs) and ok_pairs[j + 1] is True
            bad, good = (a, b) if nxt_ok else (b, a)
            if rows[bad]["status"] == "trend_conflict":
                continue
            _flag_trend(rows, ctx, diagrams, tol, bad, good, ok_pairs[j])


def _pair_consistent(ra, rb, ca, cb, diagrams, tol):
    """True if one branch (same line) passes both rows; else the branches through ``ra`` and where they go."""
    key, sa = ca[0], ca[1]
    sb = cb[1]
    frame = ca[5].frame
    d = diagrams[key]
    fa, fb = ra["freq_hz"], rb["freq_hz"]
    stda, stdb = float(ca[2].freq_std_hz[ca[3]]), float(cb[2].freq_std_hz[cb[3]])
    through = []
    for c in diagram_candidates(d, sa, frame):
        if abs((fa - c.hz) / _sigma(c.hz, stda, tol)) > EXPLAINED_Z:
            continue
        follow = _follow(d, c, sb, frame)
        if follow is None:
            continue
        through.append((c, follow))
        if abs((fb - follow) / _sigma(follow, stdb, tol)) <= EXPLAINED_Z:
            return True
    return through


def _follow(d, c, s, frame):
    if frame == "fixed":
        return float(d.fixed_hz[s, c.branch])
    j = int(np.flatnonzero(d.k == c.k)[0])
    return abs(float(d.line_hz[s, c.branch, j]))


def _flag_trend(rows, ctx, diagrams, tol, bad, good, through):
    rb, rg = rows[bad], rows[good]
    key, s, t, i, lab, c = ctx[bad]
    d = diagrams[key]
    moves = rb["freq_hz"] - rg["freq_hz"]
    if through:
        dest = ", ".join(f"branch {x.branch + 1} → {f:.1f} Hz" for x, f in through[:3])
        branches = f"the branches through {rg['freq_hz']:.1f} Hz at {rg['speed_kmh']:.4g} km/h go to {dest}"
    else:
        branches = f"no branch passes its {rg['speed_kmh']:.4g} km/h row ({rg['freq_hz']:.1f} Hz)"
    alt_txt = _alternatives(rb["freq_hz"], float(t.freq_std_hz[i]), lab, d, s, c.frame, tol)
    rb["status"] = "trend_conflict"
    rb["note"] = (f"speed trend contradicts every branch: from {rg['speed_kmh']:.4g} to {rb['speed_kmh']:.4g} km/h this "
                  f"row moves {moves:+.1f} Hz while {branches}; {alt_txt}.")


def match_rows_table(match: CampbellMatch) -> list[list]:
    """``match.rows`` as lists of values in :data:`MATCH_COLUMNS` order (None/NaN where empty)."""
    return [[r[c] for c in MATCH_COLUMNS] for r in match.rows]


# ----------------------------------------------------------------------------------------------- identification side
#: Without a tyre model, a winding above channels/this is flagged (fewer than 4 channels per wavelength).
CHANNELS_PER_WAVELENGTH = 4


def resolution_flags(table: ModeTable, channels: int) -> list[str]:
    """Flags for orders the SSI channel spacing cannot resolve reliably (no model needed).

    A winding m is estimated from ``channels`` evenly spaced sectors; it is unique only for
    |m| < channels/2 and with fewer than :data:`CHANNELS_PER_WAVELENGTH` channels per
    wavelength (|m| > channels/4) aliasing and noise poles with random shapes dominate.
    **Returns:** one string per row ("" when plausible).
    """
    limit = channels / CHANNELS_PER_WAVELENGTH
    out = []
    for i in range(len(table)):
        n = int(table.n[i])
        if n > limit:
            out.append(f"n = {n} is beyond what {channels} channels resolve (|n| ≤ {limit:g}: "
                       f"{CHANNELS_PER_WAVELENGTH} channels per wavelength); likely a noise pole or an alias")
        else:
            out.append("")
    return out


def label_identified_modes(table: ModeTable, ring=None, geometry=None, *, channels: int, load_n: float | None = None,
                           drum_diameter_m: float | None = None, model_tolerance: float = MODEL_TOLERANCE,
                           n_max: int = DEFAULT_N_MAX, speeds_kmh=None) -> tuple[ModeTable, list[str]]:
    """Model labels (n, direction) for a rolling-tyre mode table and flags for implausible labels (issue 13 item 6).

    **Arguments:** ``table`` from :func:`ringfit.targets.rolling_modes.identify_rolling_modes`
    (fixed frame); ``ring``, ``geometry`` (None: only the channel-resolution check of
    :func:`resolution_flags`); ``channels`` — SSI channels; the rest as :func:`match_tables`.

    **Returns:** ``(table, flags)``: a copy with extra columns ``model_branch``, ``model_n``,
    ``model_direction``, ``model_tag``, ``model_hz``, ``label_flag`` (docs/formats.md §2:
    unknown columns are kept), and one flag sentence per row ("" when plausible).
    """
    from dataclasses import replace

    flags = resolution_flags(table, channels)
    extra = dict(table.extra)
    m = len(table)
    if ring is not None and m:
        res = match_tables([table], ring, geometry, load_n=load_n, drum_diameter_m=drum_diameter_m,
                           model_tolerance=model_tolerance, n_max=n_max, speeds_kmh=speeds_kmh)
        cols = {k: [] for k in ("model_branch", "model_n", "model_direction", "model_tag", "model_hz")}
        for j, r in enumerate(res.rows):
            ok = r["explained"]
            cols["model_branch"].append(str(r["model_branch"]) if ok else "")
            cols["model_n"].append(str(r["model_n"]) if ok else "")
            cols["model_direction"].append(r["model_direction"] if ok else "")
            cols["model_tag"].append(r["model_tag"] if ok else "")
            cols["model_hz"].append(f"{r['model_hz']:.4f}" if ok else "")
            if r["status"] != "matched":
                flags[j] = "; ".join(x for x in (flags[j], r["note"]) if x)
        extra.update({k: np.array(v, dtype=object) for k, v in cols.items()})
    extra["label_flag"] = np.array(flags, dtype=object)
    return replace(table, extra=extra), flags


# ----------------------------------------------------------------------------------------------- free ring
def compare_with_ring(table, ring, geometry, rotation_hz: float) -> list[dict]:
    """Each identified mode beside the free rotating ring's prediction (docs/physics.md §3.2–3.3).

    For a row with order n and a branch (or a standing tag, compared with
    both branches) the prediction is the fixed-frame frequency |ω_nk − nΩ|/2π
    (eq. 26) of that wave, and the co-rotating one |ω_nk|/2π (eq. 25): the
    difference between the two is the Doppler shift nΩ/2π, and the fixed-frame
    gap between the forward and backward waves of one n is the bifurcation.
    No contact: for the loaded tyre use :func:`match_tables`.

    **Returns** one dict per row: ``n``, ``branch``, ``tag``, ``freq_hz``,
    ``fixed_pred_hz``, ``rotating_pred_hz``, ``doppler_hz``, ``error_hz``,
    ``bifurcation_pred_hz`` (fixed-frame forward − backward for that n).
    """
    from ringfit.physics.natural import fixed_frame_frequencies, rotating_natural_frequencies

    omega = 2.0 * math.pi * float(rotation_hz)
    out = []
    for i in range(len(table)):
        n = int(table.n[i])
        if n < 1:
            continue
        fixed = np.abs(np.asarray(fixed_frame_frequencies(ring, geometry, float(n), omega)))
        rot = np.abs(np.asarray(rotating_natural_frequencies(ring, geometry, float(n), omega)))
        branch = table.branch[i]
        if branch:
            k = 0 if branch == "backward" else 1
        else:  # standing: the nearer of the two waves
            k = int(np.argmin(np.abs(fixed - table.freq_hz[i])))
        out.append({
            "n": n, "branch": branch or ("backward" if k == 0 else "forward"), "tag": table.tag[i],
            "freq_hz": float(table.freq_hz[i]), "fixed_pred_hz": float(fixed[k]),
            "rotating_pred_hz": float(rot[k]), "doppler_hz": float(n * omega / (2 * math.pi)),
            "error_hz": float(table.freq_hz[i] - fixed[k]), "bifurcation_pred_hz": float(fixed[1] - fixed[0]),
        })
    return out


__all__ = [
    "DEFAULT_N_MAX", "MODEL_TOLERANCE", "MIN_TOLERANCE", "data_tolerance", "EXPLAINED_Z", "LABEL_PENALTY", "CampbellDiagram", "campbell_diagram",
    "track_branches", "TableCondition", "table_conditions", "CampbellMatch", "match_tables", "MATCH_COLUMNS",
    "CAMPBELL_COLUMNS", "match_rows_table", "resolution_flags", "label_identified_modes", "compare_with_ring",
    "frame_name", "Candidate", "diagram_candidates", "diagram_group_key", "row_labels", "label_penalties", "assign_rows",
    "MIN_LINE_WEIGHT",
]
