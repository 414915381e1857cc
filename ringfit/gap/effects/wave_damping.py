"""``wave_damping`` — loss that grows with frequency, so deformation waves decay away from the patch (PHYSICS.md §4.2, §6).

Loss factor ``η(ω) = η0 + η1 ω/ω_ref`` with ω_ref = 2π·100 Hz; η0 = 2ζ is the
baseline's hysteretic loss, η1 (``eta_slope``, null 0) is the effect.

- Modal data: ``ζ = ζ0 + η1 ω/(2 ω_ref)`` on damping rows — ζ rising with n.
- Rolling profiles: the material sees harmonic n at ω = |n|Ω, so the extra
  hysteretic term ``i η1 (|n|Ω/ω_ref) s_n K_n^c`` is added to D_n through
  :class:`ringfit.physics.rolling.RingModel` ``terms`` — leading/trailing
  asymmetry growing with speed.
"""

import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.rolling import AbstractOperatorTerm, elastic_stiffness

REFERENCE_FREQUENCY_HZ = 100.0


class GrowingLoss(AbstractOperatorTerm):
    """Operator term ``i η1 (|n|Ω/ω_ref) s_n K_n^c`` [N/m²] (complex, ``n.shape + (2, 2)``)."""

    eta_slope: float
    reference_rad_s: float = 2.0 * np.pi * REFERENCE_FREQUENCY_HZ

    def __call__(self, ring, geometry, n, omega):
        n = jnp.asarray(n, dtype=jnp.float64)
        eta = self.eta_slope * jnp.abs(n) * omega / self.reference_rad_s
        return 1j * (eta * jnp.sign(n))[..., None, None] * elastic_stiffness(ring, geometry, n)


class WaveDamping(Effect):
    name = "wave_damping"
    baseline_partners = ("damping_ratio",)
    summary = "damping that grows with frequency: waves decay away from the patch, front and rear differ"
    parameters = (
        Parameter("eta_slope", "-", null=0.0, lo=0.0, hi=0.3, start=0.02,
                  description="growth of the loss factor per 100 Hz"),
    )

    def modal_mask(self, rows):
        return np.asarray(rows.is_freq) == 0

    def modal(self, values, omega, zeta, rows, ring, geometry):
        ref = 2.0 * jnp.pi * REFERENCE_FREQUENCY_HZ
        return omega, zeta + 0.5 * values[0] * omega / ref

    def profile_model(self, values, model):
        return model.with_operator_term(GrowingLoss(values[0]))


EFFECT = register(WaveDamping())
