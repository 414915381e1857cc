"""The estimate as a problem on the one engine (docs/physics.md §10): parameters, coordinates, settings,
data arrays and residuals.

θ = (load, gain, angle offset, high-pass corner, tilt, k_trd) (:data:`PARAMETERS`, :data:`COORDS`); the
residuals are the weighted radial harmonics 2…k_max of :func:`ringfit.physics.profile.profile_channels`
less the measured ones (:class:`EstimateResiduals` on :class:`EstimateArrays`); :func:`estimate_problem`
makes the :class:`~ringfit.fit.engine.Problem` that :mod:`ringfit.fit.estimate.load` and
:mod:`ringfit.fit.estimate.revolutions` solve. No solver of its own.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp

from ringfit.fit.engine import LINEAR, LOG, AbstractResiduals, Coordinate, GaussianPrior, Problem, SigmaMode
from ringfit.fit.estimate.harmonics import harmonic_amplitudes, amplitude_rows
from ringfit.fit.least_squares import RING_FIELDS
from ringfit.io.tyre import LINEAR_COVARIANCE
from ringfit.fit.profile_block import GAIN_RANGE, sensor_coordinate, sensor_prior_entry  # one sensor for every reader
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, as_traced
from ringfit.physics.profile import FlatOrDrum, ProfileModel, full_band, profile_channels
from ringfit.physics.sensor import STANDARD_GRAVITY

LOAD, GAIN, ANGLE_OFFSET, CORNER, TILT, K_TREAD = "load_n", "gain", "angle_offset", "corner_hz", "tilt_gain", "k_tread"
#: Every parameter of the estimate problem, in θ order.
PARAMETERS = (LOAD, GAIN, ANGLE_OFFSET, CORNER, TILT, K_TREAD)
#: Plausible loads [N]: the load's bounds (a fit that ends there has failed).
LOAD_RANGE = (200.0, 20000.0)
# Weak priors on the sensor nuisances (the profile block's, :data:`ringfit.fit.profile_block.CORNER_PRIOR` and
# :data:`~ringfit.fit.profile_block.TILT_PRIOR`): they keep the nuisances finite where the data say little (a high
# speed, no gravity) and are propagated like any other parameter.

COORDS = (
    Coordinate(LOAD, LOG, lo=LOAD_RANGE[0], hi=LOAD_RANGE[1]),
    Coordinate(GAIN, LOG, lo=GAIN_RANGE[0], hi=GAIN_RANGE[1]),
    Coordinate(ANGLE_OFFSET, LINEAR, scale=math.radians(1.0)),
    sensor_coordinate(CORNER, bounded=False),
    sensor_coordinate(TILT),
    Coordinate(K_TREAD, LOG, lo=1e5, hi=1e9),
)


@dataclass(frozen=True)
class EstimateSettings:
    """How the estimate is computed.

    - ``n_grid``: model grid M of the contact solve (docs/physics.md §4.4–4.5). The fitted harmonics
      converge by M = 256, but the patch's discrete active set makes the load–shape relation a
      staircase: fitting M = 2048 profiles, M = 256 is biased by up to 1 % (at some loads), 384 by
      0.3 %, 512 by < 0.1 % (``benchmarks/bench_estimate.py``), up to 0.24 % at 1.5–2 kN against an
      independent finite-difference truth; ``grid_check`` carries it into the interval.
    - ``k_max``: highest revolution harmonic fitted (lowered to the data's band limit).
    - ``window_deg``: contact candidate window (the patch must lie inside).
    - ``k_tread_sd``: σ of ln k_trd; ``None`` = fixed at the tyre file's value (when the file has one).
    - ``highpass_order``: stages of the modelled high-pass (1: the IEPE sensor).
    - ``max_steps``, ``rtol``, ``atol``: Levenberg–Marquardt step cap and Cauchy tolerances (solver
      coordinates: log load, degrees of offset; residual rows in units of their σ). A nuisance that only its
      prior holds (the high-pass corner at a high speed, the tilt without gravity) lies on a cost flat to
      ~1e-4 of χ², along which the solver creeps: a reweighted pass took up to ~170 steps to meet the tolerances
      on ``benchmarks/bench_estimate.py``'s red-noise profiles, hence the cap of 300.
    - ``revolution_window_deg``: candidate window for the per-revolution fits (the patch must fit; a
      smaller window is a smaller dense contact solve: 20° holds loads up to ~10 kN on the Table 9 tyre
      and is widened automatically when a recording's patch needs more).
    - ``curve_points``, ``curve_grid``: loads and model grid of the load curves (patch, feature).
    - ``grid_check``: refine the grid once at the fit (M → 2M) and carry the load's shift into its
      interval (docs/physics.md §10, *the estimator's own grid*); for the state estimate, fit the 4M model by
      defect correction and carry the grid error left (§13.4 *the model's grid*); ``False`` leaves the M model
      and the interval statistical.
    """

    n_grid: int = 512
    k_max: int = 40
    window_deg: float = 35.0
    k_tread_sd: float | None = None
    highpass_order: int = 1
    max_steps: int = 300
    rtol: float = 1e-6
    atol: float = 1e-6
    revolution_window_deg: float = 20.0
    curve_points: int = 48
    curve_grid: int = 512
    grid_check: bool = True

    @property
    def solver(self) -> ContactSolver:
        return ContactSolver(n_grid=self.n_grid, window_deg=self.window_deg)

    def profile_model(self) -> ProfileModel:
        """The forward model: baseline ring, gravity on, tilt and high-pass set per fit (traced)."""
        return ProfileModel().with_sensor(gravity=STANDARD_GRAVITY, highpass_order=self.highpass_order)


class EstimateArrays(eqx.Module):
    """Data of one estimate (leading axis P = 1 profile; a batch adds an axis in front).

    - ``geometry``, ``ring``: the tyre (k_trd is replaced by θ's).
    - ``omega``: ``(P,)`` Ω [rad/s]; ``roads``: :class:`~ringfit.physics.profile.FlatOrDrum` ``(P,)``.
    - ``response``: ``(P, K)`` the acquisition's gain on harmonics k_min…k_max (resampling, bin averaging; 1 = none).
    - ``measured``: ``(P, 2K)`` radial harmonic rows (Re, Im) [m/s²]; ``weight``: ``(P, 2K)`` 1/σ per row.
    """

    geometry: TyreGeometry
    ring: RingParams
    omega: jax.Array
    roads: FlatOrDrum
    response: jax.Array
    measured: jax.Array
    weight: jax.Array


class EstimateResiduals(AbstractResiduals):
    """``weight·(model − measured)`` of the radial harmonics k_min…k_max; aux: the model rows ``(P, 2K)``.

    θ = (load [N], gain, angle offset [rad], high-pass corner [Hz], tilt γ, k_trd [N/m²]) —
    :data:`PARAMETERS`; the reading is :func:`ringfit.physics.profile.profile_channels` of
    ``profile`` with the corner and tilt set from θ, times the gain.
    """

    profile: ProfileModel = eqx.field(static=True)
    solver: ContactSolver = eqx.field(static=True)
    k_min: int = eqx.field(static=True)
    k_max: int = eqx.field(static=True)

    def channels(self, theta, data: EstimateArrays):
        """Model channels ``(P, 2, M)`` [m/s²] at θ (gain applied)."""
        load, gain, offset, corner, tilt, k_tread = (theta[i] for i in range(6))
        model = self.profile.with_sensor(corner_hz=corner, tilt_gain=tilt)
        ring = data.ring.replace(k_tread=k_tread)
        P = data.omega.shape[0]
        ch = profile_channels(model, ring, data.geometry, data.omega, jnp.full(P, load), data.roads,
                              full_band(P, self.solver.n_grid), offset, self.solver)
        return gain * ch

    def __call__(self, theta, data: EstimateArrays):
        radial = self.channels(theta, data)[:, 0]
        rows = amplitude_rows(harmonic_amplitudes(radial, self.k_min, self.k_max) * data.response)
        return ((rows - data.measured) * data.weight).ravel(), rows


def covariance_kind(name: str) -> str:
    """The coordinate of ``name`` in a ``[ring.covariance]`` (docs/formats.md §1.1): the share itself for a pressure
    share (:data:`ringfit.io.tyre.LINEAR_COVARIANCE`), else its logarithm."""
    return LINEAR if name in LINEAR_COVARIANCE else LOG


def tyre_with(ring: RingParams, laws, names: tuple[str, ...], values):
    """``(ring, laws)`` with the parameters ``names`` at ``values`` (natural units): a ring parameter's
    (:data:`ringfit.fit.least_squares.RING_FIELDS`) in the ring, every other ``[ring.covariance]`` name — a state law
    identified across states (k_x, the pressure shares) — in the laws (``laws`` None: ring names only)."""
    on_ring = {n: values[i] for i, n in enumerate(names) if n in RING_FIELDS}
    on_laws = {n: values[i] for i, n in enumerate(names) if n not in RING_FIELDS}
    if on_laws and laws is None:
        raise ValueError(f"{sorted(on_laws)}: state laws, but this estimate has none")
    return (ring.replace(**on_ring) if on_ring else ring), (laws.replace(**on_laws) if on_laws else laws)


def tyre_value(ring: RingParams, laws, name: str) -> float:
    """The tyre file's value of a ``[ring.covariance]`` name: the ring's, or the state law's."""
    return float(getattr(ring if name in RING_FIELDS else laws, name))


class RingSensitivityResiduals(AbstractResiduals):
    """An estimate's residuals with the tyre's parameters appended to θ: θ = (the problem's own ``n_own``
    parameters…, ``ring_names``…) — the load estimate's (:class:`EstimateResiduals`) or the state's, whose
    ``ring_names`` may name state laws too (k_x, the pressure shares: :func:`tyre_with`).

    Only for the Jacobian of the estimate's rows with respect to the tyre's parameters (each in its
    ``[ring.covariance]`` coordinate, :func:`covariance_kind`), which propagates the tyre file's covariance into the
    estimate (:func:`optimum_ring_shift`, docs/physics.md §10, §13.4); never fitted. ``k_tread`` is the load
    estimate's own θ, not a ring name there.
    """

    base: AbstractResiduals
    ring_names: tuple = eqx.field(static=True)
    n_own: int = eqx.field(static=True)

    def __call__(self, theta, data):
        n = self.n_own
        ring, laws = tyre_with(data.ring, getattr(data, "laws", None), self.ring_names, theta[n:])
        data = eqx.tree_at(lambda a: a.ring, data, ring)
        if laws is not getattr(data, "laws", None):
            data = eqx.tree_at(lambda a: a.laws, data, laws)
        return self.base(theta[:n], data)


def ring_sensitivity_problem(problem: Problem, ring_names: tuple[str, ...]) -> Problem:
    """The estimate ``problem`` with ``ring_names`` appended to θ, each in its ``[ring.covariance]`` coordinate
    (:class:`RingSensitivityResiduals`)."""
    coords = tuple(problem.coords) + tuple(Coordinate(n, covariance_kind(n)) for n in ring_names)
    model = RingSensitivityResiduals(problem.model, tuple(ring_names), len(problem.coords))
    return Problem(model, problem.data, coords, sigma=problem.sigma, data_label=problem.data_label)


def optimum_ring_shift(fit, ring: RingParams, names: tuple[str, ...], laws=None):
    """How a fit's optimum û moves with the tyre's parameters q held fixed in it (docs/physics.md §10):
    ``∂û/∂q = −(JᵀJ)⁻¹ Jᵀ ∂r/∂q``, q each in its ``[ring.covariance]`` coordinate (ln q; a pressure share itself),
    J the Jacobian of the rows the solver minimised (prior rows included; weights of mean 1, not divided by the
    fitted σ scale), ∂r/∂q the engine's Jacobian of the same rows (:func:`ringfit.fit.engine.linearize` on
    :func:`ring_sensitivity_problem`). ``laws``: the state's, where ``names`` holds state laws.

    **Returns:** ``(du_dq (free, r), (JᵀJ)⁻¹ (free, free))``.
    """
    import numpy as np

    from ringfit.fit.engine import linearize

    problem = ring_sensitivity_problem(fit.problem, names)
    theta = np.concatenate([np.asarray(fit.theta, dtype=np.float64), [tyre_value(ring, laws, n) for n in names]])
    lin = linearize(problem, theta, names)
    m = fit.residuals.size
    J = np.asarray(fit.jacobian).copy()
    J[:m] *= float(fit.extra["sigma_scale"])  # the rows the solver minimised (FitResult divides them by s)
    Jq = np.zeros((J.shape[0], len(names)))
    Jq[:m] = lin.jacobian
    cov = np.linalg.pinv(J.T @ J)
    return -(cov @ (J.T @ Jq)), cov


def nuisance_priors() -> dict:
    """``name -> (mean, sd)`` in solver coordinates of the high-pass corner and tilt priors."""
    return {n: sensor_prior_entry(COORDS[PARAMETERS.index(n)], n) for n in (CORNER, TILT)}


def estimate_problem(arrays: EstimateArrays, settings: EstimateSettings, k_max: int,
                     prior: GaussianPrior | None = None, sigma: SigmaMode = "estimate") -> Problem:
    """The engine :class:`~ringfit.fit.engine.Problem` of an estimate. ``sigma``: ``"fixed"`` where the weights are
    the profile block's σ (:func:`ringfit.fit.profile_block.fit_profile_block`, the averaged profile), ``"estimate"``
    where they give only the noise's shape and one revolution's residual its scale (the per-revolution fits)."""
    residuals = EstimateResiduals(settings.profile_model(), settings.solver, 2, int(k_max))
    return Problem(residuals, as_traced(arrays), COORDS, prior=prior, sigma=sigma,
                   plausible={LOAD: LOAD_RANGE}, data_label="this profile")
