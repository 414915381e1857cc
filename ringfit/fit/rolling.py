"""Fit the tread stiffness (and optionally damping, angle offset) to rolling acceleration profiles.

Model: steady rolling ring with tread-spring contact (docs/physics.md §4,
:func:`ringfit.physics.contact.solve_rolling`) read by the sensor layers
(:func:`ringfit.physics.sensor.sensor_signals`; default the §6 baseline: plain
channels, per-revolution mean removed). The stiffness and density of the ring
come from the natural-frequency fit and stay fixed unless freed.

Residual rows: every profile (one per speed, any number), both channels, on
the model grid φ_j (the measured profile is band-limited-resampled there,
:func:`ringfit.io.profiles.resample_profile`; with the baseline sensor each
measured channel's mean is removed too): ``model(φ_j + offset) − measured``
[m/s²]. Positive parameters are fitted as logarithms; the angle offset
(``angle_offset``, rad, one for all profiles) linearly. Solver: optimistix
Levenberg–Marquardt; covariance from the Jacobian at the optimum scaled by the
residual variance ``s² = χ²/dof`` (the residual is model error as much as
noise, so σ is estimated, not assumed).

:func:`tread_stiffness_sweep` reproduces the source study's procedure (run the
model for a grid of tread stiffnesses at one speed, keep the lowest error) for
comparison; :func:`sample_rolling_posterior` samples the posterior with emcee
(``vectorize=True`` on one jitted, vmapped log-probability).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import equinox as eqx
import jax
import numpy as np

from ringfit.errors import InputError
from ringfit.fit.engine import LINEAR, AbstractResiduals, Coordinate, Problem, least_squares, sum_of_squares_batch
from ringfit.fit.least_squares import RING_COORDS, RING_FIELDS, ring_from_vector, ring_vector
from ringfit.fit.priors import BOUNDS
from ringfit.fit.result import FitResult
from ringfit.io.profiles import grid_angles_deg, resample_profile
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, as_traced
from ringfit.physics.profile import (FlatOrDrum, ProfileModel, effective_rolling_radius, flat_or_drum, full_band,
                                     profile_channels)
from ringfit.physics.rolling import RingModel
from ringfit.physics.sensor import SensorModel

#: Name of the angle-offset nuisance parameter [rad] (docs/physics.md §5 layer 6).
ANGLE_OFFSET = "angle_offset"
#: Parameters a rolling fit may free: positive ring parameters (log) and the angle offset (linear).
ROLLING_FREE = ("k_tread", "damping_ratio", "ei", "kw", "kv", "rho_a", ANGLE_OFFSET)
#: Flat prior range of the angle offset in the posterior [rad].
ANGLE_OFFSET_BOUND = math.radians(10.0)


@dataclass(frozen=True)
class RollingData:
    """Profiles on the model grid, ready for a fit.

    - ``measured``: ``(P, 2, M)`` radial/tangential [m/s²] on φ_j (mean removed for the baseline sensor).
    - ``omega``, ``load``: ``(P,)`` Ω [rad/s] and Fz [N]; ``drum_diameter``: ``(P,)`` [m] or None (flat road).
    - ``speed_kmh``: ``(P,)``; ``omega_source``: per profile, where Ω came from; ``sources``: file names.
    """

    measured: np.ndarray
    omega: np.ndarray
    load: np.ndarray
    drum_diameter: np.ndarray | None
    speed_kmh: np.ndarray
    omega_source: tuple[str, ...]
    sources: tuple[str, ...]


def rolling_data(
    profiles, geometry: TyreGeometry, ring: RingParams, *,
    solver: ContactSolver = ContactSolver(), sensor: SensorModel = SensorModel(), model: RingModel = RingModel(),
    rolling_radius_m: float | None = None,
) -> RollingData:
    """Put profiles on the model grid and work out Ω for each (docs/formats.md §3).

    Ω is ``2π·rotation_hz`` when the sidecar has it, else ``V / R_e`` with
    ``rolling_radius_m`` or, by default, ``R_e = R_out − δ/3`` where δ is the
    standing deflection of ``ring`` at the profile's load.
    """
    profiles = list(profiles)
    if not profiles:
        raise InputError("no profile to fit")
    drums = [p.drum_diameter_m for p in profiles]
    if any(d is None for d in drums) and not all(d is None for d in drums):
        raise InputError("profiles mix flat-road and drum conditions (drum_diameter_m); fit them separately")
    M = solver.n_grid
    measured, omega, sources = [], [], []
    for p in profiles:
        if p.rotation_hz is None and rolling_radius_m is None:
            r_e = effective_rolling_radius(ring, geometry, p.load_n, p.drum_diameter_m,
                                           model=ProfileModel(ring_model=model), solver=solver)
        else:
            r_e = rolling_radius_m
        om, src = p.omega(r_e)
        ch = resample_profile(p, M)
        if sensor.remove_mean:
            ch = ch - ch.mean(axis=-1, keepdims=True)
        measured.append(ch)
        omega.append(om)
        sources.append(src)
    return RollingData(
        measured=np.stack(measured),
        omega=np.array(omega),
        load=np.array([p.load_n for p in profiles]),
        drum_diameter=None if drums[0] is None else np.array(drums, dtype=np.float64),
        speed_kmh=np.array([p.speed_kmh for p in profiles]),
        omega_source=tuple(sources),
        sources=tuple(p.source for p in profiles),
    )


class RollingArrays(eqx.Module):
    """What the rolling residuals need besides θ: geometry, operating points ``(P,)`` and the profiles."""

    geometry: TyreGeometry
    omega: jax.Array
    load: jax.Array
    roads: FlatOrDrum
    band: jax.Array
    measured: jax.Array


class RollingResiduals(AbstractResiduals):
    """Rows ``model(φ_j) − measured(φ_j)`` [m/s²] of every profile and channel; aux: the model ``(P, 2, M)``.

    θ = the ring fields (:data:`ringfit.fit.least_squares.RING_FIELDS`) then the angle offset [rad];
    the model is the one forward model (:func:`ringfit.physics.profile.profile_channels`).
    """

    model: ProfileModel = eqx.field(static=True)
    solver: ContactSolver = eqx.field(static=True)

    def __call__(self, theta, data: RollingArrays):
        ring = ring_from_vector(theta)
        ch = profile_channels(self.model, ring, data.geometry, data.omega, data.load, data.roads, data.band,
                              theta[len(RING_FIELDS)], self.solver)
        return (ch - data.measured).ravel(), ch


#: Solver coordinates of a rolling fit: the ring's (log) and the angle offset (linear, in degrees, ±10°).
ROLLING_COORDS = RING_COORDS + (Coordinate(ANGLE_OFFSET, LINEAR, scale=math.radians(1.0), lo=-ANGLE_OFFSET_BOUND,
                                           hi=ANGLE_OFFSET_BOUND),)


def check_rolling_free(free) -> tuple[str, ...]:
    """Validate the names of the parameters to fit (see :data:`ROLLING_FREE`)."""
    free = tuple(free)
    if not free:
        raise InputError("no free parameter to fit")
    for k in free:
        if k not in ROLLING_FREE:
            raise InputError(f"cannot fit {k!r} to rolling profiles; choose from {', '.join(ROLLING_FREE)}")
    if len(set(free)) != len(free):
        raise InputError(f"parameter listed twice in {list(free)}")
    return free


def _problem(data: RollingData, geometry, free, model, sensor, solver) -> Problem:
    P, _, M = data.measured.shape
    arrays = RollingArrays(geometry=geometry, omega=data.omega, load=data.load,
                           roads=flat_or_drum(data.drum_diameter, P), band=full_band(P, M), measured=data.measured)
    residuals = RollingResiduals(ProfileModel(ring_model=model, sensor=sensor), solver)
    return Problem(residuals, as_traced(arrays), ROLLING_COORDS, sigma="estimate", plausible=BOUNDS,
                   data_label="these profiles")


def fit_rolling(
    profiles,
    geometry: TyreGeometry,
    ring: RingParams,
    *,
    free=("k_tread",),
    initial_offset_deg: float = 0.0,
    model: RingModel = RingModel(),
    sensor: SensorModel = SensorModel(),
    solver: ContactSolver = ContactSolver(),
    rolling_radius_m: float | None = None,
    max_steps: int = 64,
    rtol: float = 1e-8,
    atol: float = 1e-4,
) -> FitResult:
    """Fit ring parameters (default: the tread stiffness) to one or more rolling profiles.

    **Arguments:**

    - ``profiles``: :class:`~ringfit.io.profiles.Profile` objects (any speeds,
      all on a flat road or all on drums), or a prepared :class:`RollingData`.
    - ``geometry``, ``ring``: the tyre and the ring from the natural-frequency
      fit; parameters not in ``free`` stay at these values, free ones start there.
    - ``free``: subset of :data:`ROLLING_FREE`; ``angle_offset`` [rad] is the
      recorded-angle offset (φ = α + offset), starting at ``initial_offset_deg``.
    - ``model``, ``sensor``, ``solver``: ring form, sensor layers (default §6
      baseline), grid (see :mod:`ringfit.physics`).
    - ``rtol``, ``atol``: optimistix Cauchy termination (``atol`` applies to the
      log-parameters and to the residuals in m/s²; the last Newton steps make the
      optimum far more precise than ``atol``).

    **Returns:** :class:`~ringfit.fit.result.FitResult` (values SI; angle offset in
    rad). ``extra``: ``model``, ``measured`` ``(P, 2, M)``, ``angle_deg`` ``(M,)``,
    ``omega``, ``speed_kmh``, ``omega_source``, ``sigma_ms2`` (estimated residual
    σ), ``rms_ms2``, ``evaluations`` (model-evaluation equivalents used),
    ``data``, ``ring``, ``geometry``. Never raises on non-convergence.
    """
    data = profiles if isinstance(profiles, RollingData) else rolling_data(
        profiles, geometry, ring, solver=solver, sensor=sensor, model=model, rolling_radius_m=rolling_radius_m)
    free = check_rolling_free(free)
    problem = _problem(data, geometry, free, model, sensor, solver)
    theta0 = np.append(ring_vector(ring), math.radians(initial_offset_deg))
    result = least_squares(problem, theta0, free, max_steps=max_steps, rtol=rtol, atol=atol)
    M = data.measured.shape[-1]
    k = len(free)
    chi2 = result.extra["chi2_raw"]
    result.extra.update(
        model=np.asarray(result.extra.pop("aux")), measured=data.measured, angle_deg=grid_angles_deg(M),
        omega=data.omega, speed_kmh=data.speed_kmh, omega_source=data.omega_source,
        sigma_ms2=result.extra["sigma_scale"], rms_ms2=math.sqrt(chi2 / data.measured.size),
        evaluations=evaluations_used(result.iterations, k), data=data, ring=fitted_ring(result), geometry=geometry,
    )
    return result


def evaluations_used(steps: int, k: int) -> int:
    """Model-evaluation equivalents of a Levenberg–Marquardt fit with k parameters.

    Each step evaluates the residuals and linearises them (one primal solve and
    k tangent solves, counted as 1 + k evaluations); the final Jacobian for the
    covariance adds 1 + k.
    """
    return (steps + 1) * (1 + k)


@dataclass(frozen=True)
class SweepResult:
    """The source study's procedure: grid of tread stiffnesses, lowest error wins.

    ``k_tread`` ``(G,)`` [N/m²], ``sse`` ``(G,)`` sum of squared residuals [(m/s²)²],
    ``best`` [N/m²], ``best_sse``, ``evaluations`` (= G model runs).
    """

    k_tread: np.ndarray
    sse: np.ndarray
    best: float
    best_sse: float
    evaluations: int


def tread_stiffness_sweep(
    profiles, geometry: TyreGeometry, ring: RingParams, k_grid, *,
    model: RingModel = RingModel(), sensor: SensorModel = SensorModel(), solver: ContactSolver = ContactSolver(),
    rolling_radius_m: float | None = None, batch: int = 64,
) -> SweepResult:
    """Run the model for every tread stiffness in ``k_grid`` [N/m²] and keep the lowest error (source study §5.3).

    The error is the same sum of squared residuals that :func:`fit_rolling`
    minimises, so the two optima compare directly.
    """
    data = profiles if isinstance(profiles, RollingData) else rolling_data(
        profiles, geometry, ring, solver=solver, sensor=sensor, model=model, rolling_radius_m=rolling_radius_m)
    problem = _problem(data, geometry, ("k_tread",), model, sensor, solver)
    k_grid = np.asarray(k_grid, dtype=np.float64)
    thetas = np.tile(np.append(ring_vector(ring), 0.0), (k_grid.size, 1))
    thetas[:, RING_FIELDS.index("k_tread")] = k_grid
    sse = sum_of_squares_batch(problem, thetas, chunk=batch)
    i = int(np.argmin(sse))
    return SweepResult(k_grid, sse, float(k_grid[i]), float(sse[i]), int(k_grid.size))


def sum_of_squares(result: FitResult) -> float:
    """Unweighted sum of squared residuals [(m/s²)²] of a :func:`fit_rolling` result."""
    return float(result.extra["chi2_raw"])


def sample_rolling_posterior(result: FitResult, *, walkers: int = 16, steps: int = 400, seed: int = 0,
                             progress: bool = False):
    """Posterior of a :func:`fit_rolling` result's free parameters: :func:`ringfit.fit.posterior.sample`
    for exactly ``steps`` steps.

    Likelihood: independent Gaussians with the residual σ of the fit (``result.extra["sigma_ms2"]``);
    prior: flat in ``log θ`` within :data:`ringfit.fit.priors.BOUNDS` (±10° for the angle offset);
    walkers start in a small ball (¼ of the standard error) at the optimum.
    """
    from ringfit.fit.posterior import sample

    return sample(result, walkers=walkers, min_steps=steps, max_steps=steps, check_every=steps, seed=seed,
                  progress=progress, spread=0.25, meta={"model": "rolling", "sigma_ms2": result.extra["sigma_ms2"]})


def fitted_ring(result: FitResult) -> RingParams:
    """The :class:`RingParams` of a rolling fit (free parameters at their optimum)."""
    return RingParams(**{k: result.values[k] for k in RING_FIELDS})


__all__ = [
    "fit_rolling", "rolling_data", "RollingData", "RollingResiduals", "tread_stiffness_sweep", "SweepResult",
    "sample_rolling_posterior", "fitted_ring", "ROLLING_FREE", "ANGLE_OFFSET", "evaluations_used",
    "sum_of_squares", "check_rolling_free",
]
