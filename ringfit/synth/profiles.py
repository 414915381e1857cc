"""Synthetic rolling acceleration profiles (docs/formats.md §3) with known truth.

Used by the tests, the notebooks and the benchmarks: the one forward model
(:func:`ringfit.physics.profile.simulate_profile`) plus noise, with a sidecar
that states Ω (``rotation_hz``) unless asked otherwise.
"""

from __future__ import annotations

import numpy as np

from ringfit.io.profiles import Profile
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver
from ringfit.physics.profile import ProfileModel, simulate_profile
from ringfit.physics.rolling import RingModel
from ringfit.physics.sensor import SensorModel

#: Profile sample rate written to synthetic sidecars [Hz] (the source study's DAQ).
SAMPLE_RATE_HZ = 25600.0


def synthetic_profile(
    ring: RingParams,
    geometry: TyreGeometry,
    speed_kmh: float,
    load_n: float = 4000.0,
    *,
    drum_diameter_m: float | None = None,
    rotation_hz: float | None = None,
    write_rotation_hz: bool = True,
    n_points: int = 1024,
    noise_ms2: float = 0.0,
    seed: int = 0,
    revolutions: int = 26,
    model: RingModel = RingModel(),
    sensor: SensorModel = SensorModel(),
    solver: ContactSolver = ContactSolver(),
) -> Profile:
    """A synthetic :class:`~ringfit.io.profiles.Profile` at ``n_points`` evenly spaced angles in [−180, 180).

    **Arguments:** as :func:`~ringfit.physics.profile.simulate_profile` (``model`` the ring
    form and operator terms, ``sensor`` the sensor layers); ``noise_ms2`` — σ of white
    Gaussian noise added to each channel [m/s²] (``seed`` for the generator);
    ``write_rotation_hz`` — put the Ω used into the sidecar (else a reader must derive Ω
    from the speed); ``revolutions`` — written to the sidecar.
    """
    profile = simulate_profile(ring, geometry, speed_kmh=speed_kmh, load_n=load_n, rotation_hz=rotation_hz,
                               drum_diameter_m=drum_diameter_m, model=ProfileModel(ring_model=model, sensor=sensor),
                               solver=solver, n_points=n_points)
    values = profile.channels
    if noise_ms2 > 0:
        values = values + np.random.default_rng(seed).normal(0.0, noise_ms2, size=values.shape)
    condition = dict(profile.condition, revolutions=int(revolutions), sample_rate_hz=SAMPLE_RATE_HZ)
    if not write_rotation_hz:
        condition.pop("rotation_hz")
    return Profile(profile.angle_deg, values[0], values[1], condition=condition,
                   source=f"synthetic {speed_kmh:g} km/h")


__all__ = ["synthetic_profile", "SAMPLE_RATE_HZ"]
