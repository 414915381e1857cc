"""``tread_shear`` — tread tips stick to the road and shear in the patch (PHYSICS.md §6).

Minimal brush model on top of the radial contact solution: the tip sticks
at the leading edge φ_L and then moves with the road; base position
``x_b(φ) = (R+τ+w) sin φ + v cos φ``; shear ``Δx = x_b(φ) − x_b(φ_L) − R_e(φ − φ_L)``;
``q_x = −k_x Δx`` clipped at ``|q_x| ≤ μ p`` (μ = 1); loads
``q_w += q_x sin φ``, ``q_v += q_x cos φ``. Free rolling fixes R_e by
``∫ q_v dφ = 0``. Applied as one fixed-point step: the radial solution gives
the shear load, the contact is solved again with it
(``solve_rolling(..., extra_load=...)``). Parameter ``shear_stiffness_mn_per_m2``
= k_x / 1e6 (null 0).
"""

import equinox as eqx
import jax
import jax.numpy as jnp

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter

FRICTION = 1.0


class BrushShearLoad(eqx.Module):
    """Load hook: ``(solution, ring, geometry) -> (q_w, q_v)`` grid loads [N/m] of the brush tread shear."""

    k_x: float
    mu: float = FRICTION

    def __call__(self, sol, ring, geometry):
        phi = sol.phi
        p = sol.pressure
        inside = jax.lax.stop_gradient(p > 0)
        M = phi.shape[-1]
        x_b = (geometry.outer_radius + sol.w) * jnp.sin(phi) + sol.v * jnp.cos(phi)
        first = jnp.argmax(inside)  # leading edge: first grid point in the patch (smallest φ)
        s = phi - phi[first]
        D = x_b - x_b[first]
        num = jnp.sum(jnp.where(inside, D * jnp.cos(phi), 0.0))
        den = jnp.sum(jnp.where(inside, s * jnp.cos(phi), 0.0))
        r_e = num / jnp.where(den == 0, 1.0, den)
        q_x = -self.k_x * (D - r_e * s)
        lim = self.mu * p
        q_x = jnp.where(inside, jnp.clip(q_x, -lim, lim), 0.0)
        del M
        return q_x * jnp.sin(phi), q_x * jnp.cos(phi)


class TreadShear(Effect):
    name = "tread_shear"
    summary = "the tread sticks to the road and shears in the patch, pulling the belt tangentially"
    parameters = (
        Parameter("shear_stiffness_mn_per_m2", "MN/m^2", null=0.0, lo=0.0, hi=60.0, start=10.0,
                  description="k_x / 1e6: tangential tread stiffness per unit length"),
    )

    def profile_model(self, values, model):
        return model.with_load_hook(BrushShearLoad(values[0] * 1e6))


EFFECT = register(TreadShear())
