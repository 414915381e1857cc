"""Synthetic rolling acceleration profiles (DATA.md §3) from the steady rolling model, with known truth.

Used by the tests, the notebook and the benchmarks: simulate the sensor
(:func:`ringfit.physics.sensor.sensor_signals`) on the model grid, interpolate
(band-limited) to the profile's angles, add white Gaussian noise, and fill the
sidecar so that Ω is defined (``rotation_hz``) unless asked otherwise.
"""

from __future__ import annotations

import numpy as np

from ringfit.io.profiles import Profile
from ringfit.params import BAR, RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, RollingSolution, solve_rolling_jit
from ringfit.physics.operating import KMH, OperatingPoint, road_from_drum_diameter, rolling_radius
from ringfit.physics.rolling import RingModel
from ringfit.physics.sensor import SensorModel, sensor_signals_jit

#: Profile sample rate written to synthetic sidecars [Hz] (the source study's DAQ).
SAMPLE_RATE_HZ = 25600.0


def band_limited_resample(signal: np.ndarray, n_points: int) -> np.ndarray:
    """Periodic grid signal on φ_j = −π + 2πj/M → the same revolution on N points (zero-padded/truncated spectrum).

    ``signal`` shape ``(..., M)``; returns ``(..., N)``. Nyquist harmonics are dropped.
    """
    M = signal.shape[-1]
    spec = np.fft.rfft(signal, axis=-1)
    keep = (min(M, n_points) - 1) // 2 + 1
    out = np.zeros(signal.shape[:-1] + (n_points // 2 + 1,), dtype=complex)
    out[..., :keep] = spec[..., :keep]
    return np.fft.irfft(out, n_points, axis=-1) * (n_points / M)


def simulate_rolling(
    ring: RingParams,
    geometry: TyreGeometry,
    speed_kmh: float,
    load_n: float,
    *,
    drum_diameter_m: float | None = None,
    rotation_hz: float | None = None,
    model: RingModel = RingModel(),
    sensor: SensorModel = SensorModel(),
    solver: ContactSolver = ContactSolver(),
) -> tuple[RollingSolution, np.ndarray, float]:
    """Solve the steady rolling state at a speed and load and read the sensor.

    Ω is ``2π·rotation_hz`` when given, else ``V / R_e`` with
    ``R_e = R_out − δ/3`` (:func:`ringfit.physics.operating.rolling_radius`,
    δ from a first solve at the same load).

    **Returns:** ``(solution, channels (2, M) [m/s²] on the model grid, Ω [rad/s])``.
    """
    road = road_from_drum_diameter(drum_diameter_m)
    if rotation_hz is None:
        standing = solve_rolling_jit(ring, geometry, OperatingPoint(0.0, load_n, road), model=model, solver=solver)
        r_e = float(rolling_radius(geometry.outer_radius, standing.deflection))
        omega = speed_kmh * KMH / r_e
    else:
        omega = 2.0 * np.pi * rotation_hz
    solution = solve_rolling_jit(ring, geometry, OperatingPoint(omega, load_n, road), model=model, solver=solver)
    radial, tangential = sensor_signals_jit(solution, geometry, sensor)
    return solution, np.stack([np.asarray(radial), np.asarray(tangential)]), float(omega)


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

    **Arguments:** as :func:`simulate_rolling`; ``noise_ms2`` — σ of white
    Gaussian noise added to each channel [m/s²] (``seed`` for the generator);
    ``write_rotation_hz`` — put the Ω used into the sidecar (else a reader
    must derive Ω from the speed).
    """
    _, channels, omega = simulate_rolling(
        ring, geometry, speed_kmh, load_n, drum_diameter_m=drum_diameter_m, rotation_hz=rotation_hz,
        model=model, sensor=sensor, solver=solver,
    )
    values = band_limited_resample(channels, n_points)
    rng = np.random.default_rng(seed)
    if noise_ms2 > 0:
        values = values + rng.normal(0.0, noise_ms2, size=values.shape)
    condition = {
        "speed_kmh": float(speed_kmh), "load_n": float(load_n), "pressure_bar": float(geometry.pressure) / BAR,
        "revolutions": int(revolutions), "sample_rate_hz": SAMPLE_RATE_HZ,
    }
    if write_rotation_hz:
        condition["rotation_hz"] = omega / (2.0 * np.pi)
    if drum_diameter_m is not None:
        condition["drum_diameter_m"] = float(drum_diameter_m)
    angle = -180.0 + 360.0 * np.arange(n_points) / n_points
    return Profile(angle, values[0], values[1], condition=condition, source=f"synthetic {speed_kmh:g} km/h")


__all__ = ["simulate_rolling", "synthetic_profile", "band_limited_resample", "SAMPLE_RATE_HZ"]
