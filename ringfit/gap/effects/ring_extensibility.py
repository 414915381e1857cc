"""``ring_extensibility`` — a finite membrane stiffness EA of the belt (PHYSICS.md §2.2, §6).

Modal data: the flexural branch of ``det(K_n − ρAω² I) = 0`` with the §2.2
stiffness matrix. Written as a correction to the inextensible ω² so that
compliance 0 gives eq. 18 bit for bit: with ``c = 1/EA·R²``-scaled compliance,
``λ = ρAω²``, ``a = EI n⁴/R⁴ + k_w + P(n²−1)``, ``B = EI n²/R⁴ + k_v``,
``b₃ = EI n³/R⁴`` and ``λ₀`` the inextensible value, the flexural root is
``λ = λ₀ + δ`` with ``c δ² − [c(A′+B′) + n²+1] δ + c(A′B′ − b₃²) = 0``,
``A′ = a − λ₀``, ``B′ = B − λ₀`` (the smaller root). Parameter
``compliance_per_mn`` = 10⁶ N / EA (null 0 = inextensible, 10 = EA of 1e5 N).

Rolling profiles: the extensible 2×2 operator D_n of PHYSICS.md §4.2 with
EA = 10⁶/c N (:meth:`ringfit.physics.profile.ProfileModel.with_membrane_compliance`;
c = 0 gives EA = 1e12 N, the inextensible ring to ~1e-8). Signature: belt
stretch ``s_tan ∝ Ω²Rε′``, small (PHYSICS.md §6).
"""

import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter


class RingExtensibility(Effect):
    name = "ring_extensibility"
    summary = "a finite membrane stiffness EA of the belt lowers the flexural modes"
    parameters = (
        Parameter("compliance_per_mn", "1/MN", null=0.0, lo=0.0, hi=50.0, start=2.0,
                  description="1e6 N / EA (10 = EA of 1e5 N)"),
    )

    def profile_model(self, values, model):
        return model.with_membrane_compliance(values[0] * 1e-6)

    def modal_mask(self, rows):
        return (np.asarray(rows.is_freq) > 0) & (np.asarray(rows.n) >= 1)

    def modal(self, values, omega, zeta, rows, ring, geometry):
        n = rows.n
        R = geometry.radius
        c = values[0] * 1e-6 * R**2  # R²/EA [m²/N]: multiplies stiffnesses per unit length
        b4 = ring.ei / R**4
        lam0 = ring.rho_a * omega * omega
        A1 = b4 * n**4 + ring.kw + geometry.hoop_pressure_stiffness * (n**2 - 1.0) - lam0
        B1 = b4 * n**2 + ring.kv - lam0
        b3 = b4 * n**3
        lin = c * (A1 + B1) + n**2 + 1.0
        const = c * (A1 * B1 - b3**2)
        disc = jnp.sqrt(jnp.clip(lin**2 - 4.0 * c * const, 0.0))
        delta = 2.0 * const / (lin + disc)
        use = n >= 1
        return jnp.where(use, jnp.sqrt(omega * omega + delta / ring.rho_a), omega), zeta


EFFECT = register(RingExtensibility())
