"""Fit the tread stiffness (and optionally damping, angle offset) to rolling acceleration profiles.

Model: steady rolling ring with tread-spring contact (PHYSICS.md §4,
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
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from ringfit.errors import InputError
from ringfit.fit.least_squares import RING_FIELDS, ring_from_log, ring_vector
from ringfit.fit.priors import BOUNDS
from ringfit.fit.result import FitResult, covariance_from_jacobian, parameter_flags, solver_flags, solver_status
from ringfit.io.profiles import resample_profile
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, as_traced, solve_rolling, solve_rolling_jit
from ringfit.physics.operating import Drum, FlatRoad, OperatingPoint, rolling_radius
from ringfit.physics.rolling import RingModel
from ringfit.physics.sensor import SensorModel, sensor_signals, shift_angle

#: Name of the angle-offset nuisance parameter [rad] (PHYSICS.md §5 layer 6).
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

    @property
    def roads(self):
        """A road PyTree with a leading batch axis (or the leafless FlatRoad)."""
        return FlatRoad() if self.drum_diameter is None else Drum(jnp.asarray(self.drum_diameter))


def rolling_data(
    profiles, geometry: TyreGeometry, ring: RingParams, *,
    solver: ContactSolver = ContactSolver(), sensor: SensorModel = SensorModel(), model: RingModel = RingModel(),
    rolling_radius_m: float | None = None,
) -> RollingData:
    """Put profiles on the model grid and work out Ω for each (DATA.md §3).

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
            road = FlatRoad() if p.drum_diameter_m is None else Drum(p.drum_diameter_m)
            standing = solve_rolling_jit(ring, geometry, OperatingPoint(0.0, p.load_n, road), model=model, solver=solver)
            r_e = float(rolling_radius(geometry.outer_radius, standing.deflection))
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


def model_profiles(ring: RingParams, geometry: TyreGeometry, omega, load, roads, offset=0.0, *,
                   model: RingModel = RingModel(), sensor: SensorModel = SensorModel(),
                   solver: ContactSolver = ContactSolver()):
    """Sensor channels for a batch of operating points, ``(P, 2, M)`` [m/s²] on φ_j + ``offset``.

    ``omega``, ``load`` ``(P,)``; ``roads`` a road with ``(P,)`` leaves or leafless. Pure JAX (vmap over P).
    """

    def one(om, fz, road):
        sol = solve_rolling(ring, geometry, OperatingPoint(om, fz, road), model=model, solver=solver)
        return jnp.stack(sensor_signals(sol, geometry, sensor))

    channels = jax.vmap(one)(jnp.asarray(omega), jnp.asarray(load), roads)
    return shift_angle(channels, offset)


class _Spec(eqx.Module):
    """Static description of the free parameters and the model structure."""

    free_index: tuple = eqx.field(static=True)
    has_offset: bool = eqx.field(static=True)
    model: RingModel
    sensor: SensorModel
    solver: ContactSolver


def _residuals(y, args, spec: _Spec):
    base, geometry, measured, omega, load, roads = args
    k = len(spec.free_index)
    ring = ring_from_log(y[:k], spec.free_index, base)
    offset = y[k] if spec.has_offset else 0.0
    ch = model_profiles(ring, geometry, omega, load, roads, offset, model=spec.model, sensor=spec.sensor,
                        solver=spec.solver)
    return (ch - measured).ravel()


def _residuals_and_jacobian(y, args, spec: _Spec):
    """Residuals ``(m,)`` and their Jacobian ``(m, k)`` by forward mode: one primal and one vmapped tangent pass."""

    def with_aux(y_):
        r = _residuals(y_, args, spec)
        return r, r

    jac, res = jax.jacfwd(with_aux, has_aux=True)(y)
    return res, jac


def _dense_jacobian_residuals(args, spec: _Spec):
    """``y -> residuals`` whose JVP is the dense product ``J(y) ẏ`` (J from :func:`_residuals_and_jacobian`).

    The solver linearises this once per step: the model is traced once (primal +
    k tangents) and every further Jacobian product it needs is a small matrix
    product, which keeps the compiled fit small. Differentiates in ``y`` only.
    """

    @jax.custom_jvp
    def fn(y):
        return _residuals(y, args, spec)

    @fn.defjvp
    def fn_jvp(primals, tangents):
        (y,), (dy,) = primals, tangents
        res, jac = _residuals_and_jacobian(y, args, spec)
        return res, jac @ dy

    return fn


@eqx.filter_jit
def _solve(y0, args, spec, max_steps, rtol, atol):
    fn = _dense_jacobian_residuals(args, spec)
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.SVD())
    sol = optx.least_squares(lambda y, _: fn(y), solver, y0, max_steps=max_steps, throw=False)
    # Residuals and Jacobian at the returned point from the solver's last
    # linearisation (its state keeps them for the accepted y): no further model trace.
    f_info = getattr(sol.state, "f_info", None)
    if f_info is None:  # a solver state without it (other optimistix versions): evaluate once more
        res, jac = _residuals_and_jacobian(sol.value, args, spec)
    else:
        res, jac = f_info.residual, f_info.jac.as_matrix()
    return sol.value, sol.result, sol.stats["num_steps"], res, jac


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


def _problem(data: RollingData, geometry, ring, free, model, sensor, solver):
    free = check_rolling_free(free)
    ring_free = tuple(k for k in free if k != ANGLE_OFFSET)
    free_index = tuple(RING_FIELDS.index(k) for k in ring_free)
    base = ring_vector(ring)
    spec = _Spec(free_index, ANGLE_OFFSET in free, model, sensor, solver)
    args = (jnp.asarray(base), as_traced(geometry), jnp.asarray(data.measured), jnp.asarray(data.omega),
            jnp.asarray(data.load), data.roads)
    return free, ring_free, free_index, base, as_traced(spec), args


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
    free, ring_free, free_index, base, spec, args = _problem(data, geometry, ring, free, model, sensor, solver)
    y0 = list(np.log(base[list(free_index)]))
    if spec.has_offset:
        y0.append(math.radians(initial_offset_deg))
    y0 = np.array(y0)
    if not np.all(np.isfinite(y0)):
        raise InputError(f"initial values of {list(ring_free)} must be positive and finite")
    y, result, steps, res, jac = _solve(jnp.asarray(y0), args, spec, max_steps, rtol, atol)
    y, res, jac, steps = np.asarray(y), np.asarray(res), np.asarray(jac), int(steps)
    return _fit_result(free, ring_free, base, y, result, steps, res, jac, data, geometry, spec)


def evaluations_used(steps: int, k: int) -> int:
    """Model-evaluation equivalents of a Levenberg–Marquardt fit with k parameters.

    Each step evaluates the residuals and linearises them (one primal solve and
    k tangent solves, counted as 1 + k evaluations); the final Jacobian for the
    covariance adds 1 + k.
    """
    return (steps + 1) * (1 + k)


def _fit_result(free, ring_free, base, y, result, steps, res, jac, data, geometry, spec) -> FitResult:
    status, message = solver_status(result)
    m = res.size
    k = len(free)
    values = dict(zip(RING_FIELDS, base.tolist()))
    values.update({name: float(np.exp(v)) for name, v in zip(ring_free, y)})
    if spec.has_offset:
        values[ANGLE_OFFSET] = np.float64(y[-1])
    chi2 = float(res @ res)
    dof = max(m - k, 1)
    sigma = math.sqrt(chi2 / dof)
    scale = sigma if sigma > 0 else 1.0
    cov = covariance_from_jacobian(jac / scale)
    stderr = {}
    for i, name in enumerate(free):
        sd = math.sqrt(cov[i, i]) if np.isfinite(cov[i, i]) else math.inf
        stderr[name] = sd if name == ANGLE_OFFSET else values[name] * sd
    ring = RingParams(**{f: values[f] for f in RING_FIELDS})
    model = res.reshape(data.measured.shape) + data.measured
    flags = solver_flags(status, message) + parameter_flags(ring_free, values, stderr, data="these profiles")
    M = data.measured.shape[-1]
    return FitResult(
        status=status,
        message=message or "converged",
        names=tuple(free),
        values=values,
        stderr=stderr,
        covariance_log=cov,
        residuals=res / scale,
        jacobian=jac / scale,
        n_data=m,
        iterations=steps,
        flags=flags,
        extra=dict(
            model=model, measured=data.measured, angle_deg=-180.0 + 360.0 * np.arange(M) / M,
            omega=data.omega, speed_kmh=data.speed_kmh, omega_source=data.omega_source,
            sigma_ms2=sigma, rms_ms2=math.sqrt(chi2 / m), evaluations=evaluations_used(steps, k),
            data=data, ring=ring, geometry=geometry, spec=spec,
        ),
    )


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
    _, _, _, _, spec, args = _problem(data, geometry, ring, ("k_tread",), model, sensor, solver)
    k_grid = np.asarray(k_grid, dtype=np.float64)
    sse = _in_fixed_chunks(lambda ys: _batched_sse(ys, args, spec), np.log(k_grid)[:, None], batch)
    i = int(np.argmin(sse))
    return SweepResult(k_grid, sse, float(k_grid[i]), float(sse[i]), int(k_grid.size))


def _in_fixed_chunks(batched_fn, ys, size: int) -> np.ndarray:
    """``batched_fn`` over the rows of ``ys`` ``(G, k)`` in chunks of exactly ``min(size, G)`` rows.

    The last chunk is padded with copies of its last row (results dropped), so a
    jitted ``batched_fn`` compiles once per chunk size, not once per remainder.
    """
    ys = np.asarray(ys, dtype=np.float64)
    n = ys.shape[0]
    size = max(1, min(int(size), n))
    pad = -n % size
    if pad:
        ys = np.concatenate([ys, np.repeat(ys[-1:], pad, axis=0)])
    out = [np.asarray(batched_fn(jnp.asarray(ys[i : i + size]))) for i in range(0, ys.shape[0], size)]
    return np.concatenate(out)[:n]


@eqx.filter_jit
def _batched_sse(ys, args, spec):
    return jax.vmap(lambda y: jnp.sum(_residuals(y, args, spec) ** 2))(ys)


def sum_of_squares(result: FitResult) -> float:
    """Unweighted sum of squared residuals [(m/s²)²] of a :func:`fit_rolling` result."""
    return float(result.chi2 * result.extra["sigma_ms2"] ** 2)


# ----------------------------------------------------------------------------- posterior


@dataclass
class RollingPosterior:
    """emcee draws for a rolling fit.

    - ``names``: free parameters ``(k,)`` (positive ones sampled as logs, ``angle_offset`` linear).
    - ``chain``: ``(steps, walkers, k)`` in the sampler's space; ``log_prob`` ``(steps, walkers)``.
    - ``acceptance``: ``(walkers,)``; ``tau``: ``(k,)`` integrated autocorrelation times [steps]
      (NaN if the chain is too short to estimate them); ``burn``: steps discarded; ``sigma_ms2``:
      the residual σ used in the likelihood.
    """

    names: tuple[str, ...]
    chain: np.ndarray
    log_prob: np.ndarray
    acceptance: np.ndarray
    tau: np.ndarray
    burn: int
    sigma_ms2: float

    @property
    def samples(self) -> np.ndarray:
        """``(draws, k)`` in SI units (rad for the angle offset)."""
        flat = self.chain[self.burn :].reshape(-1, len(self.names)).copy()
        for i, name in enumerate(self.names):
            if name != ANGLE_OFFSET:
                flat[:, i] = np.exp(flat[:, i])
        return flat

    @property
    def converged(self) -> bool:
        """Chain longer than 50 integrated autocorrelation times."""
        return bool(np.all(np.isfinite(self.tau)) and self.chain.shape[0] > 50 * np.max(self.tau))

    def summary(self) -> dict[str, tuple[float, float, float]]:
        """name -> (16 %, 50 %, 84 %) quantiles in SI units."""
        s = self.samples
        return {k: tuple(np.percentile(s[:, i], [16, 50, 84]).tolist()) for i, k in enumerate(self.names)}


def _log_probability(y, args, spec, sigma, lo, hi):
    r = _residuals(y, args, spec)
    value = -0.5 * jnp.sum(r**2) / sigma**2
    inside = jnp.all((y >= lo) & (y <= hi))
    value = jnp.where(inside, value, -jnp.inf)
    return jnp.where(jnp.isnan(value), -jnp.inf, value)


@eqx.filter_jit
def _batched_log_probability(ys, args, spec, sigma, lo, hi):
    return jax.vmap(lambda y: _log_probability(y, args, spec, sigma, lo, hi))(ys)


def sample_rolling_posterior(
    result: FitResult, *, walkers: int = 16, steps: int = 400, burn: int | None = None, seed: int = 0,
    progress: bool = False,
) -> RollingPosterior:
    """Posterior of a :func:`fit_rolling` result's free parameters with emcee.

    Likelihood: independent Gaussians with the residual σ of the fit
    (``result.extra["sigma_ms2"]``); prior: flat in ``log θ`` within
    :data:`ringfit.fit.priors.BOUNDS` (flat within ±10° for the angle offset).
    ``emcee.EnsembleSampler(vectorize=True)`` calls one jitted, vmapped
    log-probability (:func:`ringfit.fit.posterior.run_ensemble`, here for exactly
    ``steps`` steps); walkers start in a small ball (¼ of the standard error) at the optimum.
    """
    from ringfit.fit.posterior import run_ensemble

    spec = result.extra["spec"]
    data = result.extra["data"]
    ring = result.extra["ring"]
    free = result.names
    free, ring_free, free_index, base, spec, args = _problem(
        data, result.extra["geometry"], ring, free, spec.model, spec.sensor, spec.solver)
    y_opt = np.array([math.log(result.values[k]) if k != ANGLE_OFFSET else float(result.values[k]) for k in free])
    lo = np.array([math.log(BOUNDS[k][0]) if k != ANGLE_OFFSET else -ANGLE_OFFSET_BOUND for k in free])
    hi = np.array([math.log(BOUNDS[k][1]) if k != ANGLE_OFFSET else ANGLE_OFFSET_BOUND for k in free])
    sd = np.sqrt(np.clip(np.diag(result.covariance_log), 1e-12, 1.0))
    sigma = jnp.asarray(result.extra["sigma_ms2"])
    lo_j, hi_j = jnp.asarray(lo), jnp.asarray(hi)

    # emcee evaluates all walkers once, then each half of the ensemble per move:
    # fixed chunks of half the walkers keep that to one compilation.
    def log_prob(ys):
        out = _in_fixed_chunks(lambda y: _batched_log_probability(y, args, spec, sigma, lo_j, hi_j), ys,
                               (walkers + 1) // 2)
        return np.where(np.isnan(out), -np.inf, out)

    rng = np.random.default_rng(seed)
    p0 = y_opt + 0.25 * sd * rng.standard_normal((walkers, len(free)))
    sampler, tau = run_ensemble(log_prob, p0, min_steps=steps, max_steps=steps, seed=seed, progress=progress)
    burn = int(burn if burn is not None else min(steps // 2, max(int(3 * np.nanmax(tau)), steps // 5)))
    return RollingPosterior(tuple(free), sampler.get_chain(), sampler.get_log_prob(),
                            sampler.acceptance_fraction, np.asarray(tau), burn, float(sigma))


def fitted_ring(result: FitResult) -> RingParams:
    """The :class:`RingParams` of a rolling fit (free parameters at their optimum)."""
    return RingParams(**{k: result.values[k] for k in RING_FIELDS})


__all__ = [
    "fit_rolling", "rolling_data", "RollingData", "model_profiles", "tread_stiffness_sweep", "SweepResult",
    "sample_rolling_posterior", "RollingPosterior", "fitted_ring", "ROLLING_FREE", "ANGLE_OFFSET",
    "evaluations_used", "sum_of_squares", "check_rolling_free",
]
