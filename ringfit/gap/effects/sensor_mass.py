"""``sensor_mass`` — the accelerometer and its mount as a point mass on the ring (docs/physics.md §6).

Modal data: the mode a single sensor sees has its antinode at the sensor,
so its modal mass grows by m_s (Rayleigh): ``ω' = ω √(M_n/(M_n + m_s))`` with
``M_n = πRρA(1 + 1/n²)`` (n ≥ 1; rigid rotation n = 0: ``2πRρA``). About
−0.06 % for 3 g: a large shrink attributed to it is suspicious. Parameter
``mass_kg`` (null 0): the mass a test table carries *beyond the reference state*, so it acts on the rows of
test tables only, never on ``free.modes.csv`` (``rows.reference``). The ring is fitted to the reference table:
a mass glued on for that measurement too is already in the fitted ρA (its Rayleigh factor is ρA's own
``1 + 1/n²`` pattern), and what a test table can show is the difference. Applied to the reference rows as well,
the refit (where the ring answers to the reference rows alone, :class:`ringfit.gap.modal_rows.ModalPredictor`) lets
the ring undo the mass there while the mass answers to the test rows with the ring held: a 44 g sensor present
only in the test table then fits at 20 g with an interval reaching 0 (issue 30 item 9, the independent
``sensor_mass`` cases of ``benchmarks/_independent_effects.py``).

Rolling profiles: mass loading of the belt at the sensor, revolution harmonic
k seen at ω = kΩ through ``Z/(Z + iωm_s)`` with the belt's wave impedance
``Z = 2√(T0 ρA)`` (≈ 330 N s/m, corner ≈ 17 kHz for 3 g: docs/physics.md §6) — a
gentle low-pass of both channels, expected negligible; the bound (50 g) keeps
it physical. The centrifugal point load m_sΩ²R is a revolution-mean term the
baseline's mean removal takes out.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ringfit.gap.effects import register
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.physics.natural import ring_modal_mass


class MassLoading(eqx.Module):
    """Gain ``Z/(Z + i kΩ m_s)`` of revolution harmonic k [-], ``Z = 2√(T0 ρA)`` (docs/physics.md §6 sensor_mass)."""

    mass: float

    def __call__(self, omega, ring, geometry, k):
        impedance = 2.0 * jnp.sqrt(geometry.pretension * ring.rho_a)
        return impedance / (impedance + 1j * k * omega * self.mass)


class SensorMass(Effect):
    """The ``sensor_mass`` effect: the added mass of the accelerometer and its mount lowers the modes it sits on.

    This module's docstring has its model and parameters.
    """

    name = "sensor_mass"
    summary = "the added mass of the accelerometer and its mount lowers the modes it sits on"
    parameters = (
        Parameter("mass_kg", "kg", null=0.0, lo=0.0, hi=0.3, start=0.02,
                  description="sensor + mount mass m_s",
                  # an in-tyre sensor with its mount and glue: up to ~150 g (a TPMS unit is 30–50 g)
                  plausible=(0.0, 0.15)),
    )

    profile_parameters = (
        Parameter("mass_kg", "kg", null=0.0, lo=0.0, hi=0.05, start=0.005,
                  description="sensor + mount mass m_s"),
    )

    def profile_model(self, values, model):
        return model.with_channel_filter(MassLoading(values[0]))

    def modal_mask(self, rows):
        return (np.asarray(rows.is_freq) > 0) & (np.asarray(rows.reference) == 0)

    def modal(self, values, omega, zeta, rows, ring, geometry):
        modal_mass = ring_modal_mass(ring, geometry, rows.n)  # M_n [kg], docs/physics.md §6
        loaded = omega * jnp.sqrt(modal_mass / (modal_mass + values[0]))
        return jnp.where(rows.reference > 0, omega, loaded), zeta  # test tables only (module docstring)


EFFECT = register(SensorMass())
