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

3. **A loss growing with the wave's order** at any speed: ``η(n) = η0 + η2·(n/10)²``
   (``eta_order`` = η2, the extra loss factor at order 10): ``i η2 (n/10)² s_n K_n^c``
   added to D_n (:class:`OrderLoss`). A material's loss depends on how fast it is strained
   (forms 1 and 2); a structure's can depend on how short the wave is (the belt's bending
   strains grow as the curvature, n²), whatever the speed.

Forms 1 and 2 make the loss grow with the harmonic's frequency nΩ, so the
bulges at |φ| ≈ 15–60° lose their front/rear symmetry more at higher speed;
the growing hysteretic form grows like n·K_n (strongest at high n, near the
patch edges), the viscous one like n (the long waves); form 3 grows like n²·K_n and
not with speed. The refit frees all three and the JSON reports them; at least one
interval must exclude 0 for acceptance.

- **Modal data**: only the hysteretic form, whose modal signature is the one
  docs/physics.md §6 names — ``ζ = ζ0 + η1 ω/(2 ω_ref)`` on damping rows, ζ rising
  with n. (Viscous c_w = c_v gives ``ζ = c/(2ρAω)``, falling with n — not a
  wave-damping signature on a free tyre, and collinear with ζ0 over the few
  measured modes.)
- **Rolling profiles**: all three forms (parameters ``eta_slope``, ``viscous_c``, ``eta_order``).
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


class OrderLoss(AbstractOperatorTerm):
    """Operator term ``i η2 (n/n_ref)² s_n K_n^c`` [N/m²] (complex, ``n.shape + (2, 2)``), n_ref = 10."""

    eta_order: float
    reference_order: float = 10.0

    def __call__(self, ring, geometry, n, omega):
        n = jnp.asarray(n, dtype=jnp.float64)
        eta = self.eta_order * (n / self.reference_order) ** 2
        return 1j * (eta * jnp.sign(n))[..., None, None] * elastic_stiffness(ring, geometry, n)


ETA_SLOPE = Parameter("eta_slope", "-", null=0.0, lo=0.0, hi=0.3, start=0.02,
                      description="growth of the hysteretic loss factor per 100 Hz")
VISCOUS_C = Parameter("viscous_c", "N s/m^2", null=0.0, lo=0.0, hi=5000.0, start=300.0,
                      description="viscous material damping c = c_w = c_v per unit length")
ETA_ORDER = Parameter("eta_order", "-", null=0.0, lo=0.0, hi=0.3, start=0.02,
                      description="extra hysteretic loss factor at order 10, growing as (n/10)^2 at any speed")


class WaveDamping(Effect):
    """The ``wave_damping`` effect: damping that grows with frequency: waves decay away from the patch, front and rear differ.

    This module's docstring has its model and parameters.
    """

    name = "wave_damping"
    baseline_partners = ("damping_ratio",)
    summary = "damping that grows with frequency: waves decay away from the patch, front and rear differ"
    parameters = (ETA_SLOPE,)
    profile_parameters = (ETA_SLOPE, VISCOUS_C, ETA_ORDER)

    def modal_mask(self, rows):
        return np.asarray(rows.is_freq) == 0

    def modal(self, values, omega, zeta, rows, ring, geometry):
        ref = 2.0 * jnp.pi * REFERENCE_FREQUENCY_HZ
        return omega, zeta + 0.5 * values[0] * omega / ref

    def profile_model(self, values, model):
        model = model.with_operator_term(GrowingLoss(values[0]))
        model = model.with_operator_term(Viscous(c_w=values[1], c_v=values[1]))
        return model.with_operator_term(OrderLoss(values[2]))


EFFECT = register(WaveDamping())
