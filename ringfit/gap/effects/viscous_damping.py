"""``viscous_damping`` — viscous loss on the damping rows of mode tables (docs/physics.md §6; the damping family: see
:mod:`ringfit.gap.effects.damping_growth`)."""

from dataclasses import replace

import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect
from ringfit.gap.effects.wave_damping import VISCOUS_C


class ViscousDamping(Effect):
    """The ``viscous_damping`` effect: ζ = ζ0 + c/(2ρAω) on damping rows (docs/physics.md §6)."""

    name = "viscous_damping"
    baseline_partners = ("damping_ratio",)
    summary = "viscous loss: damping that falls with frequency, ζ = ζ0 + c/(2ρAω)"
    # the c of wave_damping's viscous profile form (same name, unit and bounds: docs/physics.md §6)
    parameters = (replace(VISCOUS_C, description="viscous damping c per unit length"),)

    def modal_mask(self, rows):
        return np.asarray(rows.is_freq) == 0

    def modal(self, values, omega, zeta, rows, ring, geometry):
        add = values[0] / (2.0 * ring.rho_a * jnp.maximum(omega, 1e-9))
        return omega, jnp.where(rows.is_freq == 0, zeta + add, zeta)


EFFECT = register(ViscousDamping())
