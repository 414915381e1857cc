"""``wave_damping`` — loss that grows with frequency, so deformation waves decay away from the patch (docs/physics.md §4.2, §6).

docs/physics.md §6 names two forms; the effect carries both, each with its own
parameter (null 0 = the baseline's constant hysteretic loss η0 = 2ζ):

1. **Growing hysteretic loss** ``η(ω) = η0 + η1·ω/ω_ref``, ω_ref = 2π·100 Hz
   (``eta_slope`` = η1). The material sees harmonic n at ω = |n|Ω, so the
   extra term ``i η1 (|n|Ω/ω_ref) s_n K_n^c`` is added to D_n (:class:`GrowingLoss`).
2. **Viscous material damping** (docs/physics.md §4.2 "alternative damping"):
   ``i nΩ c_w`` on D_n[0,0] and ``i nΩ c_v`` on D_n[1,1], added on top of the
   baseline's hysteretic loss through :class:`ringfit.physics.rolling.Viscous`
   with one coefficient ``c = c_w = c_v`` [N s/m²] (``viscous_c``; isotropic
   material viscosity per unit length — the data cannot separate c_v from c_w:
   for the inextensible ring they enter only as ``c_w + c_v/n²``).

Either form makes the loss grow with the harmonic's frequency nΩ, so the
bulges at |φ| ≈ 15–60° lose their front/rear symmetry more at higher speed;
the growing hysteretic form grows like n·K_n (strongest at high n, near the
patch edges), the viscous one like n (the long waves). The refit frees both and
the JSON reports both; at least one interval must exclude 0 for acceptance.

- **Modal data**: only the hysteretic form, whose modal signature is the one
  docs/physics.md §6 names — ``ζ = ζ0 + η1 ω/(2 ω_ref)`` on damping rows, ζ rising
  with n. (Viscous c_w = c_v gives ``ζ = c/(2ρAω)``, falling with n — not a
  wave-damping signature on a free tyre, and collinear with ζ0 over the few
  measured modes.)
- **Rolling profiles**: both forms (parameters ``eta_slope``, ``viscous_c``).
"""

import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.rolling import AbstractOperatorTerm, Viscous, elastic_stiffness

REFERENCE_FREQUENCY_HZ = 100.0


class GrowingLoss(AbstractOperatorTerm):
    """Operator term ``i η1 (|n|Ω/ω_ref) s_n K_n^c`` [N/m²] (complex, ``n.shape + (2, 2)``)."""

    eta_slope: float
    reference_rad_s: float = 2.0 * np.pi * REFERENCE_FREQUENCY_HZ

    def __call__(self, ring, geometry, n, omega):
        n = jnp.asarray(n, dtype=jnp.float64)
        eta = self.eta_slope * jnp.abs(n) * omega / self.reference_rad_s
        return 1j * (eta * jnp.sign(n))[..., None, None] * elastic_stiffness(ring, geometry, n)


ETA_SLOPE = Parameter("eta_slope", "-", null=0.0, lo=0.0, hi=0.3, start=0.02,
                      description="growth of the hysteretic loss factor per 100 Hz")
VISCOUS_C = Parameter("viscous_c", "N s/m^2", null=0.0, lo=0.0, hi=5000.0, start=300.0,
                      description="viscous material damping c = c_w = c_v per unit length")


class WaveDamping(Effect):
    """The ``wave_damping`` effect: damping that grows with frequency: waves decay away from the patch, front and rear differ.

    This module's docstring has its model and parameters.
    """

    name = "wave_damping"
    baseline_partners = ("damping_ratio",)
    summary = "damping that grows with frequency: waves decay away from the patch, front and rear differ"
    parameters = (ETA_SLOPE,)
    profile_parameters = (ETA_SLOPE, VISCOUS_C)

    def modal_mask(self, rows):
        return np.asarray(rows.is_freq) == 0

    def modal(self, values, omega, zeta, rows, ring, geometry):
        ref = 2.0 * jnp.pi * REFERENCE_FREQUENCY_HZ
        return omega, zeta + 0.5 * values[0] * omega / ref

    def profile_model(self, values, model):
        model = model.with_operator_term(GrowingLoss(values[0]))
        return model.with_operator_term(Viscous(c_w=values[1], c_v=values[1]))


EFFECT = register(WaveDamping())
