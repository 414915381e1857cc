"""``cavity_mode`` — the acoustic resonance of the air cavity coupled with the ring (docs/physics.md §3.6, §6).

Modal data: per harmonic, the cavity pressure ``P_n = ρ0c²(b/A_c) ω² W_n/(ω_a,n² − ω²)``
loads the ring (``q_w += b P_n``), ``ω_a,n = n·2π f_cav``. With the modal
mass ``m = ρA(n²+1)/n²`` per unit length and ``k = b²ρ0c²/(A_c m)`` the
structural root continues ω₀ as ``ω² = ω₀² + δ``,
``δ² − [(ω_a² − ω₀²) + k] δ − k ω₀² = 0`` (the root that vanishes with k;
:func:`ringfit.physics.natural.cavity_coupling`, :func:`~ringfit.physics.natural.cavity_coupled_shift`).
f_cav is the row of kind ``acoustic`` in the data when there is one (the
uncoupled cavity frequency taken as measured) and eq. 22 (343/1.568 Hz)
otherwise; ρ0 = 1.2 (p0 + p_atm)/p_atm, c = 343 m/s. Parameter
``inverse_area_per_m2`` = 1/A_c (null 0: no coupling). Steady rolling sees
only ~1e-3 of it (docs/physics.md §6): not a profile effect.
"""

import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.natural import cavity_coupled_shift, cavity_coupling


class CavityMode(Effect):
    """The ``cavity_mode`` effect: the air cavity's acoustic resonance pulls on the ring modes near it.

    This module's docstring has its model and parameters.
    """

    name = "cavity_mode"
    summary = "the air cavity's acoustic resonance pulls on the ring modes near it"
    parameters = (
        Parameter("inverse_area_per_m2", "1/m^2", null=0.0, lo=0.0, hi=500.0, start=50.0,
                  description="1 / cavity cross-section A_c"),
    )

    def modal_mask(self, rows):
        return (np.asarray(rows.is_freq) > 0) & (np.asarray(rows.n) >= 1)

    def modal(self, values, omega, zeta, rows, ring, geometry):
        nz = rows.n >= 1
        nn = jnp.where(nz, rows.n, 1.0)
        k = cavity_coupling(ring, geometry, nn, values[0])
        delta = cavity_coupled_shift(omega, 2.0 * jnp.pi * rows.cavity_hz * nn, k)
        return jnp.where(nz, jnp.sqrt(jnp.clip(omega * omega + delta, 0.0)), omega), zeta


EFFECT = register(CavityMode())
