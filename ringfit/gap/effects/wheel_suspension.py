"""``wheel_suspension`` — the rim, hub and fixture as a rigid body on the fixture's springs (docs/physics.md §6).

Modal data only: rows with n ≤ 1, and tagged rows of loaded tables, of tables whose sidecar says ``fixture: suspension``
(docs/formats.md §2; the body's mass, inertia, stiffnesses and dampers from the sidecar,
its defaults where left out). A bolted table (the default) is never touched: the
rim-fixed model exactly.

- rows of a loaded table tagged ``vert``/``extr`` (``hort``/``0``): the loaded
  ring of :mod:`ringfit.physics.loaded` bordered by the body's vertical (fore-aft)
  coordinate at the table's computed patch (:func:`ringfit.physics.wheel.loaded_wheel_angular_frequencies`);
  the change of the row's mode from the rim-fixed loaded mode is added (with ``ground_contact`` before
  it in a chain the sum is the bordered model exactly).
- other n = 1 rows: the two-body root of :func:`ringfit.physics.wheel.coupled_angular_frequency`
  on the prediction so far (belt mass 2πRρA, sidewall πR(k_w + k_v)); an untagged row
  takes the direction (vertical or fore-aft) whose line is nearer its measured frequency.
- n = 0 rows: the same with the belt's inertia 2πR³ρA and sidewall torsion 2πR³k_v.
- damping rows: the support's dampers add ``d y²/(2ω(m + M y²))`` to ζ.

Parameter ``compliance_scale`` s multiplies the fixture's compliances 1/k: null 0
(rigid fixture: rim fixed), fixed by the measured condition at 1 (the *computed*
candidate: the fixture as the sidecar states it), free in the *fitted* one (a
fixture softer or stiffer than stated is a finding too).
"""

import jax
import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.loaded import loaded_angular_frequencies
from ringfit.physics.wheel import (Wheel, belt_torsion, belt_translation, coupled_angular_frequency,
                                   loaded_wheel_angular_frequencies)


def _wheel_rows(rows):
    w = rows.wheel
    return w if w is not None else jnp.zeros((rows.n.shape[0], 9))


class WheelSuspension(Effect):
    """The ``wheel_suspension`` effect: the rim on its fixture's springs, n ≤ 1 rows (docs/physics.md §6)."""

    name = "wheel_suspension"
    summary = "the wheel moves on its suspension: the n = 1 (translation) and n = 0 (torsion) modes shift and split"
    applies_when = "no table has the sidecar key `fixture: suspension` (docs/formats.md §2): the wheel on its suspension acts only on the n <= 1 rows and the loaded rows of such a table"
    parameters = (
        Parameter("compliance_scale", "-", null=0.0, lo=0.0, hi=20.0, start=1.0, condition=1.0,
                  description="the fixture's compliances 1/k over those its sidecar states (0: rim fixed)"),
    )

    def modal_mask(self, rows):
        w = np.asarray(_wheel_rows(rows))
        n = np.asarray(rows.n)
        loaded = (np.asarray(rows.contact) != 0) & (np.asarray(rows.patch) > 0) & (n >= 1)
        return (w[:, 0] > 0) & (((n >= 0) & (n <= 1)) | loaded)

    def modal(self, values, omega, zeta, rows, ring, geometry):
        s = values[0]
        w = _wheel_rows(rows)
        mass, inertia = w[:, 1], w[:, 2]
        cz, cx, ct = s * w[:, 3], s * w[:, 4], s * w[:, 5]
        dz, dx, dt = w[:, 6], w[:, 7], w[:, 8]
        tagged = (rows.contact != 0) & (rows.patch > 0) & (rows.n >= 1)
        on = (w[:, 0] > 0) & (((rows.n >= 0) & (rows.n <= 1)) | tagged) & (s > 0)
        body = jnp.where(on, mass, 1.0)
        m_b, K1 = belt_translation(ring, geometry)
        I_b, K0 = belt_torsion(ring, geometry)
        # two-body roots on the prediction so far (docs/physics.md §6 wheel_suspension)
        oz, zz = coupled_angular_frequency(omega, m_b, K1, body, cz, dz)
        ox, zx = coupled_angular_frequency(omega, m_b, K1, body, cx, dx)
        ot, zt = coupled_angular_frequency(omega, I_b, K0, jnp.where(on, inertia, 1.0), ct, dt)
        f = 2.0 * jnp.pi * rows.freq_hz
        vertical = jnp.where(rows.contact == 1, True,
                             jnp.where(rows.contact == 2, False, jnp.abs(oz - f) <= jnp.abs(ox - f)))
        om1 = jnp.where(vertical, oz, ox)
        ze1 = jnp.where(vertical, zz, zx)

        # loaded tables: the bordered loaded ring at the computed patch, rows tagged by contact (any n:
        # the patch passes the body's motion on to the low extr modes)
        tables = rows.contact_tables
        k = jnp.clip(rows.n, 1, _HARMONICS).astype(jnp.int32) - 1

        def solve(_):
            shift = jnp.zeros_like(omega)
            for t in range(rows.table_patch.shape[0]) if tables is None else tables:
                sel = rows.table == t
                cnt = jnp.maximum(jnp.sum(sel), 1)
                wt = jnp.sum(jnp.where(sel[:, None], w, 0.0), axis=0) / cnt
                wheel = Wheel(jnp.where(wt[0] > 0, wt[1], 1.0), wt[2], s * wt[3], s * wt[4], s * wt[5])
                a = rows.table_patch[t]
                c1, s1 = loaded_wheel_angular_frequencies(ring, geometry, a, wheel, n_max=_HARMONICS)
                c0, s0 = loaded_angular_frequencies(ring, geometry, a, _HARMONICS)  # the rim-fixed loaded modes
                pick = jnp.where(rows.contact == 1, c1[k] - c0[k], s1[k] - s0[k])
                shift = jnp.where(sel & (wt[0] > 0), pick, shift)
            return shift

        # no eigen-solve without a loaded table, nor at the null (every refit without this effect)
        shift = (jnp.zeros_like(omega) if tables == () else
                 jax.lax.cond(s > 0, solve, lambda _: jnp.zeros_like(omega), None))
        om1 = jnp.where(tagged, omega + shift, om1)

        new = jnp.where(rows.n == 0, ot, om1)
        dzeta = jnp.where(rows.n == 0, zt, ze1)
        freq = rows.is_freq > 0
        omega_out = jnp.where(on & freq, new, omega)
        zeta_out = jnp.where(on & ~freq, zeta + dzeta, zeta)
        return omega_out, zeta_out


#: Harmonics of the bordered loaded basis (n = 1 converges fast: 20 is within 0.01 Hz of 40).
_HARMONICS = 20

EFFECT = register(WheelSuspension())
