"""Fit the tread stiffness (and optionally damping or other ring parameters) to rolling acceleration profiles.

Model: steady rolling ring with tread-spring contact (docs/physics.md §4,
:func:`ringfit.physics.contact.solve_rolling`) read by the sensor layers
(:func:`ringfit.physics.sensor.sensor_signals`; default the §6 baseline: plain
channels, per-revolution mean removed). The stiffness and density of the ring
come from the natural-frequency fit and stay fixed unless freed.

The profiles are read with the profile block's likelihood (:mod:`ringfit.fit.profile_block`,
docs/physics.md §11 "profiles"), the same ``ringfit identify`` and the diagnosis's profile baseline use:

- **rows**: each profile band-limited-resampled onto the model grid (:func:`rolling_data`), then its
  revolution harmonics k = :data:`~ringfit.fit.profile_block.PROFILE_K_MIN` …
  :func:`~ringfit.fit.profile_block.profile_band` (real then imaginary parts,
  :func:`~ringfit.fit.profile_block.harmonic_rows`), ``(model − measured)/σ``;
- **nuisances**: per profile an angle offset and a gain on the reading
  (:func:`~ringfit.fit.profile_block.read_through`), always fitted, tied by the block's prior
  (:func:`~ringfit.fit.profile_block.nuisance_prior`: one sensor for every run); and, with ``sensor_nuisances``
  (the default, as ``identify``), each run's sensor's own nuisances
  (:data:`~ringfit.fit.profile_block.SENSOR_FIELDS`: tilt gain, IEPE corner, liner offset, tangential gain; their
  priors :func:`~ringfit.fit.profile_block.sensor_prior`), read through the same bilinear basis
  (:func:`~ringfit.fit.profile_block.sensor_basis`, :func:`~ringfit.fit.profile_block.sensor_reading`). The model
  is in two stages (the rolling solve, then each run's reading), so the nuisances' tangents skip the solve;
- **noise**: σ per profile, channel and harmonic from the fit's own residual
  (:func:`~ringfit.fit.profile_block.noise_from_residual`: a power law, the neighbouring harmonics' average
  with each harmonic's own residual left out, widened by ν/(ν − 4) and the degrees of freedom the fit took),
  in passes as ``identify`` does (:data:`~ringfit.fit.free_block.SCALE_PASSES`): σ weights the fit, the
  fit's residual gives σ.

Positive parameters are fitted as logarithms, the offsets linearly. Solver: optimistix
Levenberg–Marquardt; covariance from the weighted rows and the prior's at the optimum (σ known from the
noise model: ``Problem(sigma="fixed")``).

:func:`tread_stiffness_sweep` reproduces the source study's procedure (run the model for a grid of
tread stiffnesses at one speed, keep the lowest sum of squared time-domain errors, no offset, no gain) for
comparison; :func:`sample_rolling_posterior` samples the block's likelihood (its weighted rows and the
nuisances' prior) with the compiled ensemble sampler.

Example::

    fit = fit_rolling(profiles, geometry, ring)          # k_tread, each run's gain and angle offset
    fit.values["k_tread"], fit.extra["gain"], fit.extra["angle_offset_deg"]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import equinox as eqx
import jax
import numpy as np

from ringfit.errors import InputError
from ringfit.fit.engine import AbstractResiduals, Problem, least_squares, sum_of_squares_batch
from ringfit.fit.least_squares import RING_COORDS, RING_FIELDS, ring_from_vector, ring_vector
from ringfit.fit.priors import BOUNDS
from ringfit.fit.profile_block import (SENSOR_FIELDS, RollingData, block_rows, decrement_tol,
                                       fit_profile_block, harmonic_rows,
                                       nuisance_coords, nuisance_names, nuisance_prior, nuisance_start, profile_basis,
                                       read_through, rolling_data, sensor_coords, sensor_names, sensor_prior,
                                       sensor_reading, sensor_start)
from ringfit.fit.result import FitResult
from ringfit.io.profiles import grid_angles_deg
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, as_traced
from ringfit.physics.profile import FlatOrDrum, ProfileModel, flat_or_drum, full_band, profile_channels
from ringfit.physics.operating import OperatingPoint
from ringfit.physics.rolling import RingModel
from ringfit.physics.sensor import SensorModel

#: The one angle offset a rolling fit once freed for every profile; refused in ``free`` now that the profile
#: block fits each run's angle offset and gain (:func:`ringfit.fit.profile_block.nuisance_names`).
ANGLE_OFFSET = "angle_offset"
#: Ring parameters a rolling fit may free (log); each run's angle offset and gain are always fitted.
ROLLING_FREE = ("k_tread", "damping_ratio", "ei", "kw", "kv", "rho_a")


class RollingArrays(eqx.Module):
    """What the rolling residuals need besides θ: geometry, operating points ``(P,)``, the profiles' harmonic rows
    ``measured`` ``(P, 2, 2H)`` (:func:`ringfit.fit.profile_block.harmonic_rows`) and their σ (same shape)."""

    geometry: TyreGeometry
    omega: jax.Array
    load: jax.Array
    roads: FlatOrDrum
    band: jax.Array
    measured: jax.Array
    sigma: jax.Array


class RollingResiduals(AbstractResiduals):
    """The profile block's rows ``(model − measured)/σ`` of every profile, channel and revolution harmonic (real
    then imaginary parts); aux: the model's channels as each run reads them ``(P, 2, M)`` [m/s²].

    θ = the ring fields (:data:`ringfit.fit.least_squares.RING_FIELDS`) then per profile its angle offset [rad]
    and gain (:func:`ringfit.fit.profile_block.nuisance_names`), then with :attr:`sensor` per profile its sensor's
    nuisances (:func:`ringfit.fit.profile_block.sensor_names`). Two stages (the engine's two-stage model, as
    :class:`ringfit.fit.identify.JointResiduals`): the rolling solve of every profile (the one forward model,
    :func:`ringfit.physics.profile.profile_channels`; with :attr:`sensor` the reading's bilinear basis in the liner
    offset and tilt, :func:`ringfit.fit.profile_block.sensor_basis`), then each run's reading through its sensor,
    offset and gain (:func:`ringfit.fit.profile_block.sensor_reading`, :func:`~ringfit.fit.profile_block.read_through`)
    — the nuisances' tangents skip the solve.
    """

    n_profiles: int = eqx.field(static=True)
    model: ProfileModel = eqx.field(static=True)
    solver: ContactSolver = eqx.field(static=True)
    #: highest harmonic compared (:func:`ringfit.fit.profile_block.profile_band`; 0: M/2 − 1)
    k_top: int = eqx.field(static=True, default=0)
    #: each profile read through its sensor's own nuisances (θ's last 4P entries), as identify's ``sensor``
    sensor: bool = eqx.field(static=True, default=False)

    @property
    def readout(self) -> tuple[int, ...]:
        """θ indices of the profiles' nuisances (angle offset, gain per profile; with :attr:`sensor` each run's sensor
        nuisances): they act after the solve."""
        base = len(RING_FIELDS)
        n = (2 + (len(SENSOR_FIELDS) if self.sensor else 0)) * self.n_profiles
        return tuple(range(base, base + n))

    def __call__(self, theta, data: RollingArrays):
        return self.outer(self.inner(theta, data), theta, data)

    def inner(self, theta, data: RollingArrays):
        """The expensive stage: the model's channels ``(P, 2, M)`` before each run's reading (with :attr:`sensor`,
        their bilinear basis ``(P, 4, 2, M)``)."""
        ring = ring_from_vector(theta)
        if not self.sensor:
            return profile_channels(self.model, ring, data.geometry, data.omega, data.load, data.roads, data.band,
                                    0.0, self.solver)
        ring_p = self.model.ring(ring)
        return jax.vmap(lambda om, fz, road, band: profile_basis(self.model, ring_p, data.geometry,
                                                                OperatingPoint(om, fz, road), band, self.solver))(
            data.omega, data.load, data.roads, data.band)

    def outer(self, channels, theta, data: RollingArrays):
        """The cheap stage: each run's reading of ``channels`` and its harmonic rows, divided by their σ."""
        base = len(RING_FIELDS)
        P = self.n_profiles
        if self.sensor:  # each run's sensor: (e, γ) on its basis, its high-pass and tangential gain
            start, F = base + 2 * P, len(SENSOR_FIELDS)
            channels = sensor_reading(channels, data.omega, theta[start : start + F * P].reshape(P, F))
        read = read_through(channels, theta[base : base + 2 * P : 2], theta[base + 1 : base + 2 * P : 2])
        rows = harmonic_rows(read, k_top=self.k_top)
        return ((rows - data.measured) / data.sigma).ravel(), read


class _GridResiduals(AbstractResiduals):
    """The source study's error (:func:`tread_stiffness_sweep`): ``model(φ_j) − measured(φ_j)`` [m/s²] on the
    model grid, no angle offset, no gain; θ = the ring fields."""

    model: ProfileModel = eqx.field(static=True)
    solver: ContactSolver = eqx.field(static=True)

    def __call__(self, theta, data: RollingArrays):
        ch = profile_channels(self.model, ring_from_vector(theta), data.geometry, data.omega, data.load, data.roads,
                              data.band, 0.0, self.solver)
        return (ch - data.measured).ravel(), ch


def rolling_coords(P: int, sensor: bool = False):
    """Solver coordinates of a rolling fit of ``P`` profiles: the ring's (log), then the profile block's
    nuisances (:func:`ringfit.fit.profile_block.nuisance_coords`), then with ``sensor`` each run's sensor's
    (:func:`ringfit.fit.profile_block.sensor_coords`)."""
    return RING_COORDS + nuisance_coords(P) + (sensor_coords(P) if sensor else ())


def check_rolling_free(free) -> tuple[str, ...]:
    """Validate the names of the ring parameters to fit (see :data:`ROLLING_FREE`)."""
    free = tuple(free)
    if not free:
        raise InputError("no free parameter to fit")
    for k in free:
        if k == ANGLE_OFFSET:
            raise InputError("cannot free 'angle_offset': fit-rolling now fits each run's angle offset and gain "
                             "(the profile block's nuisances, always fitted); list ring parameters only: "
                             f"{', '.join(ROLLING_FREE)}")
        if k not in ROLLING_FREE:
            raise InputError(f"cannot fit {k!r} to rolling profiles; choose from {', '.join(ROLLING_FREE)}")
    if len(set(free)) != len(free):
        raise InputError(f"parameter listed twice in {list(free)}")
    return free


def _arrays(data: RollingData, geometry, measured, sigma, M) -> RollingArrays:
    P = data.measured.shape[0]
    return as_traced(RollingArrays(geometry=geometry, omega=data.omega, load=data.load,
                                   roads=flat_or_drum(data.drum_diameter, P), band=full_band(P, M),
                                   measured=measured, sigma=sigma))


def _problem(data: RollingData, geometry, rows: dict, sigma, model, sensor, solver, nuisances: bool) -> Problem:
    P, _, M = data.measured.shape
    residuals = RollingResiduals(P, ProfileModel(ring_model=model, sensor=sensor), solver, k_top=rows["k_top"],
                                 sensor=nuisances)
    prior = nuisance_prior(P).combine(sensor_prior(P)) if nuisances else nuisance_prior(P)
    return Problem(residuals, _arrays(data, geometry, rows["measured"], sigma, M), rolling_coords(P, nuisances),
                   prior=prior, sigma="fixed", plausible=BOUNDS, data_label="these profiles")


def fit_rolling(
    profiles,
    geometry: TyreGeometry,
    ring: RingParams,
    *,
    free=("k_tread",),
    model: RingModel = RingModel(),
    sensor: SensorModel = SensorModel(),
    solver: ContactSolver = ContactSolver(),
    rolling_radius_m: float | None = None,
    max_steps: int | None = None,
    rtol: float = 1e-8,
    atol: float = 1e-8,
    sensor_nuisances: bool = True,
) -> FitResult:
    """Fit ring parameters (default: the tread stiffness) to one or more rolling profiles, with each run's angle
    offset and gain, on the profile block's likelihood (module docstring).

    **Arguments:**

    - ``profiles``: :class:`~ringfit.io.profiles.Profile` objects (any speeds,
      all on a flat road or all on drums), or a prepared :class:`RollingData`.
    - ``geometry``, ``ring``: the tyre and the ring from the natural-frequency
      fit; parameters not in ``free`` stay at these values, free ones start there.
    - ``free``: subset of :data:`ROLLING_FREE` (ring parameters); the nuisances
      ``angle_offset_i`` [rad] (φ = α + offset) and ``gain_i`` are always fitted.
    - ``model``, ``sensor``, ``solver``: ring form, sensor layers (default §6
      baseline), grid (see :mod:`ringfit.physics`).
    - ``rtol``, ``atol``: optimistix Cauchy termination (on the solver coordinates and the weighted rows),
      as ``identify``'s.
    - ``sensor_nuisances``: each run is also read through its sensor's own nuisances (tilt gain, IEPE corner,
      liner offset, tangential gain: :data:`~ringfit.fit.profile_block.SENSOR_FIELDS`, with the profile block's
      priors), as ``identify`` reads profiles (its default ``sensor``): the same likelihood, and the same answer
      (``tests/test_rolling_block.py``). On by default: profiles read through a sensor of typical tilt (γ 0.6), IEPE
      corner (0.8 Hz) and liner offset (2 mm) gave the plain reading a k_tread 97 % low, "converged", 730 σ from the
      truth; the sensor's nuisances recover it within its interval (``tests/test_rolling_block.py``). ``False``: the
      plain reading of ``sensor`` (the §6 baseline, the source study's reading), about 8 steps a pass instead of
      about 40 where the data tell the nuisances weakly (a corner far below the first harmonic: Gauss–Newton
      converges on it only linearly, and with the nuisances the passes stop at the decrement
      :data:`~ringfit.fit.engine.DECREMENT_TOL`, docs/physics.md §11 *convergence*).
    - ``max_steps``: per pass (default 64; with ``sensor_nuisances`` identify's 256).

    **Returns:** :class:`~ringfit.fit.result.FitResult` of the last pass (values SI; angle offsets in rad).
    ``extra``: ``model`` (the fitted model as each run reads it) and ``measured`` ``(P, 2, M)`` on the grid,
    ``angle_deg`` ``(M,)``, ``omega``, ``speed_kmh``, ``omega_source``, ``harmonics`` ``(H,)`` (k compared),
    ``model_rows``/``measured_rows`` ``(P, 2, 2H)``, ``sigma_ms2`` ``(P, 2, H)`` (the noise model's σ per
    profile, channel and harmonic the last pass weighted by), ``rms_ms2`` (RMS of the unweighted harmonic
    residual rows), ``gain``/``angle_offset_deg`` ``(P,)`` with ``gain_sd``/``angle_offset_sd_deg``,
    ``passes``, ``evaluations`` (model-evaluation equivalents, all passes), ``data``, ``ring``, ``geometry``;
    with ``sensor_nuisances`` also ``sensor`` (per field of :data:`~ringfit.fit.profile_block.SENSOR_FIELDS`, the
    runs' values ``(P,)``) and ``sensor_sd``. Never raises on non-convergence.

    Runs with one BLAS thread (as ``identify``): the contact solves' small LU factorisations run on XLA's own
    threads and the noise passes' algebra is on tall, thin matrices (thousands of rows × ≤ 15 columns), where a
    threaded BLAS only synchronises — on a loaded two-core machine it made the warm four-speed fit of
    ``benchmarks/bench_rolling.py`` take 1.3–2.1 s of CPU instead of 0.25–0.33 s (not on every run: when the
    BLAS threads found the cores busy).
    """
    from ringfit._threads import small_matrix_threads  # noqa: PLC0415 (as identify's)

    with small_matrix_threads():
        return _fit_rolling(profiles, geometry, ring, free=free, model=model, sensor=sensor, solver=solver,
                            rolling_radius_m=rolling_radius_m,
                            max_steps=max_steps if max_steps is not None else (256 if sensor_nuisances else 64),
                            rtol=rtol, atol=atol, nuisances=bool(sensor_nuisances))


def _fit_rolling(profiles, geometry, ring, *, free, model, sensor, solver, rolling_radius_m, max_steps, rtol,
                 atol, nuisances) -> FitResult:
    data = profiles if isinstance(profiles, RollingData) else rolling_data(
        profiles, geometry, ring, solver=solver, sensor=sensor, model=model, rolling_radius_m=rolling_radius_m)
    free_ring = check_rolling_free(free)
    P, _, M = data.measured.shape
    rows = block_rows(data)
    free = free_ring + nuisance_names(P) + (sensor_names(P) if nuisances else ())
    start = [ring_vector(ring), nuisance_start(P)] + ([sensor_start(P)] if nuisances else [])
    state = dict(theta=np.concatenate(start), evaluations=0)

    def fit_at(sigma):  # one pass, warm-started from the last converged one
        fit = least_squares(_problem(data, geometry, rows, sigma, model, sensor, solver, nuisances), state["theta"],
                            free, max_steps=max_steps, rtol=rtol, atol=atol,
                            dtol=decrement_tol(nuisances))
        state["evaluations"] += evaluations_used(fit.iterations, len(free_ring))
        if fit.converged:
            state["theta"] = fit.theta.copy()
        return fit

    # σ weights the fit, the fit's residual gives σ (the profile block's noise model, as identify's passes)
    fit, used, passes = fit_profile_block(fit_at, rows["sigma"], k_min=rows["k_min"])
    evaluations = state["evaluations"]
    read = np.asarray(fit.extra.pop("aux"))
    model_rows = np.asarray(harmonic_rows(jax.numpy.asarray(read), k_top=rows["k_top"]))
    H = rows["measured"].shape[-1] // 2
    names = nuisance_names(P)
    fit.extra.update(
        model=read, measured=data.measured, angle_deg=grid_angles_deg(M),
        omega=data.omega, speed_kmh=data.speed_kmh, omega_source=data.omega_source,
        harmonics=np.arange(rows["k_min"], rows["k_min"] + H), model_rows=model_rows, measured_rows=rows["measured"],
        sigma_ms2=np.asarray(used)[..., :H],
        rms_ms2=math.sqrt(float(np.mean((model_rows - rows["measured"]) ** 2))),
        gain=np.array([fit.values[n] for n in names[1::2]]),
        gain_sd=np.array([fit.stderr[n] for n in names[1::2]]),
        angle_offset_deg=np.degrees([fit.values[n] for n in names[0::2]]),
        angle_offset_sd_deg=np.degrees([fit.stderr[n] for n in names[0::2]]),
        passes=passes, evaluations=evaluations, data=data, ring=fitted_ring(fit), geometry=geometry,
    )
    if nuisances:
        fit.extra["sensor"] = {f: np.array([fit.values[f"{f}_{i + 1}"] for i in range(P)]) for f in SENSOR_FIELDS}
        fit.extra["sensor_sd"] = {f: np.array([fit.stderr[f"{f}_{i + 1}"] for i in range(P)]) for f in SENSOR_FIELDS}
    return fit


def evaluations_used(steps: int, k: int) -> int:
    """Model-evaluation equivalents of a Levenberg–Marquardt fit with k parameters through the solve.

    Each step evaluates the residuals and linearises them (one primal solve and
    k tangent solves, counted as 1 + k evaluations); the final Jacobian for the
    covariance adds 1 + k. The readout's nuisances (each run's gain and offset) pass no tangent through the
    solve and are not counted.
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

    The error is the study's: the sum of squared time-domain residuals on the model grid, no angle offset, no
    gain (:func:`sum_of_squares` gives the same error of a :func:`fit_rolling` result, read through its fitted
    nuisances).
    """
    data = profiles if isinstance(profiles, RollingData) else rolling_data(
        profiles, geometry, ring, solver=solver, sensor=sensor, model=model, rolling_radius_m=rolling_radius_m)
    P, _, M = data.measured.shape
    arrays = as_traced(RollingArrays(geometry=geometry, omega=data.omega, load=data.load,
                                     roads=flat_or_drum(data.drum_diameter, P), band=full_band(P, M),
                                     measured=data.measured, sigma=np.ones(())))
    problem = Problem(_GridResiduals(ProfileModel(ring_model=model, sensor=sensor), solver), arrays, RING_COORDS,
                      sigma="estimate", plausible=BOUNDS, data_label="these profiles")
    k_grid = np.asarray(k_grid, dtype=np.float64)
    thetas = np.tile(ring_vector(ring), (k_grid.size, 1))
    thetas[:, RING_FIELDS.index("k_tread")] = k_grid
    sse = sum_of_squares_batch(problem, thetas, chunk=batch)
    i = int(np.argmin(sse))
    return SweepResult(k_grid, sse, float(k_grid[i]), float(sse[i]), int(k_grid.size))


def sum_of_squares(result: FitResult) -> float:
    """The source study's error of a :func:`fit_rolling` result: the sum of squared time-domain residuals
    [(m/s²)²] on the model grid of the fitted model as each run reads it (:func:`tread_stiffness_sweep`'s error)."""
    return float(np.sum((np.asarray(result.extra["model"]) - np.asarray(result.extra["measured"])) ** 2))


def sample_rolling_posterior(result: FitResult, *, walkers: int | None = None, steps: int = 400, seed: int = 0,
                             progress: bool = False):
    """Posterior of a :func:`fit_rolling` result's free parameters (the ring's and each run's gain and angle
    offset): :func:`ringfit.fit.posterior.sample` for exactly ``steps`` steps.

    Likelihood: the profile block's — independent Gaussian harmonic rows with the noise model's σ the fit's last
    pass weighted by (``result.extra["sigma_ms2"]``) — and the nuisances' prior
    (:func:`ringfit.fit.profile_block.nuisance_prior`); flat in ``log θ`` within
    :data:`ringfit.fit.priors.BOUNDS` and the nuisances' bounds; walkers (default: the smallest even number ≥ 16
    and ≥ twice the free parameters) start in a small ball (¼ of the standard error) at the optimum.
    """
    from ringfit.fit.posterior import sample

    if walkers is None:
        walkers = max(16, 2 * len(result.names))
    return sample(result, walkers=walkers, min_steps=steps, max_steps=steps, check_every=steps, seed=seed,
                  progress=progress, spread=0.25, meta={"model": "rolling"})


def fitted_ring(result: FitResult) -> RingParams:
    """The :class:`RingParams` of a rolling fit (free parameters at their optimum)."""
    return RingParams(**{k: result.values[k] for k in RING_FIELDS})


__all__ = [
    "fit_rolling", "rolling_data", "RollingData", "RollingResiduals", "tread_stiffness_sweep", "SweepResult",
    "sample_rolling_posterior", "fitted_ring", "ROLLING_FREE", "ANGLE_OFFSET", "evaluations_used",
    "sum_of_squares", "check_rolling_free", "RollingArrays", "rolling_coords", "block_rows",
]
