"""``cavity_mode`` — the acoustic resonance of the air cavity coupled with the ring (PHYSICS.md §3.6, §6).

Modal data: per harmonic, the cavity pressure ``P_n = ρ0c²(b/A_c) ω² W_n/(ω_a,n² − ω²)``
loads the ring (``q_w += b P_n``), ``ω_a,n = n·2π f_cav``. With the modal
mass ``m = ρA(n²+1)/n²`` per unit length and ``k = b²ρ0c²/(A_c m)`` the
structural root continues ω₀ as ``ω² = ω₀² + δ``,
``δ² − [(ω_a² − ω₀²) + k] δ − k ω₀² = 0`` (the root that vanishes with k).
f_cav is the row of kind ``acoustic`` in the data when there is one (the
uncoupled cavity frequency taken as measured) and eq. 22 (343/1.568 Hz)
otherwise; ρ0 = 1.2 (p0 + p_atm)/p_atm, c = 343 m/s. Parameter
``inverse_area_per_m2`` = 1/A_c (null 0: no coupling). Steady rolling sees
only ~1e-3 of it (PHYSICS.md §6): not a profile effect.
"""

import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.natural import ring_modal_mass

SOUND_SPEED = 343.0
P_ATM = 101325.0


class CavityMode(Effect):
    name = "cavity_mode"
    summary = "the air cavity's acoustic resonance pulls on the ring modes near it"
    parameters = (
        Parameter("inverse_area_per_m2", "1/m^2", null=0.0, lo=0.0, hi=500.0, start=50.0,
                  description="1 / cavity cross-section A_c"),
    )

    def modal_mask(self, rows):
        return (np.asarray(rows.is_freq) > 0) & (np.asarray(rows.n) >= 1)

    def modal(self, values, omega, zeta, rows, ring, geometry):
        n = rows.n
        rho0 = 1.2 * (geometry.pressure + P_ATM) / P_ATM
        nz = n >= 1
        nn = jnp.where(nz, n, 1.0)
        m = ring_modal_mass(ring, geometry, nn) / (jnp.pi * geometry.radius)  # ρA(n²+1)/n² [kg/m]
        k = geometry.width**2 * rho0 * SOUND_SPEED**2 * values[0] / m
        wa2 = (2.0 * jnp.pi * rows.cavity_hz * nn) ** 2
        x0 = omega * omega
        B = wa2 - x0 + k
        sgn = jnp.where(B >= 0, 1.0, -1.0)
        delta = -2.0 * k * x0 / (B + sgn * jnp.sqrt(B * B + 4.0 * k * x0))
        return jnp.where(nz, jnp.sqrt(jnp.clip(x0 + delta, 0.0)), omega), zeta


EFFECT = register(CavityMode())
