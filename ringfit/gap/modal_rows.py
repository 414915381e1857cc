"""The rows of the mode-table diagnosis and the predictors that map an effect chain onto them (docs/physics.md §6).

:class:`ModalRows` (one row per measured mode: n, tag, branch, condition, patch, spin, frame, cavity line),
:class:`ModalData`, :class:`ModalPredictor` (frequencies, every effect's modal hook on the baseline ring) and
:class:`DampingPredictor` (ln ζ); rows padded to :data:`ROW_BUCKET` so one compiled refit serves tables of similar
size. Built by :mod:`ringfit.gap.modal`.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ringfit.gap.rolling_rows import JOINT
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.natural import natural_angular_frequencies


#: Relative floor of the measurement σ of a test-table row without ``freq_std_hz``: a table identified
#: on a loaded or rolling tyre (contact, rotation, a drifting operating point) is not measured better
#: than this, even when the free table it borrows its σ from was (a few free modes give a small and
#: uncertain scale).
TEST_SIGMA_FLOOR_REL = 1e-3
#: Rows are padded to a multiple of this (dummy rows, weight 0, dropped from every output), so one
#: compiled refit serves mode tables of similar size.
ROW_BUCKET = 32


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


def rows_module(rows, is_freq: float, cavity_hz: float, table_patch, rolling=None) -> ModalRows:
    """The row dicts (:func:`ringfit.gap.modal_conditions.table_rows`) as one :class:`ModalRows`: ``is_freq`` 1 for
    frequency rows, 0 for damping rows; ``cavity_hz`` where a row states none; ``table_patch`` per table;
    ``rolling``: the rolling tables' speeds and patch edges (``None``: none)."""
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


def rolling_tables(rows) -> tuple[int, ...]:
    """Indices of the tables with rows the rolling model predicts (assigned rows of ``rolling`` tables)."""
    return tuple(sorted({r["table"] for r in rows if r["joint"] > 0}))


__all__ = ["ModalRows", "ModalData", "ModalPredictor", "DampingPredictor", "rows_module", "pad_rows",
           "rolling_tables", "ROW_BUCKET", "TEST_SIGMA_FLOOR_REL"]
