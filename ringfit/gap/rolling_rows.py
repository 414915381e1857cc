"""Rows of ``rolling`` mode tables in the gap diagnosis: the rolling, loaded tyre's modes (docs/physics.md §3.7, §6).

A ``rolling`` table (docs/formats.md §2 sidecar: ``state = rolling``, ``load_n`` > 0,
``speed_kmh`` or ``rotation_hz`` > 0, ``frame``) was measured on a tyre that spins
*and* touches the ground. Its rows are predicted by the model of docs/physics.md §3.7
(:func:`ringfit.physics.rolling_modes.rolling_modes`: the ring rotating at Ω with the
tread springs of the steady contact patch, Hill's method) and by what the table's
observer sees of it (:func:`~ringfit.physics.rolling_modes.observed_frequencies`: the
co-rotating sensor a line ω + kΩ, a fixed observer ω).

**Assignment, once, outside the refits.** Every structural row of the rolling tables
is matched to a branch (fixed frame) or to a line of a branch (co-rotating frame) by
:func:`ringfit.gap.campbell.match_tables` — the matching of ``ringfit campbell`` —
at the computed condition: the ring fitted to ``free.modes.csv``, ``k_trd`` of the
diagnosis, Ω = V/R_e (R_e = R_out − δ/3), the patch of the steady rolling solution at
that speed, :data:`ROLLING_HARMONICS` harmonics. Tags ``extr``/``0`` (``vert``/``hort``)
are matched to the contact-symmetric/antisymmetric branches through the modes'
symmetry; rows without n, tag or branch are matched by frequency; the match (branch,
n, direction, line, error, z) is stated per row (``labels["matched"]``,
``labels["rolling"]``: the JSON ``rows[].match`` and ``rows[].rolling_match``). The
assignment — mode index at that speed and sensor line k — is static; inside the
predictor only the frequencies are recomputed, so the refits differentiate them with
respect to ``patch_scale`` and ``speed_gain``.

**How the two effects combine on these rows** (:class:`RollingJoint`). With both
``ground_contact`` (patch scale s) and ``rotation`` (speed gain g) away from their
nulls, a rolling row is ``rolling_modes(ring, g·Ω, arc scaled by s)`` at its assigned
mode and line — the joint model, one eigen-solve per rolling table (a sequential ``lax.map``:
batched eigen-solves under forward-mode differentiation are avoided on purpose),
added to what the chain's other effects did (``+ (joint − eq. 18)``). With one of
the two alone, the rows get that effect alone: ``rotation`` eq. 25/26 on the row's
branch (where the table gives none: the wave of eq. 25/26 nearer the measured
frequency, stated), ``ground_contact`` the standing loaded modes on the row's tag
(where it gives none: the cos/sin-type loaded mode nearer the measured frequency,
stated). With neither, the baseline is eq. 18 of the row's n. A row without n takes, for the
baseline and the single-effect predictions, the n (and wave) of the nearest eq. 25/26 wave — each
model its own assignment: the joint one keeps the branch it was matched to, whatever its n.

The mode index is fixed at the computed condition; a fitted patch scale or speed gain
far from 1 may reorder modes, and the row then follows the index, not the shape (a
stated limitation: the computed variants are the predictions the verdict leans on).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

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
    """Match the structural rows of the rolling tables to the model's branches; fills the row dicts.

    **Arguments:** ``tables`` — the case's tables (free first); ``rows`` — the row dicts of
    :mod:`ringfit.gap.modal` (keys ``table``, ``i``, ``n``, ``tag``, ``branch``, ``contact``,
    ``freq``, ``fixed``, …; modified in place: ``n`` where missing, ``spin``, ``joint``,
    ``mode_index``, ``line_k``, ``wave``, ``contact``, ``patch``); ``ring``, ``geometry`` —
    the ring fitted to ``free.modes.csv`` (``k_tread`` of the diagnosis); ``patches`` —
    ``(a, σ_a)`` of each table's static contact solve.

    **Returns:** ``(conditions, notes, records, line_sets)``: :class:`RollingConditions` (``None``
    without rolling tables), ``{row position: match sentence}``, ``{row position:
    structured match}`` (n, direction, tag, line k, frame, model frequency, z, status) and
    ``{table index: [line dicts]}`` — every line a row of that table could be matched to
    (``hz``, matching ``cost`` and ``sigma``, the row ``fields`` of :func:`line_fields`), for the
    random-line null of :mod:`ringfit.gap.calibration` and the ambiguity of a match.
    """
    from ringfit.gap.campbell import MODEL_TOLERANCE, _candidates, _group_key, match_tables

    T = len(tables)
    sel = [ti for ti, t in enumerate(tables) if is_rolling(t)]
    if not sel:
        return None, {}, {}, {}
    omega, lead, trail = np.zeros(T), np.zeros(T), np.zeros(T)
    table_notes, notes, records, line_sets = {}, {}, {}, {}
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
            d = match.diagrams[_group_key(cond.contact, cond.load_n, drum)]
            s = int(np.argmin(np.abs(d.speed_kmh - round(cond.speed_kmh, 9))))
            omega[ti] = cond.omega
            lead[ti], trail[ti] = math.radians(d.leading_deg[s]), math.radians(d.trailing_deg[s])
            patch = patches[ti][0]
            line_sets[ti] = [dict(hz=c.hz, cost=-2.0 * math.log(max(c.weight, 1e-12)),
                                  sigma=MODEL_TOLERANCE * c.hz,
                                  fields=line_fields(c.n, c.direction, c.tag, int(d.mode_index[s, c.branch]),
                                                     float(c.k or 0), patch))
                             for c in _candidates(d, s, cond.frame)]
            table_notes[ti] = (f"rolling model (docs/physics.md §3.7): Ω = {cond.omega:.4g} rad/s from "
                               f"{cond.source_speed}, contact arc {d.leading_deg[s]:.2f}…{d.trailing_deg[s]:.2f} deg "
                               f"of the steady rolling solution at {cond.load_n:g} N, {cond.frame} frame, "
                               f"K = {ROLLING_HARMONICS} harmonics; rows matched to branches as `ringfit campbell` does")
            for i in range(len(t)):
                rec = match.rows[offset + i]
                j = position.get((ti, i))
                if j is None:  # acoustic rows are not part of the frequency problem
                    continue
                r = rows[j]
                a = rec["_assignment"]
                r["spin"] = float(cond.omega)
                if a["mode_index"] < 0:
                    notes[j] = "rolling model: no branch to match (the row keeps the single-effect predictions)"
                    continue
                r.update(joint=1.0, mode_index=int(a["mode_index"]), line_k=float(a["k"]))
                shared = _shared_assignment(r, rec, patches[ti][0])
                records[j] = {"model_branch": rec["model_branch"], "model_n": rec["model_n"],
                              "model_direction": rec["model_direction"], "model_tag": rec["model_tag"],
                              "model_k": rec["model_k"], "frame": rec["frame"], "model_hz": _num(rec["model_hz"]),
                              "z": _num(rec["z"]), "status": rec["status"]}
                notes[j] = f"rolling model: {rec['note']}".rstrip(".")
                if shared:
                    notes[j] += "; " + shared
            offset += len(t)
    _single_effect_labels(rows, ring, geometry, patches, notes, sel)
    return RollingConditions(omega, lead, trail, table_notes), notes, records, line_sets


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
        if r["table"] not in sel or r["joint"] > 0:
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
           "joint_for"]
