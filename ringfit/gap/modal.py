"""The mode-table side of the gap diagnosis (docs/physics.md §2.1, §3, §6; docs/formats.md §2, §5, §6).

Two problems, one per family of observations, because frequencies and damping
ratios are measured on different scales and a damping residual must never
decide a structural verdict (only an effect that models damping,
``wave_damping``, is tried on it):

**Frequencies** — every structural row of every table (``free.modes.csv``, the
reference state, first; then the test tables: loaded, rolling, spinning).

- *Baseline from the reference state only.* The ring (ρA, EI, k_w, k_v) is
  :func:`ringfit.fit.least_squares.fit_natural_frequencies` on ``free.modes.csv``
  — ``ringfit fit``'s engine, model, prior (the physical EI prior) and weights
  (``freq_std_hz`` where given, else the relative σ estimated below: the same
  fit as ``ringfit fit --default-std σ``). Test tables never refit it: their
  rows see the ring through a stop-gradient, so in every refit the ring answers
  to the free table (and its prior) alone, while an effect's parameters answer
  to every row. With no effect, test rows are pure predictions (held out by
  construction); the free rows are held out by leave-modes-out refits of the ring.
- *Effects fixed by the measured condition are computed, not fitted*: the contact
  patch of a loaded or rolling table from its ``load_n`` through the rolling
  model's static contact solve (:func:`ringfit.physics.contact.solve_rolling` at
  Ω = 0 with the fitted ring and ``k_tread`` from the tyre file — or, when it has
  none, 19 MN/m² with a log-normal σ of :data:`K_TREAD_PRIOR_SD`, whose effect on
  the patch is reported); the wheel speed of a spinning table from ``rotation_hz``
  or ``speed_kmh``. Such a candidate (variant ``computed``) is a prediction with no
  free parameter. The same effect with its parameter free (variant ``fitted``:
  patch scale, speed gain) is tried beside it; both are reported.
- *Loaded-tyre tags*: rows tagged ``extr``/``vert`` take the contact-symmetric
  (cos-type) mode of their n, ``0``/``hort`` the contact-antisymmetric (sin-type)
  one (:mod:`ringfit.physics.loaded`); rows without n are matched by frequency to
  the nearest mode of the model their condition computes (eq. 18, the loaded modes
  with the computed patch, eq. 25/26 at the condition's speed), and the match is
  stated (``labels["matched"]``).
- *Noise*: a relative σ per table. The free table's from its reference fit:
  ``freq_std_hz`` where given; else the larger of two robust scales of the fit's
  relative residual — second differences along n, ``1.4826·median|Δ²r|/√6`` (white
  noise gives Var Δ²r = 6σ²; one outlying row moves the median little) and the MAD
  ``1.4826·median|r − median r|·√(m/(m−4))`` (the misfit eq. 18 leaves on a real
  tyre, which second differences would cancel, is part of what a prediction of
  another state must be judged against) — floored at
  :data:`FREQ_SIGMA_FLOOR_REL` and :data:`FREQ_SIGMA_FLOOR_HZ`; raised to the
  identification spread ``|f_a − f_b|/√2`` (robust RMS over matched n) when the
  folder holds a second table of the reference state (e.g. SSI and FRF of the same
  free tyre). A test row's σ adds, in quadrature, the reference fit's prediction
  uncertainty at that row (its covariance propagated through eq. 18) and the test
  table's own measurement σ (``freq_std_hz`` where given, else the free table's, at least
  :data:`TEST_SIGMA_FLOOR_REL` of the frequency).
- *Heavy tails*: test rows enter refits and statistics through the Huber function
  (``ψ(z) = z`` for ``|z| ≤`` :data:`HUBER`, ``sign(z)·√(2c|z| − c²)`` beyond), so
  one outlying row counts linearly, not quadratically; rows with held-out
  ``|z| >`` :data:`OUTLIER_Z` are named outliers.

**Damping** — every row with ``damping_pct``, as ``ln ζ`` (damping is scattered
tenfold: logarithms make a factor the same size everywhere). Baseline: one level
ζ0 per table (identification methods disagree on damping far more than on
frequency; each table has its own level), Huber on every row. Noise per table:
second differences of ``ln ζ`` along n (robust), floored at
:data:`DAMPING_SIGMA_FLOOR`; a row whose own ``damping_std_pct`` (``ringfit ssi``'s
jackknife σ) is wider in ``ln ζ`` (δζ/ζ) takes that. Effects: those whose modal hook changes ζ
(``wave_damping``, using each row's measured frequency).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ringfit.errors import InputError
from ringfit.gap.effects.base import Effect
from ringfit.gap.problem import UNSET, GapProblem, ProblemMeta
from ringfit.gap.rolling_rows import JOINT, assign_rolling_rows, joint_for
from ringfit.io.modes import ModeTable
from ringfit.params import RingParams, TyreGeometry
from ringfit._cache import jit
from ringfit.physics.natural import (cavity_frequency_jit, natural_angular_frequencies,
                                     natural_frequencies_jit)
from ringfit.units import KMH

FREQ_SIGMA_FLOOR_HZ = 0.02
#: Relative floor: a frequency is rarely identified better than this.
FREQ_SIGMA_FLOOR_REL = 2e-4
#: Relative floor of the measurement σ of a test-table row without ``freq_std_hz``: a table identified
#: on a loaded or rolling tyre (contact, rotation, a drifting operating point) is not measured better
#: than this, even when the free table it borrows its σ from was (a few free modes give a small and
#: uncertain scale).
TEST_SIGMA_FLOOR_REL = 1e-3
#: Floor of the damping noise (ln ζ): modal damping is rarely identified better than 10 %.
DAMPING_SIGMA_FLOOR = 0.10
#: Huber threshold on standardised residuals of test rows (refits and statistics).
HUBER = 2.0
#: A row whose held-out standardised residual exceeds this is named an outlier.
OUTLIER_Z = 3.0
#: log-normal σ of k_trd when the tyre file gives none (its median is then the Table 9 value).
K_TREAD_PRIOR_SD = 0.5
#: log σ of k_trd when the tyre file gives it (a fitted value: ``ringfit fit-rolling``'s typical error).
K_TREAD_FITTED_SD = 0.1
DEFAULT_K_TREAD = 19e6
#: Baseline parameters of the frequency side: the ring of eq. 18 (``ringfit fit``'s default free set).
BASE = ("rho_a", "ei", "kw", "kv")
#: Effect parameters a chain frees at most besides the baseline (the refit's padded free-set size).
MAX_CHAIN_PARAMETERS = 4
#: Rows are padded to a multiple of this (dummy rows, weight 0, dropped from every output), so one
#: compiled refit serves mode tables of similar size.
ROW_BUCKET = 32
#: Rows of a line problem (the random-line null, :func:`line_problem`) are padded to a multiple of this.
LINE_BUCKET = 128
#: Largest n a row without n is matched to.
MATCH_N_MAX = 15


class ModalRows(eqx.Module):
    """The observations of a mode-table diagnosis as arrays, shape ``(m,)`` each.

    - ``n``: circumferential index (float; matched by frequency where the table gave none);
      ``is_freq``: 1 frequency row, 0 damping row.
    - ``contact``: 0 untagged / free, 1 cosine type (``extr``, ``vert``), 2 sine type (``0``, ``hort``).
    - ``spin``: wheel speed Ω of the table's condition [rad/s] (0 = static).
    - ``branch``: +1 backward, −1 forward, 0 none; ``fixed_frame``: 1 fixed observer, 0 co-rotating.
    - ``cavity_hz``: uncoupled cavity frequency the row's ring mode meets (``cavity_mode``) [Hz], per row:
      the unloaded line f_a, on a loaded table the fore-aft (``hort``/``0`` rows) or vertical
      (``vert``/``extr``) line of n = 1 (:mod:`ringfit.physics.cavity`); 0 where the table's tyre
      has no air (``pressure_bar`` = 0).
    - ``reference``: 1 for rows of ``free.modes.csv`` (the ring answers to them only).
    - ``patch``: contact half-angle computed from the table's load [rad] (0: no contact / unknown).
    - ``freq_hz``: the row's measured frequency [Hz] (damping rows: their mode's).
    - ``table``: index of the row's table (0 = free table); ``table_patch``: ``(T,)`` the
      computed contact half-angle of each table [rad] (0: none).
    - ``joint``: 1 for a row of a ``rolling`` table assigned to a mode of the rolling model
      (:mod:`ringfit.gap.rolling_rows`), ``mode_index`` its mode (int) and ``line_k`` its
      sensor line k; ``table_omega``, ``table_leading``, ``table_trailing``: ``(T,)`` Ω [rad/s]
      and the contact arc edges [rad] of each rolling table (0 for the others).
    - ``contact_tables`` (static): the tables whose ``table_patch`` > 0.
    """

    n: jax.Array
    is_freq: jax.Array
    contact: jax.Array
    spin: jax.Array
    branch: jax.Array
    fixed_frame: jax.Array
    cavity_hz: jax.Array
    reference: jax.Array
    patch: jax.Array
    freq_hz: jax.Array
    table: jax.Array
    table_patch: jax.Array
    # rolling tables (None where a caller builds rows without them: no rolling model)
    joint: jax.Array | None = None
    mode_index: jax.Array | None = None
    line_k: jax.Array | None = None
    table_omega: jax.Array | None = None
    table_leading: jax.Array | None = None
    table_trailing: jax.Array | None = None
    #: indices of the tables with a contact patch (static: effects solve only these tables' contact
    #: problems); None = every table
    contact_tables: tuple | None = eqx.field(static=True, default=None)

    def joint_rows(self) -> np.ndarray:
        """``(m,)`` bool (NumPy): rows the rolling model predicts (:mod:`ringfit.gap.rolling_rows`), for the
        effects' masks; all False for rows built without rolling tables."""
        return np.zeros(np.shape(self.n), dtype=bool) if self.joint is None else np.asarray(self.joint) > 0
    #: ``(m, 9)`` the wheel body of the row's table (``fixture: suspension``, docs/formats.md §2):
    #: on (1/0), m_w, I_w, compliances 1/k_z, 1/k_x, 1/k_θ, dampers c_z, c_x, c_θ (SI; all 0 when bolted)
    wheel: jax.Array | None = None


class ModalData(eqx.Module):
    """What a modal gap problem's model reads: the test rows, the reference ring and the geometry."""

    rows: ModalRows
    ring: RingParams
    geometry: TyreGeometry


def _apply_effects(theta, ring, geometry, rows, effects, sizes, i0, joint=None):
    """ω, ζ of every row: eq. 18, then each effect in turn; rolling rows with both effects of
    :data:`ringfit.gap.rolling_rows.JOINT` on take the joint rolling model instead of the two
    (``joint``: :class:`~ringfit.gap.rolling_rows.RollingJoint`, docs/physics.md §3.7, §6)."""
    omega0 = natural_angular_frequencies(ring, geometry, rows.n)
    omega = omega0
    zeta = jnp.zeros_like(omega) + ring.damping_ratio
    on = None if joint is None else joint.active(theta, rows)
    i = i0
    for effect, k in zip(effects, sizes):
        new, zeta = effect.modal(theta[i : i + k], omega, zeta, rows, ring, geometry)
        omega = jnp.where(on, omega, new) if on is not None and effect.name in JOINT else new
        i += k
    if on is not None:
        omega = jnp.where(on, omega + joint.angular_frequencies(theta, ring, geometry, rows) - omega0, omega)
    return omega, zeta


class ModalPredictor(eqx.Module):
    """Frequencies [Hz] of every (padded) row: eq. 18 of the ring ``theta[:4]`` with the effects applied.

    Rows of the reference table see the ring itself, every other row a stop-gradient
    copy: in a refit the ring answers to the free table alone (module docstring).
    ``joint``: the rolling model's prediction of rolling rows (:mod:`ringfit.gap.rolling_rows`),
    ``None`` without rolling tables or without both ``ground_contact`` and ``rotation``.
    """

    effects: tuple = eqx.field(static=True)
    base: tuple = eqx.field(static=True)
    sizes: tuple = eqx.field(static=True)
    joint: object = eqx.field(static=True, default=None)

    def __call__(self, theta, data: ModalData):
        ring = data.ring.replace(**{k: theta[i] for i, k in enumerate(self.base)})
        frozen = jax.lax.stop_gradient(ring)
        nb = len(self.base)
        # reference rows never touch the ground (the free table has no patch): their pass solves no
        # contact problem
        live_rows = dataclasses.replace(data.rows, contact_tables=())
        live, _ = _apply_effects(theta, ring, data.geometry, live_rows, self.effects, self.sizes, nb)
        test, _ = _apply_effects(theta, frozen, data.geometry, data.rows, self.effects, self.sizes, nb, self.joint)
        return jnp.where(data.rows.reference > 0, live, test) / (2.0 * jnp.pi)


class DampingPredictor(eqx.Module):
    """``ln ζ`` of every (padded) damping row: one level per table (``theta[:T]``) with the effects applied.

    Effects see each row's measured frequency as ω (the damping side needs no ring model).
    """

    effects: tuple = eqx.field(static=True)
    base: tuple = eqx.field(static=True)
    sizes: tuple = eqx.field(static=True)

    def __call__(self, theta, data: ModalData):
        rows = data.rows
        levels = jnp.stack([theta[i] for i in range(len(self.base))])
        zeta = levels[rows.table]
        omega = 2.0 * jnp.pi * rows.freq_hz
        i = len(self.base)
        for effect, k in zip(self.effects, self.sizes):
            omega, zeta = effect.modal(theta[i : i + k], omega, zeta, rows, data.ring, data.geometry)
            i += k
        return jnp.log(jnp.clip(zeta, 1e-6))


def table_label(table: ModeTable, index: int) -> str:
    """A short name for a table: its state (and speed, load) for the free table, else its file name."""
    c = table.condition
    state = table.state
    parts = [state]
    sp = c.get("speed_kmh") or 0
    if sp:
        parts.append(f"{sp:g} km/h")
    if state != "free" and c.get("load_n"):
        parts.append(f"{c['load_n']:g} N")
    name = str(table.source).rsplit("/", 1)[-1].removesuffix(".modes.csv")
    return " ".join(parts) if index == 0 else f"{name} ({' '.join(parts)})"


def spin_of(table: ModeTable, outer_radius: float) -> float:
    """Ω [rad/s] of a table's condition: ``rotation_hz`` or ``speed_kmh``/R_out (0 if static)."""
    c = table.condition
    if c.get("rotation_hz"):
        return 2.0 * math.pi * float(c["rotation_hz"])
    if c.get("speed_kmh"):
        return float(c["speed_kmh"]) * KMH / outer_radius
    return 0.0


def _is_reference_state(table: ModeTable) -> bool:
    c = table.condition
    # a free tyre on a suspended wheel is another state (its n <= 1 modes move: wheel_suspension)
    return (table.state == "free" and not float(c.get("speed_kmh") or 0) and not float(c.get("rotation_hz") or 0)
            and c.get("fixture", "bolted") == "bolted")


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


def contact_patch(ring: RingParams, geometry: TyreGeometry, load_n: float, drum_diameter_m=None,
                  k_tread_sd: float = K_TREAD_FITTED_SD) -> tuple[float, float]:
    """Contact half-angle [rad] of the standing tyre at ``load_n`` and its σ from the k_trd uncertainty.

    The static contact solve of the rolling model (docs/physics.md §4.3–4.4, Ω = 0): the
    half-angle is half the patch between its edges; σ from k_trd·e^{±k_tread_sd}.
    """
    a, sa, _ = _static_contact(ring, geometry, load_n, drum_diameter_m, k_tread_sd)
    return a, sa


def _static_contact(ring, geometry, load_n, drum_diameter_m, k_tread_sd):
    """:func:`contact_patch`'s ``(a, σ_a)`` and the nominal static solution (the loaded cavity's split uses it)."""
    from ringfit.physics.contact import ContactSolver, patch_edges, solve_rolling_jit
    from ringfit.physics.operating import OperatingPoint, road_from_drum_diameter

    road = road_from_drum_diameter(drum_diameter_m)
    out, sols = [], []
    for factor in (1.0, math.exp(-k_tread_sd), math.exp(k_tread_sd)):
        r = ring.replace(k_tread=float(ring.k_tread) * factor)
        sol = solve_rolling_jit(r, geometry, OperatingPoint(0.0, float(load_n), road), solver=ContactSolver())
        lead, trail = (float(x) for x in patch_edges(sol))
        out.append(0.5 * (trail - lead))
        sols.append(sol)
    return out[0], 0.5 * abs(out[2] - out[1]), sols[0]


@jit
def _loaded_cavity_lines(f_a, split):
    """The loaded cavity's pair at rest (fore-aft, vertical) [Hz] (docs/physics.md §6), in one compiled program."""
    from ringfit.physics.cavity import loaded_cavity_lines

    return loaded_cavity_lines(f_a, split)


@jit
def _cavity_split(solution, geometry):
    """W_2/h_c of a static contact solution (docs/physics.md §6 cavity_mode), in one compiled program."""
    from ringfit.physics.cavity import cavity_height, deflection_cos2

    return deflection_cos2(solution) / cavity_height(geometry)


def wheel_row(condition: dict, source: str = "<condition>") -> list[float]:
    """The 9 numbers of :attr:`ModalRows.wheel` from a table's sidecar (zeros for a bolted rim)."""
    from ringfit.io.modes import wheel_of

    w = wheel_of(condition, source=source)
    if w is None:
        return [0.0] * 9
    inv = [1.0 / w[k] for k in ("k_vertical", "k_fore_aft", "k_torsion")]
    return [1.0, w["mass"], w["inertia"], *inv, w["c_vertical"], w["c_fore_aft"], w["c_torsion"]]


def _table_rows(tables, geometry, patches, spins, cavity_split=None):
    """Per structural row: dict of its attributes (before n-matching).

    ``cavity_split``: per table W_2/h_c of the loaded cavity (docs/physics.md §6 cavity_mode), or None."""
    cavity = [float(f) for t in tables for f, k in zip(t.freq_hz, t.kind) if k == "acoustic"]
    f_a = cavity[0] if cavity else float(cavity_frequency_jit(1))  # one program, not one per operation
    rows = []
    damping_std = [t.extra_floats("damping_std_pct") for t in tables]
    wheels = [wheel_row(t.condition, str(t.source)) for t in tables]
    for ti, t in enumerate(tables):
        fixed = t.condition.get("frame", "rotating" if spins[ti] > 0 else "fixed") == "fixed"
        tl = table_label(t, ti)
        for i in range(len(t)):
            if t.kind[i] != "structural":
                continue
            tag, branch = str(t.tag[i]), str(t.branch[i])
            contact = 0
            if t.state != "free":
                contact = 1 if tag in ("extr", "vert") else 2 if tag in ("0", "hort") else 0
            rows.append(dict(
                table=ti, i=i, tlabel=tl, n=int(t.n[i]), tag=tag, branch=branch, contact=contact,
                spin=spins[ti], fixed=fixed, patch=patches[ti][0] if contact else 0.0,
                freq=float(t.freq_hz[i]), std=float(t.freq_std_hz[i]), damping=float(t.damping_pct[i]),
                damping_std=damping_std[ti][i],
                reference=ti == 0, a=int(t.a[i]), joint=0.0, mode_index=0, line_k=0.0, wave="",
                wheel=wheels[ti], cavity=_row_cavity(t, f_a, contact, int(t.n[i]),
                                                     None if cavity_split is None else cavity_split[ti]),
            ))
    return rows, f_a


def _row_cavity(table: ModeTable, f_a: float, contact: int, n: int, split) -> float:
    """The cavity line a row's ring mode meets [Hz] (:attr:`ModalRows.cavity_hz`)."""
    p = table.condition.get("pressure_bar")
    if p is not None and float(p) == 0.0:
        return 0.0  # no air in the cavity: cavity_mode does not act on this table
    if split is None or n != 1 or not contact:
        return f_a

    # the loaded cavity's pair at rest: fore-aft f_a sqrt(1 + e), vertical f_a sqrt(1 - e) (docs/physics.md §6);
    # one compiled program, not one per operation (a cold process compiles each)
    fore_aft, vertical = _loaded_cavity_lines(f_a, split)
    return float(vertical if contact == 1 else fore_aft)


def _rows_module(rows, is_freq: float, cavity_hz: float, table_patch, rolling=None) -> ModalRows:
    def col(key, dtype=np.float64):
        return np.asarray([r[key] for r in rows], dtype=dtype)

    def per_table(field):
        return np.asarray(np.zeros(len(table_patch)) if rolling is None else getattr(rolling, field),
                           dtype=np.float64)

    return ModalRows(
        n=col("n"), is_freq=np.full(len(rows), is_freq), contact=col("contact", np.int32), spin=col("spin"),
        # a rolling row without a branch: the wave of eq. 25/26 it was matched to (rotation alone)
        branch=np.asarray([{"backward": 1.0, "forward": -1.0}.get(r["branch"] or r.get("wave", ""), 0.0)
                            for r in rows]),
        fixed_frame=np.asarray([1.0 if r["fixed"] else 0.0 for r in rows]),
        cavity_hz=np.asarray([r.get("cavity", cavity_hz) for r in rows], dtype=np.float64),
        reference=np.asarray([1.0 if r["reference"] else 0.0 for r in rows]), patch=col("patch"),
        freq_hz=col("freq"), table=col("table", np.int32),
        table_patch=np.asarray(np.asarray(table_patch, dtype=np.float64)),
        joint=col("joint"), mode_index=col("mode_index", np.int32), line_k=col("line_k"),
        table_omega=per_table("omega"), table_leading=per_table("leading"), table_trailing=per_table("trailing"),
        contact_tables=tuple(int(i) for i, a in enumerate(np.asarray(table_patch, dtype=np.float64)) if a > 0),
        wheel=np.asarray([r.get("wheel", [0.0] * 9) for r in rows], dtype=np.float64).reshape(len(rows), 9),
    )


def pad_rows(rows: ModalRows, bucket: int = ROW_BUCKET) -> ModalRows:
    """``rows`` padded with dummy rows (n = 2, untagged, static, reference) to a multiple of ``bucket``."""
    m = int(rows.n.shape[0])
    extra = (-m) % bucket
    if extra == 0:
        return rows
    fill = {"n": 2.0, "is_freq": rows.is_freq[0] if m else 1.0, "contact": 0, "spin": 0.0, "branch": 0.0,
            "fixed_frame": 0.0, "reference": 1.0, "patch": 0.0, "freq_hz": 100.0, "table": 0, "joint": 0.0,
            "mode_index": 0, "line_k": 0.0}
    def grow(k, v):
        col = getattr(rows, k)
        return None if col is None else np.concatenate([col, np.full(extra, v, dtype=col.dtype)])

    cav = rows.cavity_hz
    cav = cav if np.ndim(cav) == 0 else np.concatenate([cav, np.full(extra, cav[0] if m else 0.0)])
    return ModalRows(**{k: grow(k, v) for k, v in fill.items()}, cavity_hz=cav, table_patch=rows.table_patch,
                     table_omega=rows.table_omega, table_leading=rows.table_leading,
                     table_trailing=rows.table_trailing, contact_tables=rows.contact_tables,
                     wheel=None if rows.wheel is None else np.concatenate([rows.wheel, np.zeros((extra, 9))]))


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


def _ambiguity(problem: GapProblem, rows, choice):
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


def _match_missing_n(rows, ring, geometry):
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

    fit_natural_frequencies = functools.partial(_fit, at_initial=fixed)

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
    """Relative σ of one identification from two tables of the reference state: RMS(Δf/f)/√2 over matched n."""
    ref = tables[ref_index]
    for t in tables[1:]:
        if not _is_reference_state(t):
            continue
        d = []
        for n in set(ref.n[(ref.kind == "structural") & (ref.n >= 0)].tolist()):
            a = ref.freq_hz[(ref.n == n) & (ref.kind == "structural")]
            b = t.freq_hz[(t.n == n) & (t.kind == "structural")]
            if a.size == 1 and b.size == 1:
                d.append((b[0] - a[0]) / a[0])
        if len(d) >= 3:
            d = np.asarray(d)
            spread = 1.4826 * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(2.0)
            rms = float(np.sqrt(np.mean(d**2))) / math.sqrt(2.0)
            s = max(spread, min(rms, 2.0 * spread))
            name = str(t.source).rsplit("/", 1)[-1]
            return s, f"identification spread {s:.3g} (relative) between free.modes.csv and {name}"
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
            a, sa, sol = _static_contact(ring_ref, geometry, float(load), t.condition.get("drum_diameter_m"), kt_sd)
            patches.append((a, sa))
            # the loaded cavity's split W_2/h_c (docs/physics.md §6) from the same static solve
            splits.append(float(_cavity_split(sol, geometry)) if t.state == "loaded" else None)
            conditions.append(f"patch half-angle {math.degrees(a):.2f} ± {math.degrees(sa):.2f} deg from "
                              f"load_n = {float(load):g} N (k_trd {ring_ref.k_tread:.3g} N/m^2"
                              f"{'' if has_kt else ', tyre.toml has none: its prior'})")
        else:
            patches.append((0.0, 0.0))
            conditions.append("")
            splits.append(None)
    for ti, t in enumerate(tables):  # the wheel on its suspension (docs/physics.md §6 wheel_suspension)
        note = _wheel_note(t)
        if note:
            conditions[ti] = "; ".join(x for x in (conditions[ti], note) if x)
    rows, cavity_hz = _table_rows(tables, geometry, patches, spins, splits)
    for r in rows:  # rows whose n (and type) the table leaves to matching by frequency: the random-line null's rows
        r["matchable"] = (not r["reference"]) and r["n"] < 0
        # the labels as the table gave them (the assignment of a rolling table may override them: the random-line
        # null re-assigns such rows with these labels and their penalties, calibration.py)
        r["label_n"], r["label_contact"], r["label_patch"] = r["n"], r["contact"], r["patch"]
    rolling, rolling_notes, rolling_records, choice = assign_rolling_rows(tables, rows, ring_ref, geometry, patches)
    if rolling is not None:
        for ti, note in rolling.notes.items():
            conditions[ti] = "; ".join(x for x in (conditions[ti], note) if x)
    match_notes, matched_lines = _match_missing_n(rows, ring_ref, geometry)
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
    _ambiguity(problems[0], rows, choice)
    meta = problems[0].meta
    meta.table_names, meta.patches = [table_label(t, i) for i, t in enumerate(tables)], patches
    meta.spins, meta.outer_radius_m = spins, float(geometry.outer_radius)
    damp = [r for r in rows if math.isfinite(r["damping"]) and r["damping"] > 0]
    if len(damp) >= 4:
        problems.append(_damping_problem(tables, damp, cavity_hz, geometry, ring_ref, effects, noise))
    return problems


def _wheel_note(table: ModeTable) -> str:
    """One line on the table's fixture (empty for a bolted rim); a ``WARNING`` where defaults stand in."""
    import warnings

    from ringfit.io.modes import wheel_of

    w = wheel_of(table.condition, source=str(table.source))
    if w is None:
        return ""
    note = (f"fixture suspension: wheel {w['mass']:g} kg, {w['inertia']:g} kg m^2 on k_z {w['k_vertical']:.3g}, "
            f"k_x {w['k_fore_aft']:.3g} N/m, k_theta {w['k_torsion']:.3g} N m/rad")
    if w["defaults"]:
        msg = (f"{table.source}: fixture 'suspension' without {', '.join(w['defaults'])}: the defaults of "
               "docs/formats.md §2 stand in (the computed wheel_suspension candidate uses them)")
        warnings.warn(msg, stacklevel=2)
        note += f" (defaults for {', '.join(w['defaults'])})"
    return note


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
    mrows = _rows_module(rows, 1.0, cavity_hz, [p[0] for p in patches], rolling)
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


def rolling_tables(rows) -> tuple[int, ...]:
    """Indices of the tables with rows the rolling model predicts (assigned rows of ``rolling`` tables)."""
    return tuple(sorted({r["table"] for r in rows if r["joint"] > 0}))


def _condition_sd(patches) -> dict:
    """σ of the condition-fixed effect parameters: the patch scale's from the k_trd uncertainty (RMS over tables)."""
    rel = [sa / a for a, sa in patches if a > 0]
    return {"ground_contact": {"patch_scale": float(np.sqrt(np.mean(np.square(rel))))}} if rel else {}


def _damping_problem(tables, rows, cavity_hz, geometry, ring_ref, effects, noise) -> GapProblem:
    m = len(rows)
    table_ids = sorted({r["table"] for r in rows})
    remap = {t: i for i, t in enumerate(table_ids)}
    mrows = _rows_module([dict(r, table=remap[r["table"]]) for r in rows], 0.0, cavity_hz, np.zeros(len(table_ids)))
    y = np.log(np.array([r["damping"] for r in rows]) / 100.0)
    n = np.array([r["n"] for r in rows], dtype=float)
    tab = np.array([remap[r["table"]] for r in rows])
    usable, dropped = _usable(effects, mrows, "no damping rows")
    sizes = tuple(len(e.params_for("modes")) for e in usable)
    base = tuple(f"damping_ratio:{table_label(tables[t], t)}" for t in table_ids)
    levels = np.array([math.exp(float(np.median(y[tab == i]))) for i in range(len(table_ids))])
    sigma = np.empty(m)
    notes = []
    user = noise.get("damping")
    for i, t in enumerate(table_ids):
        sel = tab == i
        if user is not None:
            s = float(user)
            notes.append(f"{table_label(tables[t], t)}: user value {s:.3g}")
        else:
            s, cnt = second_difference_sigma(y[sel] - np.median(y[sel]), np.zeros(int(sel.sum())), n[sel])
            if not math.isfinite(s):
                s = 2 * DAMPING_SIGMA_FLOOR
                notes.append(f"{table_label(tables[t], t)}: too few modes for second differences, {s:.3g}")
            else:
                notes.append(f"{table_label(tables[t], t)}: {max(s, DAMPING_SIGMA_FLOOR):.3g} from second "
                             f"differences of ln(damping) along n ({cnt} values)")
        sigma[sel] = max(s, DAMPING_SIGMA_FLOOR)
    # a row's own identification σ (damping_std_pct, e.g. from `ringfit ssi`) in ln ζ (δζ/ζ): it can only
    # widen the row's σ (the per-table scale already holds the identification noise of a typical row)
    own = np.array([r.get("damping_std", math.nan) / r["damping"] for r in rows])
    wider = np.isfinite(own) & (own > sigma)
    if user is None and wider.any():
        sigma[wider] = own[wider]
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
                         files=[str(tables[t].source).rsplit("/", 1)[-1] for t in table_ids], tables=table_ids),
        predictor=DampingPredictor(effects=usable, base=base, sizes=sizes),
        robust=np.ones(m, dtype=bool), huber=HUBER,
    )
    return problem


__all__ = ["build_modal_problems", "ModalRows", "ModalData", "ModalPredictor", "DampingPredictor",
           "second_difference_sigma", "contact_patch", "spin_of", "table_label", "HUBER", "OUTLIER_Z"]


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
    mrows = _rows_module(every, 1.0, L.cavity_hz, L.table_patch, L.rolling)
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
