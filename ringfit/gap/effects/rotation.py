"""``rotation`` — centrifugal stiffening and Coriolis splitting of a spinning ring (docs/physics.md §3.2–3.3, §6).

Modal data: rows of a spinning table (``rotation_hz`` or ``speed_kmh`` > 0)
with a ``branch`` (backward / forward) follow eq. 25 (co-rotating frame) or
eq. 26 (fixed frame) at Ω' = g·Ω, where Ω is the condition's wheel speed and g
the parameter ``speed_gain`` (null 0: the static eq. 18, the baseline), fixed at 1
by the measured condition in the *computed* candidate (Ω from ``rotation_hz`` or
``speed_kmh``: a prediction with no free parameter), free in the *fitted* one. The formulas act on the
current ω of each row, so the effect composes with others.

Rolling profiles: the centrifugal share not carried as belt tension,
``1 − χ`` (null 0 = χ = 1, the baseline), through the (1−χ)ρAΩ² F_n term of
the per-harmonic operator (docs/physics.md §4.2): profiles divided by Ω² then stop
collapsing across speeds.
"""

import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.physics import natural
from ringfit.gap.effects.base import Effect, Parameter


def rotating_from_static(omega_static, n, spin, backward, fixed_frame):
    """|ω| [rad/s] of each row from its static ω_fn: eq. 25, plus the Doppler shift of eq. 26 in the fixed frame.

    Uses :func:`ringfit.physics.natural.rotating_from_static` (docs/physics.md §3.2–3.3);
    ``spin`` Ω [rad/s]; ``backward`` bool selects ω_n1 (else ω_n2); ``fixed_frame`` bool.
    """
    waves = natural.rotating_from_static(omega_static, n, spin)
    rot = jnp.where(backward, waves[..., 0], waves[..., 1])
    return jnp.abs(jnp.where(fixed_frame, rot - n * spin, rot))


class Rotation(Effect):
    """The ``rotation`` effect: a spinning ring: Coriolis splitting of backward/forward waves and centrifugal tension.

    This module's docstring has its model and parameters.
    """

    name = "rotation"
    summary = "a spinning ring: Coriolis splitting of backward/forward waves and centrifugal tension"
    applies_when = "no spinning table (sidecar `rotation_hz` or `speed_kmh` > 0) with a row that has a `branch` or a line of the rolling model"
    parameters = (
        Parameter("speed_gain", "-", null=0.0, lo=0.0, hi=2.0, start=1.0, condition=1.0,
                  description="wheel speed seen by the modes / the table's wheel speed (eq. 25/26)",
                  # the modes see the wheel's speed to within the rolling radius and the belt's slip: 0.5 … 1.5
                  plausible=(0.5, 1.5)),
    )
    profile_parameters = (
        Parameter("chi_deficit", "-", null=0.0, lo=0.0, hi=1.0, start=0.3,
                  description="1 - chi: centrifugal load not carried as belt tension"),
    )

    def modal_mask(self, rows):
        # rows with a wave, and rows the rolling model predicts (with ground_contact: docs/physics.md §3.7)
        joint = rows.joint_rows()
        return (np.asarray(rows.spin) > 0) & ((np.asarray(rows.branch) != 0) | joint) & (np.asarray(rows.is_freq) > 0)

    def modal(self, values, omega, zeta, rows, ring, geometry):
        spin = values[0] * rows.spin
        new = rotating_from_static(omega, rows.n, spin, rows.branch > 0, rows.fixed_frame > 0)
        use = (rows.spin > 0) & (rows.branch != 0)
        return jnp.where(use, new, omega), zeta

    def profile_model(self, values, model):
        return model.with_ring_changes(chi=1.0 - values[0])


EFFECT = register(Rotation())
