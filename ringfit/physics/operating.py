"""Operating point of a rolling tyre: wheel speed, load and the road (docs/physics.md §4.3).

The road is a small :class:`AbstractRoad` module that gives the distance from
the axle to the road surface along the ray at fixed-frame angle φ when the
axle sits at height H above the road (flat) or above the top of the drum.
New road shapes are added as new road modules; the contact solve
(:mod:`ringfit.physics.contact`) only calls :meth:`AbstractRoad.distance`.
"""

from __future__ import annotations

import abc
import math

import equinox as eqx
import jax.numpy as jnp

from ringfit.units import KMH  # m/s per km/h (re-exported here)


class AbstractRoad(eqx.Module):
    """A road surface seen from the axle (docs/physics.md §4.3)."""

    @abc.abstractmethod
    def distance(self, phi, height):
        """Axle-to-road distance s(φ) [m] along the ray at angle φ [rad], shape of ``phi``.

        ``height`` H [m] is the axle height above the road (flat) or above the
        top of the drum. Where the ray misses the road the distance is ``+inf``
        (no contact possible).
        """


class FlatRoad(AbstractRoad):
    """Flat road: ``s(φ) = H / cos φ`` for |φ| < π/2 (docs/physics.md §4.3)."""

    def distance(self, phi, height):
        c = jnp.cos(phi)
        return jnp.where(c > 1e-6, height / jnp.where(c > 1e-6, c, 1.0), jnp.inf)


class Drum(AbstractRoad):
    """Drum of diameter ``diameter`` [m] under the tyre (docs/physics.md §4.3).

    With D = H + R_d (axle to drum centre): ``s(φ) = D cos φ − √(R_d² − D² sin²φ)``,
    ``+inf`` where the root is imaginary or the ray points away from the drum.
    """

    diameter: float

    def distance(self, phi, height):
        rd = 0.5 * self.diameter
        d = height + rd
        disc = rd**2 - (d * jnp.sin(phi)) ** 2
        ok = (disc > 0.0) & (jnp.cos(phi) > 0.0)
        root = jnp.sqrt(jnp.where(ok, disc, 1.0))
        return jnp.where(ok, d * jnp.cos(phi) - root, jnp.inf)


class OperatingPoint(eqx.Module):
    """Steady rolling condition.

    **Fields:**

    - ``omega``: wheel rotation speed Ω [rad/s] (> 0 rolls forward; 0 = loaded, standing).
    - ``load``: vertical load Fz [N] (imposed; the axle height is solved for).
    - ``road``: :class:`FlatRoad` (default) or :class:`Drum`.
    """

    omega: float
    load: float
    road: AbstractRoad = FlatRoad()

    @classmethod
    def from_speed(cls, speed_kmh: float, load: float, rolling_radius: float, road: AbstractRoad | None = None):
        """Ω = V / R_e from a speed [km/h] and an effective rolling radius R_e [m] (docs/formats.md §3)."""
        if not rolling_radius > 0:
            raise ValueError(f"rolling_radius = {rolling_radius}: expected a positive radius in metres")
        return cls(omega=speed_kmh * KMH / rolling_radius, load=load, road=road or FlatRoad())


def road_from_drum_diameter(drum_diameter_m: float | None) -> AbstractRoad:
    """:class:`Drum` for a finite positive diameter, else :class:`FlatRoad` (docs/formats.md §3 ``drum_diameter_m``)."""
    if drum_diameter_m is None or not math.isfinite(drum_diameter_m) or drum_diameter_m <= 0:
        return FlatRoad()
    return Drum(diameter=float(drum_diameter_m))


def rolling_radius(outer_radius, deflection):
    """Effective rolling radius ``R_e = R_out − δ/3`` [m] from the vertical deflection δ [m].

    The classical approximation for a radial tyre (between the loaded radius
    R_out − δ and the free radius R_out). ringfit uses it to turn a speed into Ω
    when a profile has no ``rotation_hz`` (docs/formats.md §3); the rotation rate is
    written alongside every simulated profile so that the choice is explicit.
    """
    return outer_radius - deflection / 3.0
