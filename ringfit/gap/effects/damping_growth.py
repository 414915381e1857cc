"""``damping_growth`` and ``viscous_damping`` — the damping family's other forms (docs/physics.md §6).

The damping rows of mode tables (``ln ζ``, one level ζ0 per table as the
baseline) are tried with three forms of loss, one effect each, and the
diagnosis keeps the one its rules prefer:

- ``wave_damping`` (its own module): hysteretic loss growing linearly with
  frequency, ``ζ = ζ0 + η1 ω/(2ω_ref)``;
- ``damping_growth``: a loss factor that grows as a power of the wave number,
  ``η(n) = η0 n^b``, i.e. ``ln ζ = ln ζ0 + b ln n`` — linear in the fitted
  quantity (ln ζ), so b stays identifiable however steep the growth: a ×10 rise
  over n = 1…9 is b ≈ 1.05, well inside the bound (−1, 3). The parameter is
  the exponent, not a slope in ζ, so no bound cuts a steep law off;
- ``viscous_damping``: a viscous foundation/material loss c (N s/m² per unit
  length), ``ζ = ζ0 + c/(2ρA ω)`` — falling with frequency (docs/physics.md §4.2
  alternative damping; c = c_w = c_v on the inextensible ring's modal mass).

Mode tables only (damping rows). Rows without n (or n = 0) are left alone by
``damping_growth``.
"""

import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter


class DampingGrowth(Effect):
    """The ``damping_growth`` effect: η(n) = η₀ nᵇ on damping rows (docs/physics.md §6)."""

    name = "damping_growth"
    baseline_partners = ("damping_ratio",)
    summary = "a loss factor that grows as a power of n: ln ζ rises linearly in ln n"
    parameters = (
        Parameter("exponent", "-", null=0.0, lo=-1.0, hi=3.0, start=0.5,
                  description="b of η(n) = η0 n^b (b = 1.05: ×10 over n = 1…9)"),
    )

    def modal_mask(self, rows):
        return (np.asarray(rows.is_freq) == 0) & (np.asarray(rows.n) >= 1)

    def modal(self, values, omega, zeta, rows, ring, geometry):
        ok = rows.n >= 1
        # ζ n^b written as ζ·exp(b ln n): exactly ζ at b = 0
        factor = jnp.exp(values[0] * jnp.log(jnp.where(ok, rows.n, 1.0)))
        return omega, jnp.where(ok & (rows.is_freq == 0), zeta * factor, zeta)


EFFECT = register(DampingGrowth())
