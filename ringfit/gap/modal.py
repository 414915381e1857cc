"""The mode-table side of the gap diagnosis: baseline eq. 18 fitted to ``free.modes.csv`` (PHYSICS.md §2.1, §6).

Every structural row with an assigned n of every mode table in the case
(the free table and the test tables: loaded, rolling, spinning) is one
frequency observation; rows with ``damping_pct`` add a damping observation.
The baseline predicts ``f_n`` of eq. 18 and one damping ratio ζ0 for all of
them, whatever the table's state; the effects (ground contact, rotation,
cavity, sensor mass, extensibility, wave damping) change the rows they speak
to (:meth:`ringfit.gap.effects.base.Effect.modal`).

Noise (when the table has no ``freq_std_hz``): from the data, by second
differences along n of the baseline residual within each sequence (one
table, one tag/branch, one family): for white noise
``Var(r_{n+1} − 2r_n + r_{n−1}) = 6σ²``, while a residual that varies smoothly
with n (what most effects produce) largely cancels. Robust form
``σ = 1.4826·median|Δ²r|/√6`` pooled over sequences, with floors of
:data:`FREQ_SIGMA_FLOOR_HZ` and :data:`DAMPING_SIGMA_FLOOR`. A user value
overrides it (``noise={"freq_hz": 0.3, "damping": 0.002}``).
"""

from __future__ import annotations

import math
from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ringfit.errors import InputError
from ringfit.gap.effects.base import Effect
from ringfit.gap.problem import GapProblem
from ringfit.gap.ranking import predict
from ringfit.io.modes import ModeTable
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.natural import cavity_frequency, natural_angular_frequencies

FREQ_SIGMA_FLOOR_HZ = 0.02
#: Relative floor: a frequency is rarely identified better than this.
FREQ_SIGMA_FLOOR_REL = 2e-4
DAMPING_SIGMA_FLOOR = 5e-4
#: Relative floor on the damping noise: modal damping is rarely identified better than 10 %.
DAMPING_SIGMA_FLOOR_REL = 0.10
#: Baseline parameters of the mode-table side (eq. 18 + one damping ratio).
BASE = ("rho_a", "ei", "kw", "kv", "damping_ratio")
#: log-normal prior σ around the free-table fit in refits (weak: keeps ρA, which eq. 18
#: determines only through p0·b/R, from wandering off).
BASE_PRIOR_SD = 0.5
KMH = 1.0 / 3.6


class ModalRows(eqx.Module):
    """The observations of a mode-table diagnosis as arrays, shape ``(m,)`` each.

    - ``n``: circumferential index (float); ``is_freq``: 1 frequency row, 0 damping row.
    - ``contact``: 0 untagged / free, 1 cosine type (``extr``, ``vert``), 2 sine type (``0``, ``hort``).
    - ``spin``: wheel speed Ω of the table's condition [rad/s] (0 = static).
    - ``branch``: +1 backward, −1 forward, 0 none; ``fixed_frame``: 1 fixed observer, 0 co-rotating.
    - ``cavity_hz``: uncoupled cavity frequency used by ``cavity_mode`` [Hz] (same for all rows).
    """

    n: jax.Array
    is_freq: jax.Array
    contact: jax.Array
    spin: jax.Array
    branch: jax.Array
    fixed_frame: jax.Array
    cavity_hz: jax.Array


class ModalData(eqx.Module):
    rows: ModalRows
    ring: RingParams
    geometry: TyreGeometry


def table_label(table: ModeTable, index: int) -> str:
    c = table.condition
    state = table.state
    parts = [state]
    sp = c.get("speed_kmh") or 0
    if sp:
        parts.append(f"{sp:g} km/h")
    if state != "free" and c.get("load_n"):
        parts.append(f"{c['load_n']:g} N")
    name = str(table.source).rsplit("/", 1)[-1]
    return " ".join(parts) if index == 0 else f"{name} ({' '.join(parts)})"


def spin_of(table: ModeTable, outer_radius: float) -> float:
    """Ω [rad/s] of a table's condition: ``rotation_hz`` or ``speed_kmh``/R_out (0 if static)."""
    c = table.condition
    if c.get("rotation_hz"):
        return 2.0 * math.pi * float(c["rotation_hz"])
    if c.get("speed_kmh"):
        return float(c["speed_kmh"]) * KMH / outer_radius
    return 0.0


def build_rows(tables: list[ModeTable], geometry: TyreGeometry):
    """Observation rows of all tables (the free table first).

    **Returns:** ``(rows: ModalRows, y, user_sigma, meta)``; ``user_sigma`` is NaN where the
    table gives none; ``meta`` holds per-row ``table``, ``label``, ``family``, ``sequence``.
    """
    cols = {k: [] for k in ("n", "is_freq", "contact", "spin", "branch", "fixed_frame")}
    y, user_sigma, table_idx, label, family, sequence = [], [], [], [], [], []
    cavity = [float(f) for t in tables for f, k in zip(t.freq_hz, t.kind) if k == "acoustic"]
    for ti, t in enumerate(tables):
        spin = spin_of(t, geometry.outer_radius)
        fixed = 1.0 if t.condition.get("frame", "rotating" if spin > 0 else "fixed") == "fixed" else 0.0
        tl = table_label(t, ti)
        for i in range(len(t)):
            if t.kind[i] != "structural" or t.n[i] < 0:
                continue
            tag = t.tag[i]
            contact = 0
            if t.state != "free":
                contact = 1 if tag in ("extr", "vert") else 2 if tag in ("0", "hort") else 0
            branch = {"backward": 1.0, "forward": -1.0}.get(t.branch[i], 0.0)
            qual = " ".join(x for x in (tag and f"{tag}", t.branch[i]) if x)
            seq = f"{ti}|{tag}|{t.branch[i]}|a{t.a[i]}"
            for is_freq in (1.0, 0.0):
                if is_freq:
                    value, sd = float(t.freq_hz[i]), float(t.freq_std_hz[i])
                else:
                    if not math.isfinite(t.damping_pct[i]):
                        continue
                    value, sd = float(t.damping_pct[i]) / 100.0, math.nan
                cols["n"].append(float(t.n[i]))
                cols["is_freq"].append(is_freq)
                cols["contact"].append(contact)
                cols["spin"].append(spin)
                cols["branch"].append(branch)
                cols["fixed_frame"].append(fixed)
                y.append(value)
                user_sigma.append(sd)
                table_idx.append(ti)
                fam = f"{tl}{' ' + qual if qual else ''}" + ("" if is_freq else " damping")
                family.append(fam)
                label.append(f"{tl} n={t.n[i]}{' ' + qual if qual else ''}" + ("" if is_freq else " damping"))
                sequence.append(seq + ("f" if is_freq else "d"))
    if not y:
        raise InputError("no structural modes with an assigned n in the case's mode tables")
    cav = cavity[0] if cavity else float(cavity_frequency(1))
    rows = ModalRows(
        n=jnp.asarray(cols["n"]), is_freq=jnp.asarray(cols["is_freq"]),
        contact=jnp.asarray(cols["contact"], dtype=jnp.int32), spin=jnp.asarray(cols["spin"]),
        branch=jnp.asarray(cols["branch"]), fixed_frame=jnp.asarray(cols["fixed_frame"]),
        cavity_hz=jnp.asarray(cav),
    )
    meta = dict(table=np.asarray(table_idx), group=np.where(np.asarray(cols["is_freq"]) > 0, "frequency", "damping"), label=label, family=family, sequence=sequence,
                cavity_hz=cav, cavity_source="acoustic row" if cavity else "eq. 22 (343/1.568)")
    return rows, np.asarray(y), np.asarray(user_sigma), meta


class ModalPredictor(eqx.Module):
    """Prediction of every (padded) row of a mode-table problem: frequency [Hz] or damping ratio [-].

    ``theta`` = baseline parameters (``base`` names) then each effect's parameters
    (``sizes`` of them each), natural units.
    """

    effects: tuple = eqx.field(static=True)
    base: tuple = eqx.field(static=True)
    sizes: tuple = eqx.field(static=True)

    def __call__(self, theta, data):
        return _modal(theta, data, self.effects, self.base, self.sizes)


def _modal(theta, data: ModalData, effects: tuple, base: tuple, sizes: tuple):
    ring = data.ring.replace(**{k: theta[i] for i, k in enumerate(base)})
    rows = data.rows
    omega = natural_angular_frequencies(ring, data.geometry, rows.n)
    zeta = jnp.zeros_like(omega) + ring.damping_ratio
    i = len(base)
    for effect, k in zip(effects, sizes):
        omega, zeta = effect.modal(theta[i : i + k], omega, zeta, rows, ring, data.geometry)
        i += k
    return jnp.where(rows.is_freq > 0, omega / (2.0 * jnp.pi), zeta)


#: Effect parameters a chain frees at most besides the baseline (the refit's padded free-set size).
MAX_CHAIN_PARAMETERS = 4
#: Rows are padded to a multiple of this (dummy n = 2 rows, dropped from every output), so one
#: compiled predictor serves mode tables of similar size.
ROW_BUCKET = 32


def pad_rows(rows: ModalRows, bucket: int = ROW_BUCKET) -> ModalRows:
    """``rows`` padded with dummy rows (n = 2, frequency, untagged, static) to a multiple of ``bucket``."""
    m = int(rows.n.shape[0])
    extra = (-m) % bucket
    if extra == 0:
        return rows
    fill = {"n": 2.0, "is_freq": 1.0, "contact": 0, "spin": 0.0, "branch": 0.0, "fixed_frame": 0.0}
    return ModalRows(**{k: jnp.concatenate([getattr(rows, k), jnp.full(extra, v, dtype=getattr(rows, k).dtype)])
                        for k, v in fill.items()}, cavity_hz=rows.cavity_hz)


def second_difference_sigma(residual: np.ndarray, sequence: list[str], n: np.ndarray) -> tuple[float, int]:
    """Robust noise σ from second differences along n within each sequence; returns ``(σ, count)``."""
    d2 = []
    seq = np.asarray(sequence)
    for s in dict.fromkeys(sequence):
        idx = np.flatnonzero(seq == s)
        idx = idx[np.argsort(n[idx])]
        r = residual[idx]
        if r.size >= 3:
            d2.extend(np.abs(r[2:] - 2 * r[1:-1] + r[:-2]))
    if not d2:
        return math.nan, 0
    return float(1.4826 * np.median(d2) / math.sqrt(6.0)), len(d2)


def build_modal_problem(tables: list[ModeTable], geometry: TyreGeometry, ring: RingParams,
                        effects: tuple[Effect, ...], noise: dict | None = None, fit_reference=None) -> GapProblem:
    """Assemble the mode-table problem: rows, baseline reference fit on the free table, noise, folds.

    **Arguments:** ``tables`` — the free table first, then test tables;
    ``ring`` — starting ring (tyre.toml); ``effects`` — candidates;
    ``noise`` — optional user σ (``freq_hz`` [Hz], ``damping`` [-]);
    ``fit_reference`` — callable ``(problem, mask) -> theta`` fitting the
    baseline on the rows in ``mask`` (:func:`ringfit.gap.ranking.fit_baseline`).
    """
    rows, y, user_sigma, meta = build_rows(tables, geometry)
    is_freq = np.asarray(rows.is_freq) > 0
    n = np.asarray(rows.n)
    free_rows = meta["table"] == 0
    has_damping = bool(np.any(~is_freq))
    base = BASE if has_damping else BASE[:4]
    damping0 = float(np.median(y[~is_freq & free_rows])) if np.any(~is_freq & free_rows) else ring.damping_ratio
    ring = ring.replace(damping_ratio=damping0)
    base_values = np.array([getattr(ring, k) for k in base], dtype=np.float64)

    usable, dropped = [], {}
    for e in effects:
        mask = e.modal_mask(rows)
        if mask is None:
            dropped[e.name] = "does not act on mode tables"
        elif not np.any(mask):
            dropped[e.name] = "no row of these mode tables is affected (e.g. no loaded/spinning table, no damping)"
        else:
            usable.append(e)
    usable = tuple(usable)
    sizes = tuple(len(e.params_for("modes")) for e in usable)
    data = ModalData(rows=pad_rows(rows), ring=ring, geometry=geometry)
    m = len(y)
    n_theta = len(base) + sum(sizes)
    static = dict(effects=usable, base=base, sizes=sizes)

    # provisional σ: user's, else 0.5 % of f and 20 % of ζ0 — only to fit the reference baseline
    sigma = np.where(is_freq, 0.005 * y, 0.2 * damping0)
    sigma = np.where(np.isfinite(user_sigma), user_sigma, sigma)
    problem = GapProblem(
        domain="modes", data_files=[], y=y, sigma=sigma, unit="Hz", scale=np.ones_like(y),
        folds=np.zeros(len(y), dtype=int), fold_kind="leave-modes-out", labels=meta, base=base,
        base_values=base_values, base_prior_sd=np.full(len(base), BASE_PRIOR_SD), effects=usable,
        data=data, noise_method="", baseline_model="eq18-free",
        not_applicable=dropped, meta={"reference_mask": free_rows, "block": 1,
                                      "tangents": min(n_theta, len(base) + MAX_CHAIN_PARAMETERS),
                                      "padded_rows": int(data.rows.n.shape[0])},
        predictor=ModalPredictor(**static),
    )
    if fit_reference is not None:
        for _ in range(2):  # σ depends on the residual, the residual on σ (weights): two passes suffice
            theta = fit_reference(problem, free_rows)
            problem.base_values = theta[: len(base)]
            resid = y - predict(problem, problem.null_theta())
            problem.sigma, problem.noise_method = _noise(resid, y, is_freq, user_sigma, meta, n, noise, damping0)
    # relative scale for the RMS figures: Hz rows as they are; damping rows in σ units × median Hz σ
    fs = float(np.median(problem.sigma[is_freq]))
    problem.scale = np.where(is_freq, 1.0, fs / problem.sigma)
    problem.unit = "Hz" if not has_damping else "Hz (damping rows scaled to frequency-noise units)"
    # interleaved folds over the rows of each table (leave-modes-out)
    K = int(min(5, max(2, len(y) // 4)))
    order = np.lexsort((n, meta["table"]))
    folds = np.empty(len(y), dtype=int)
    folds[order] = np.arange(len(y)) % K
    problem.folds = folds
    problem.meta["files"] = [str(t.source).rsplit("/", 1)[-1] for t in tables]
    problem.data_files = problem.meta["files"]
    return problem


def _noise(resid, y, is_freq, user_sigma, meta, n, noise, damping0):
    noise = noise or {}
    seq = meta["sequence"]
    out = np.empty_like(y)
    notes = []
    for fam, mask, floor in (("freq_hz", is_freq, None), ("damping", ~is_freq, DAMPING_SIGMA_FLOOR)):
        if not np.any(mask):
            continue
        if fam in noise:
            s = float(noise[fam])
            notes.append(f"{fam}: user value {s:.3g}")
        else:
            idx = np.flatnonzero(mask)
            s, cnt = second_difference_sigma(resid[idx], [seq[i] for i in idx], n[idx])
            if not math.isfinite(s):
                s = 0.005 * float(np.median(y[mask])) if fam == "freq_hz" else 0.2 * damping0
                notes.append(f"{fam}: too few modes for second differences, default {s:.3g}")
            else:
                notes.append(f"{fam}: {s:.3g} from second differences along n of the baseline residual ({cnt} values)")
        if fam == "freq_hz":
            sig = np.maximum(np.maximum(s, FREQ_SIGMA_FLOOR_HZ), FREQ_SIGMA_FLOOR_REL * y)
        else:
            sig = np.full(len(y), max(s, floor, DAMPING_SIGMA_FLOOR_REL * float(np.median(y[mask]))))
        out[mask] = sig[mask]
    out = np.where(np.isfinite(user_sigma) & is_freq, np.maximum(user_sigma, 1e-9), out)
    if np.any(np.isfinite(user_sigma) & is_freq):
        notes.insert(0, "freq_std_hz column where given")
    return out, "; ".join(notes)
