"""``ring_extensibility`` — a finite membrane stiffness EA of the belt (docs/physics.md §2.2, §6).

Modal data: the flexural branch of ``det(K_n − ρAω² I) = 0`` with the §2.2
stiffness matrix, added to the model's ω² as a correction,
``ω² → ω² + (ω²_flexural − ω²_eq18)`` at EA = 10⁶/c N
(:func:`ringfit.physics.natural.extensible_flexural_shift`): compliance 0
gives the model back bit for bit, and the correction is smooth there.
Parameter ``compliance_per_mn`` = 10⁶ N / EA (null 0 = inextensible, 10 = EA
of 1e5 N).

Rolling profiles: the extensible 2×2 operator D_n of docs/physics.md §4.2 with
EA = 10⁶/c N (:meth:`ringfit.physics.profile.ProfileModel.with_membrane_compliance`;
c = 0 gives EA = 1e12 N, the inextensible ring to ~1e-8). Signature: belt
stretch ``s_tan ∝ Ω²Rε′``, small (docs/physics.md §6).
"""

import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.natural import extensible_flexural_shift


class RingExtensibility(Effect):
    """The ``ring_extensibility`` effect: a finite membrane stiffness EA of the belt lowers the flexural modes.

    This module's docstring has its model and parameters.
    """

    name = "ring_extensibility"
    summary = "a finite membrane stiffness EA of the belt lowers the flexural modes"
    parameters = (
        Parameter("compliance_per_mn", "1/MN", null=0.0, lo=0.0, hi=50.0, start=2.0,
                  description="1e6 N / EA (10 = EA of 1e5 N)",
                  # a belt's membrane stiffness EA is ~1e8 N (steel belts and plies); EA < 1e6 N is no belt
                  plausible=(0.0, 1.0)),
    )

    def profile_model(self, values, model):
        return model.with_membrane_compliance(values[0] * 1e-6)

    def modal_mask(self, rows):
        return (np.asarray(rows.is_freq) > 0) & (np.asarray(rows.n) >= 1)

    def modal(self, values, omega, zeta, rows, ring, geometry):
        shift = extensible_flexural_shift(ring, geometry, rows.n, values[0] * 1e-6)  # compliance 1/EA [1/N]
        return jnp.where(rows.n >= 1, jnp.sqrt(omega * omega + shift), omega), zeta


EFFECT = register(RingExtensibility())
