"""The tyre's state from the one accelerometer: load, pressure, slip and longitudinal force, tread depth, speed
(docs/physics.md §13.4–13.5; docs/formats.md §7.1).

A problem on the one engine (:mod:`ringfit.fit.engine`), like :mod:`ringfit.fit.estimate.problem`:

- θ = :data:`STATE_PARAMETERS` (load Fz [N], pressure p [Pa], slip κ, tread depth d [m], gain, angle offset
  [rad], high-pass corner [Hz], tilt γ, the tangential axis's relative gain, the liner offset e [m]); positive
  ones in log coordinates (:data:`STATE_COORDS`);
- rows: the radial **and** tangential revolution harmonics 2…k_max of
  :func:`ringfit.physics.profile.profile_channels` at :func:`ringfit.physics.state.state_profile`'s model
  (:class:`StateResiduals` on :class:`StateArrays`), each channel whitened by its own residual spectrum;
- :func:`estimate_state` — one profile (two passes, started from :func:`~ringfit.fit.estimate.load.estimate_load`),
  :class:`StateEstimate` with 95 % intervals (the tyre's ``[ring.covariance]`` carried in), the correlation,
  and the quantities the data cannot tell apart;
- :func:`state_revolutions` — every revolution of a recording by one linearised Gauss–Newton step from the
  averaged profile's fit (the Jacobian once), :class:`StateRevolutions`;
- :func:`estimate_stretches` — a recording whose state drifted (:func:`state_drift`), fitted on stretches of it,
  each at its own load and slip (:func:`drifting_state` decides);
- :func:`state_fisher` — the per-revolution Fisher information of every state quantity at a noise level.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy.special import ndtri

from ringfit.errors import InputError
from ringfit.fit.engine import (LINEAR, LOG, AbstractResiduals, Coordinate, GaussianPrior, Problem, SigmaMode,
                                free_set, least_squares, least_squares_batch, linearize, residuals)
from ringfit.fit.estimate.harmonics import harmonic_amplitudes, amplitude_rows
from ringfit.fit.profile_block import (LINER_OFFSET_PRIOR, PROFILE_K_MAX, fit_profile_block, noise_from_residual,
                                       sensor_coordinate, sensor_prior_entry)
from ringfit.fit.estimate.load import LoadEstimate, band_top, estimate_load
from ringfit.fit.result import grid_moves
from ringfit.fit.identify import band_folds, discrepancy_ratio
from ringfit.fit.estimate.problem import (ANGLE_OFFSET, CORNER, GAIN, GAIN_RANGE, LOAD, LOAD_RANGE, TILT,
                                          EstimateSettings, covariance_kind,
                                          optimum_ring_shift, tyre_value, tyre_with)
from ringfit.params import BAR, RingParams, TyreGeometry, TyreLaws
from ringfit.physics.contact import ContactSolver, as_traced
from ringfit.physics.operating import KMH
from ringfit.physics.profile import FlatOrDrum, ProfileModel, flat_or_drum, full_band, profile_channels
from ringfit.physics.state import TyreState, state_profile, state_solution

PRESSURE, SLIP, TREAD = "pressure_pa", "slip", "tread_depth_m"
#: The sensor's two further nuisances (docs/physics.md §5, §13.4): the tangential axis's sensitivity relative to
#: the radial one (each axis of a tri-axial sensor has its own calibration, typically within ±2–5 %), and the
#: sensor's offset e inward of the belt (layer 1: the liner point reads v + eψ, a tangential term the drive/brake
#: asymmetry shares). Without them a 2 % axis mismatch or a 1 mm offset is read as state.
GAIN_TANGENTIAL, LINER_OFFSET = "gain_tangential", "liner_offset_m"
#: θ of the state estimate, in order.
STATE_PARAMETERS = (LOAD, PRESSURE, SLIP, TREAD, GAIN, ANGLE_OFFSET, CORNER, TILT, GAIN_TANGENTIAL, LINER_OFFSET)
#: The state's own parameters (the rest are the sensor's nuisances).
STATE_NAMES = (LOAD, PRESSURE, SLIP, TREAD)
#: Plausible pressures [Pa] (0.3–8 bar), slips, tread depths [m].
PRESSURE_RANGE = (0.3 * BAR, 8.0 * BAR)
SLIP_RANGE = (-0.3, 0.3)
TREAD_RANGE = (0.2e-3, 30e-3)
#: Weak priors [A] (docs/physics.md §13.4): σ of ln p about the tyre file's p_ref, σ of κ about 0, σ of ln d
#: about d_ref. A quantity whose posterior σ reaches :data:`UNTOLD_SHARE` of its prior's is "not told".
PRESSURE_PRIOR_SD = 0.3
SLIP_PRIOR_SD = 0.05
#: The first pass is also started at slip ∓ SLIP_START (docs/physics.md §13.4 *the slip's basins*): beyond the slip
#: of a drive or brake force of 0.3 × the load on the example tyre (about 1.2 % at its rated load), so that each side's
#: basin has a start on its side.
SLIP_START = 0.02
TREAD_PRIOR_SD = 0.5
UNTOLD_SHARE = 0.9
# Priors [A] of the two sensor nuisances (the profile block's GAIN_TANGENTIAL_PRIOR_SD, LINER_OFFSET_PRIOR): σ of
# ln(tangential/radial sensitivity) about 0, and the liner offset's mean and σ [m] (the sensor's centre sits a few
# mm inside the belt's neutral line).
#: What a revolution's step moves (:func:`state_revolutions`): what changes from one revolution to the next; the
#: pressure, tread depth and the sensor's corner and tilt stay at the recording's averaged fit.
REVOLUTION_FREE = (LOAD, SLIP, GAIN, ANGLE_OFFSET)
#: Correlation above which two quantities are reported as not told apart.
RIDGE_CORRELATION = 0.95
#: The ridge's profile (docs/physics.md §13.4 *intervals along the ridge*): fits at this many tread depths, evenly
#: in ln d over the weak prior's mean ± RIDGE_SPAN σ (within the coordinate's range), the rest free.
RIDGE_SLICES = 13
RIDGE_SPAN = 2.5
#: A slice this much (in −2 ln L) below the free fit: the free fit stopped on the flat ridge short of its optimum,
#: and is redone from that slice.
RIDGE_BETTER = 1.0
#: Points per interval of two neighbouring slices at which the ridge is read as a curve (:func:`_along_ridge`).
RIDGE_FINE = 64
#: The harmonics the state fits (docs/physics.md §13.4 *the harmonic band*): 2…STATE_K_MAX of both channels (the
#: patch's edges, what tells load from tread depth at light loads, live in the high ones) — unless the model's form
#: error shows there: a fit whose discrepancy ratio κ exceeds KAPPA_BAND_LIMIT is redone on 2…STATE_K_FALLBACK.
STATE_K_MAX = PROFILE_K_MAX
STATE_K_FALLBACK = 40
KAPPA_BAND_LIMIT = 4.0

STATE_COORDS = (
    Coordinate(LOAD, LOG, lo=LOAD_RANGE[0], hi=LOAD_RANGE[1]),
    Coordinate(PRESSURE, LOG, lo=PRESSURE_RANGE[0], hi=PRESSURE_RANGE[1]),
    Coordinate(SLIP, LINEAR, scale=0.01, lo=SLIP_RANGE[0], hi=SLIP_RANGE[1]),
    Coordinate(TREAD, LOG, lo=TREAD_RANGE[0], hi=TREAD_RANGE[1]),
    Coordinate(GAIN, LOG, lo=GAIN_RANGE[0], hi=GAIN_RANGE[1]),
    Coordinate(ANGLE_OFFSET, LINEAR, scale=math.radians(1.0)),
    sensor_coordinate(CORNER, bounded=False),
    sensor_coordinate(TILT),
    sensor_coordinate(GAIN_TANGENTIAL),
    sensor_coordinate(LINER_OFFSET),
)

#: Reported quantities: key → (unit, scale from SI, what) — the state, then the derived ones (docs/formats.md §7.1).
QUANTITIES = {
    "load_n": ("N", 1.0, "vertical load Fz"),
    "pressure_bar": ("bar", 1.0 / BAR, "inflation pressure"),
    "slip": ("-", 1.0, "longitudinal slip ratio κ = r_free/r_road − 1 (+ driving)"),
    "fx_n": ("N", 1.0, "longitudinal force Fx (+ driving)"),
    "torque_nm": ("N m", 1.0, "axle torque T = Fx·H (+ driving)"),
    "tread_depth_mm": ("mm", 1e3, "tread depth"),
    "speed_kmh": ("km/h", 1.0 / KMH, "speed V = Ω·r_road"),
    "rolling_radius_m": ("m", 1.0, "effective rolling radius r_road = V/Ω"),
    "free_rolling_radius_m": ("m", 1.0, "free-rolling radius r_free"),
    "axle_height_m": ("m", 1.0, "axle height H"),
    "patch_length_mm": ("mm", 1e3, "contact patch length"),
}
#: Quantities of a log coordinate: intervals log-normal.
LOG_QUANTITIES = ("load_n", "pressure_bar", "tread_depth_mm")
#: The quantities whose correlation is reported.
CORRELATED = ("load_n", "pressure_bar", "slip", "fx_n", "tread_depth_mm", "speed_kmh")
#: Pairs that are one quantity in two forms (Fx = Fx(κ) through the brush): correlated by construction, never
#: reported as "not told apart".
ONE_QUANTITY = ({"slip", "fx_n"},)


class StateArrays(eqx.Module):
    """Data of one state estimate (leading axis P = 1 profile; a batch adds an axis in front).

    ``geometry``, ``ring``, ``laws``: the reference tyre; ``omega`` ``(P,)`` Ω [rad/s]; ``roads``; ``response``
    ``(P, K)`` the acquisition's gain on harmonics 2…k_max; ``measured`` ``(P, 4K)`` rows radial (Re, Im) then
    tangential (Re, Im) [m/s²]; ``weight`` ``(P, 4K)`` 1/σ per row; ``correction`` ``(P, 4K)`` the model grid's
    defect correction added to the model's rows (docs/physics.md §13.4 *the model's grid*; zeros: none).
    """

    geometry: TyreGeometry
    ring: RingParams
    laws: TyreLaws
    omega: jax.Array
    roads: FlatOrDrum
    response: jax.Array
    measured: jax.Array
    weight: jax.Array
    correction: jax.Array
    #: stretches of one drifting recording (:func:`estimate_stretches`, docs/physics.md §13.4 *a drifting state*):
    #: ``(P,)`` each profile's load as a share of θ's and its slip less θ's (the revolutions' own drift); None: every
    #: profile at θ's load and slip
    load_scale: jax.Array | None = None
    slip_shift: jax.Array | None = None
    #: ``(P·4K, r)`` orthonormal directions of the weighted residual taken out of it (:func:`estimate_stretches`: what
    #: the stretches' own load and slip, about their mean, would explain); None: none
    basis: jax.Array | None = None


def state_of(theta, omega) -> TyreState:
    """The :class:`~ringfit.physics.state.TyreState` of θ (:data:`STATE_PARAMETERS`) at Ω."""
    return TyreState(load=theta[0], pressure=theta[1], tread_depth=theta[3], slip=theta[2], omega=omega)


class StateResiduals(AbstractResiduals):
    """``weight·(model − measured)`` of both channels' harmonics k_min…k_max; aux: the model rows ``(P, 4K)``."""

    profile: ProfileModel = eqx.field(static=True)
    solver: ContactSolver = eqx.field(static=True)
    k_min: int = eqx.field(static=True)
    k_max: int = eqx.field(static=True)

    def rows(self, theta, data: StateArrays):
        """The model's radial and tangential harmonic rows at θ (before subtracting the measured and weighting)."""
        if data.load_scale is None:
            return self._rows(theta, data)
        # stretches of a drifting recording: each profile at its own load and slip about θ's (one vmapped model)
        per = (data.omega, data.roads, data.response)

        def one(scale, shift, own):
            sub = eqx.tree_at(lambda a: (a.omega, a.roads, a.response), data,
                              jax.tree.map(lambda x: x[None], own))
            th = theta.at[0].multiply(scale).at[2].add(shift)
            return self._rows(th, sub)[0]

        return jax.vmap(one)(data.load_scale, data.slip_shift, per)

    def _rows(self, theta, data: StateArrays):
        gain, offset, corner, tilt = theta[4], theta[5], theta[6], theta[7]
        base = self.profile.with_sensor(corner_hz=corner, tilt_gain=tilt, offset=theta[9])
        model, ring, geometry = state_profile(data.geometry, data.ring, data.laws, state_of(theta, data.omega[0]),
                                              model=base)
        P = data.omega.shape[0]
        ch = gain * profile_channels(model, ring, geometry, data.omega, jnp.full(P, theta[0]), data.roads,
                                     full_band(P, self.solver.n_grid), offset, self.solver)
        amp = harmonic_amplitudes(ch, self.k_min, self.k_max) * data.response[:, None, :]
        amp = amp * jnp.stack([jnp.ones_like(theta[8]), theta[8]])[None, :, None]  # the tangential axis's own gain
        return jnp.concatenate([amplitude_rows(amp[:, 0]), amplitude_rows(amp[:, 1])], axis=-1)

    def __call__(self, theta, data: StateArrays):
        rows = self.rows(theta, data) + data.correction
        res = ((rows - data.measured) * data.weight).ravel()
        if data.basis is not None:  # the stretches' own drift projected out (estimate_stretches)
            res = res - data.basis @ (data.basis.T @ res)
        return res, rows


def state_problem(arrays: StateArrays, settings: EstimateSettings, k_max: int, prior: GaussianPrior | None = None,
                  sigma: SigmaMode = "estimate") -> Problem:
    """The engine :class:`~ringfit.fit.engine.Problem` of a state estimate."""
    model = StateResiduals(settings.profile_model(), settings.solver, 2, int(k_max))
    return Problem(model, as_traced(arrays), STATE_COORDS, prior=prior, sigma=sigma,
                   plausible={LOAD: LOAD_RANGE}, data_label="this profile")


def state_priors(geometry: TyreGeometry, laws: TyreLaws) -> dict:
    """``name -> (mean, sd)`` in solver coordinates: §13.4's weak priors and §10's nuisance priors."""
    slip = STATE_COORDS[STATE_PARAMETERS.index(SLIP)]
    return {PRESSURE: (math.log(float(geometry.pressure)), PRESSURE_PRIOR_SD),
            SLIP: (0.0, SLIP_PRIOR_SD / slip.scale),
            TREAD: (math.log(float(laws.tread_depth_ref)), TREAD_PRIOR_SD),
            **{n: sensor_prior_entry(STATE_COORDS[STATE_PARAMETERS.index(n)], n)
               for n in (CORNER, TILT, GAIN_TANGENTIAL, LINER_OFFSET)}}


def free_parameters(laws: TyreLaws, fixed: dict) -> tuple[str, ...]:
    """The θ names fitted: every one but those ``fixed`` and those the tyre has no law for (κ without a brush,
    d without a tread law)."""
    held = set(fixed)
    if not laws.has_brush:
        held.add(SLIP)
    if not laws.has_tread_depth:
        held.add(TREAD)
    return tuple(n for n in STATE_PARAMETERS if n not in held)


# --------------------------------------------------------------------------- derived quantities

def _quantity_vector(theta, ring_q, geometry, ring, laws, omega, road, names, solver, model):
    """The reported quantities (SI, :data:`QUANTITIES` order) at θ and the tyre's parameters ``names``, each in its
    ``[ring.covariance]`` coordinate (ln q; a pressure share itself: :func:`covariance_kind`)."""
    ring, laws = tyre_with(ring, laws, names, [ring_q[i] if covariance_kind(n) == LINEAR else jnp.exp(ring_q[i])
                                               for i, n in enumerate(names)])
    _, _, q = state_solution(geometry, ring, laws, state_of(theta, omega), model=model, solver=solver, road=road)
    return jnp.stack([theta[0], theta[1], q.slip, q.fx, q.torque, theta[3], q.speed, q.r_road, q.r_free,
                      q.axle_height, q.patch_length])


@eqx.filter_jit
def _quantities_and_jacobian(theta, ring_ln, geometry, ring, laws, omega, road, names, solver, model):
    f = lambda t, r: _quantity_vector(t, r, geometry, ring, laws, omega, road, names, solver, model)  # noqa: E731
    value = f(theta, ring_ln)
    jt, jr = jax.jacfwd(f, argnums=(0, 1))(theta, ring_ln)
    return value, jt, jr


def state_quantities(theta, geometry, ring, laws, omega, road=None, *, ring_names=(), settings=EstimateSettings()):
    """The reported quantities at θ (SI, :data:`QUANTITIES` order), their Jacobian in θ (natural units) and in the
    ``[ring.covariance]`` coordinates of ``ring_names`` (ring parameters and state laws: ln q, a pressure share
    itself): ``(value (Q,), d/dθ (Q, len(θ)), d/dq (Q, r))``. One compiled program per structure."""
    from ringfit.physics.operating import FlatRoad

    names = tuple(ring_names)
    values = [tyre_value(ring, laws, n) for n in names]
    ring_ln = np.array([v if covariance_kind(n) == LINEAR else math.log(v) for n, v in zip(names, values)],
                       dtype=np.float64)
    v, jt, jr = _quantities_and_jacobian(np.asarray(theta, dtype=np.float64), ring_ln,
                                         *as_traced((geometry, ring, laws)), np.float64(omega),
                                         as_traced(road or FlatRoad()), names, settings.solver,
                                         settings.profile_model())
    return np.asarray(v), np.asarray(jt), np.asarray(jr)


#: A state parameter within this share of its coordinate's range of a bound is at it (the engine's 1e-6 misses a
#: bounded coordinate that creeps towards its bound: 7.9996 bar of 8).
NEAR_BOUND = 1e-3


def near_bound(theta, free) -> list:
    """The state parameters and gain among ``free`` within :data:`NEAR_BOUND` of their range's ends (in u)."""
    out = []
    for n in free:
        if n not in STATE_NAMES and n != GAIN:
            continue
        c = STATE_COORDS[STATE_PARAMETERS.index(n)]
        if not (math.isfinite(c.lo) and math.isfinite(c.hi)):
            continue
        u, lo, hi = (c.to_u(x) for x in (float(theta[STATE_PARAMETERS.index(n)]), c.lo, c.hi))
        if min(u - lo, hi - u) <= NEAR_BOUND * (hi - lo):
            out.append(n)
    return out


def _du_dtheta(theta) -> np.ndarray:
    """dθ/du per parameter (θ for a log coordinate, its scale for a linear one)."""
    return np.array([t if c.kind == LOG else c.scale for c, t in zip(STATE_COORDS, theta)])


# --------------------------------------------------------------------------- the ridge

@dataclass
class RidgeProfile:
    """The likelihood along the load–pressure–tread-depth ridge (docs/physics.md §13.4 *intervals along the
    ridge*): ``depth`` ``(B,)`` [m] the slices' tread depths; ``theta`` ``(B, p)`` the fits with d held there;
    ``deviance`` ``(B,)`` −2 ln(L·prior) relative to the best fit (noise σ scaled as the fit's, the discrepancy
    ratio not applied); ``converged`` ``(B,)``; ``cov_u`` ``(B, k−1, k−1)`` each slice's conditional covariance of the
    other free parameters' solver coordinates (``free``)."""

    depth: np.ndarray
    theta: np.ndarray
    deviance: np.ndarray
    converged: np.ndarray
    cov_u: np.ndarray
    free: tuple

    def to_record(self, kappa: float = 1.0) -> dict:
        """``ridge`` of docs/formats.md §7.1: each slice's depth [mm], deviance Δ and weight (with κ)."""
        def finite(x):
            return [float(v) if math.isfinite(v) else None for v in x]

        return {"tread_depth_mm": finite(1e3 * self.depth), "deviance": finite(self.deviance),
                "weight": finite(self.weights(kappa)), "converged": [bool(c) for c in self.converged]}

    def weights(self, kappa: float = 1.0) -> np.ndarray:
        """Each slice's share of the posterior along the ridge: exp(−Δ/2κ)·√det C (integrated Laplace over the
        other parameters; the slices evenly spaced in ln d), converged slices only, normalised."""
        ok = self.converged & np.isfinite(self.deviance)
        logw = np.full(self.depth.size, -np.inf)
        if ok.any():
            logw[ok] = _ridge_log_weight(self.deviance[ok], _ridge_logdet(self.cov_u[ok], kappa), kappa)
        w = np.exp(logw - np.max(logw)) if ok.any() else np.zeros(self.depth.size)
        return w / w.sum() if w.sum() > 0 else w


def _ridge_logdet(cov_u, kappa: float) -> np.ndarray:
    """ln det(κC) of each ridge point's conditional covariance ``(B, k, k)`` → ``(B,)``."""
    return np.array([np.linalg.slogdet(kappa * np.asarray(c))[1] for c in cov_u])


def _ridge_log_weight(deviance, logdet, kappa: float) -> np.ndarray:
    """ln of a ridge point's posterior density: −Δ/2κ + ½ ln det(κC) (the integrated Laplace over the other
    parameters, docs/physics.md §13.4 *intervals along the ridge*; ``logdet`` from :func:`_ridge_logdet`)."""
    return -0.5 * np.asarray(deviance, dtype=np.float64) / kappa + 0.5 * np.asarray(logdet, dtype=np.float64)


def _total_chi2(problem: Problem, theta, free) -> float:
    """−2 ln(L·prior) of θ: the data rows' χ² and the prior's (solver coordinates of ``free``)."""
    from ringfit.fit.engine import residuals

    r = np.asarray(residuals(problem, theta)[0])
    return float(r @ r) + _prior_chi2(problem, np.asarray(theta)[None], free)[0]


def _prior_chi2(problem: Problem, thetas, free) -> np.ndarray:
    if problem.prior is None:
        return np.zeros(len(thetas))
    W, mean = problem.prior.rows(free, len(free))
    coords = [STATE_COORDS[STATE_PARAMETERS.index(n)] for n in free]
    u = np.array([[c.to_u(float(t[STATE_PARAMETERS.index(n)])) for c, n in zip(coords, free)] for t in thetas])
    r = (u - mean[None]) @ W.T
    return np.sum(r**2, axis=1)


def ridge_profile(problem: Problem, fit, *, max_steps: int = 256, rtol: float = 1e-10,
                  atol: float = 1e-10, depth_max: float | None = None) -> RidgeProfile:
    """The profile of the fit's likelihood in tread depth (docs/physics.md §13.4): :data:`RIDGE_SLICES` fits with
    d held at depths evenly spaced in ln d over the weak prior's ±:data:`RIDGE_SPAN` σ, every other free
    parameter fitted, in two warm-started chains from the fit outwards (:func:`~ringfit.fit.engine.least_squares_batch`,
    one compilation); the rows in units of the fit's noise (its σ scale s applied), so Δ is comparable to χ²₁.
    ``depth_max`` [m]: the new tread's depth d_new (§13.3), the deepest slice (the depth cannot exceed it)."""
    free = tuple(fit.names)
    rest = tuple(n for n in free if n != TREAD)
    c = STATE_COORDS[STATE_PARAMETERS.index(TREAD)]
    j = STATE_PARAMETERS.index(TREAD)
    mu, sd = problem.prior.mean[list(problem.prior.names).index(TREAD)], TREAD_PRIOR_SD
    lo, hi = max(mu - RIDGE_SPAN * sd, c.to_u(c.lo) + 1e-3), min(mu + RIDGE_SPAN * sd, c.to_u(c.hi) - 1e-3)
    if depth_max is not None:
        hi = min(hi, c.to_u(float(depth_max)))
    grid = np.linspace(lo, hi, RIDGE_SLICES)
    theta = np.asarray(fit.theta, dtype=np.float64)
    u_hat = c.to_u(float(theta[j]))
    s = float(fit.extra["sigma_scale"])
    data = eqx.tree_at(lambda a: a.weight, problem.data, np.asarray(problem.data.weight) / s)
    fixed = dataclasses.replace(problem, data=data, sigma="fixed")
    B = RIDGE_SLICES
    batch = jax.tree.map(lambda x: np.repeat(np.asarray(x)[None], B, axis=0), data)
    out_theta, out_chi2, out_conv, out_cov = [], [], [], []
    for chain in (grid[grid <= u_hat][::-1], grid[grid > u_hat]):
        if chain.size == 0:
            continue
        pad = np.concatenate([chain, np.full(B - chain.size, chain[-1])])
        th0 = np.repeat(theta[None], B, axis=0)
        th0[:, j] = [c.from_u(u) for u in pad]
        res = least_squares_batch(fixed, th0, rest, batch, warm_start=True, max_steps=max_steps, rtol=rtol, atol=atol)
        n = chain.size
        out_theta.append(res.theta[:n])
        out_chi2.append(res.chi2_raw[:n])
        out_conv.append(np.asarray(res.converged)[:n] & ~np.any(res.at_bound[:n], axis=1))
        out_cov.append(res.covariance_log[:n])
    th = np.concatenate(out_theta)
    order = np.argsort(th[:, j])
    th = th[order]
    total = np.concatenate(out_chi2)[order] + _prior_chi2(fixed, th, free)
    best = _total_chi2(fixed, theta, free)
    return RidgeProfile(depth=th[:, j], theta=th, deviance=total - best, converged=np.concatenate(out_conv)[order],
                        cov_u=np.concatenate(out_cov)[order], free=rest)


def _along_ridge(ridge: RidgeProfile, kappa, theta, free, geometry, ring, laws, omega, road, settings, ring_sd,
                 anchor_cov=None):
    """Each reported quantity's 95 % interval along the ridge (docs/physics.md §13.4 *intervals along the ridge*):
    the marginal over the tread depth of the ridge's conditional normals (κ × the slice's statistical variance +
    the ring's part at the fit; log-normal for :data:`LOG_QUANTITIES`), its 2.5 and 97.5 % quantiles; and
    ``spread_u`` the ridge's spread about the fit in the solver coordinates of ``free``.

    The ridge is read as a curve, not as its slices: between two converged slices the deviance Δ is interpolated
    by Akima's local cubic in ln d (exact on a quadratic; no overshoot beyond its neighbours), ln det C, each
    quantity's conditional mean and σ and the other parameters linearly, on :data:`RIDGE_FINE` points per interval,
    each weighted as :meth:`RidgeProfile.weights` weights a slice, times its cell in ln d. So a posterior narrower
    than the slices' spacing — a depth held on the new tread's bound, its likelihood falling steeply below it —
    keeps its width, instead of collapsing onto one slice. ``anchor_cov``: the fit's own
    conditional covariance of ``ridge.free`` given the depth (with the depth free): the fit joins the slices as the
    ridge's point at its depth, Δ = 0, so the curve passes through the mode and its quantities exactly."""
    from scipy.interpolate import Akima1DInterpolator
    from scipy.special import ndtr

    keys = list(QUANTITIES)
    Q = len(keys)
    keep = np.flatnonzero(ridge.converged & np.isfinite(ridge.deviance))
    if keep.size == 0:
        return None
    c_d = STATE_COORDS[STATE_PARAMETERS.index(TREAD)]
    j_d = STATE_PARAMETERS.index(TREAD)
    th_s = np.asarray(ridge.theta, dtype=np.float64)[keep]
    d_s = np.asarray(ridge.deviance, dtype=np.float64)[keep]
    cov_s = np.asarray(ridge.cov_u, dtype=np.float64)[keep]
    u_s = np.array([c_d.to_u(float(x)) for x in th_s[:, j_d]])
    if anchor_cov is not None and np.all(np.isfinite(theta)):
        u_fit = c_d.to_u(float(theta[j_d]))
        if np.min(np.abs(u_s - u_fit)) > 1e-9:  # the fit between the slices: the ridge's point at its depth
            at = int(np.searchsorted(u_s, u_fit))
            th_s = np.insert(th_s, at, np.asarray(theta, dtype=np.float64), axis=0)
            d_s = np.insert(d_s, at, 0.0)  # Δ is relative to the fit (ridge_profile)
            cov_s = np.insert(cov_s, at, np.asarray(anchor_cov, dtype=np.float64), axis=0)
            u_s = np.insert(u_s, at, u_fit)
    n_pts = u_s.size
    logdet = _ridge_logdet(cov_s, kappa)
    log_w = _ridge_log_weight(d_s, logdet, kappa)
    # the slices that bound an interval of non-negligible weight: their quantities are needed
    near = log_w > np.max(log_w) + math.log(1e-8)
    need = near.copy()
    need[1:] |= near[:-1]
    need[:-1] |= near[1:]
    idx = [STATE_PARAMETERS.index(n) for n in ridge.free]
    mean, sd = np.zeros((n_pts, Q)), np.zeros((n_pts, Q))
    for a in np.flatnonzero(need):
        value, jt, _ = state_quantities(th_s[a], geometry, ring, laws, omega, road, settings=settings)
        G = jt[:, idx] * _du_dtheta(th_s[a])[idx][None, :]
        var = kappa * np.einsum("qi,ij,qj->q", G, cov_s[a], G) + ring_sd**2
        mean[a], sd[a] = value, np.sqrt(np.maximum(var, 0.0))
    coords = [STATE_COORDS[STATE_PARAMETERS.index(n)] for n in free]
    u_free = np.array([[c.to_u(float(th[STATE_PARAMETERS.index(n)])) for c, n in zip(coords, free)] for th in th_s])
    # the fine grid: RIDGE_FINE points per interval of two neighbouring slices that both are needed (point i of
    # interval a at a + i/RIDGE_FINE), and the last slice
    starts = np.flatnonzero(need[:-1] & need[1:])
    a_i = np.concatenate([np.repeat(starts, RIDGE_FINE), [n_pts - 1] if need[-1] else []]).astype(int)
    f = np.concatenate([np.tile(np.arange(RIDGE_FINE) / RIDGE_FINE, starts.size), [0.0] if need[-1] else []])
    b_i = np.minimum(a_i + 1, n_pts - 1)
    lerp = lambda x: (1 - f)[:, None] * x[a_i] + f[:, None] * x[b_i]  # noqa: E731
    u_f = (1 - f) * u_s[a_i] + f * u_s[b_i]
    if n_pts >= 3:
        dev_f = Akima1DInterpolator(u_s, d_s)(u_f)
    else:
        dev_f = np.interp(u_f, u_s, d_s) if n_pts == 2 else d_s[a_i]
    logw_f = _ridge_log_weight(dev_f, (1 - f) * logdet[a_i] + f * logdet[b_i], kappa)
    # each point's share of the ridge: its weight times its cell in ln d (trapezoid: half a step at either end; the
    # slices need not be evenly spaced)
    step = 0.5 * (np.diff(u_f, prepend=u_f[0]) + np.diff(u_f, append=u_f[-1])) if u_f.size > 1 else np.ones(1)
    w = np.exp(logw_f - np.max(logw_f)) * np.maximum(step, 0.0)
    if not np.isfinite(w).all() or w.sum() <= 0:
        return None
    ww = w / w.sum()
    m_f, s_f = lerp(mean), lerp(sd)
    lo, hi = np.full(Q, np.nan), np.full(Q, np.nan)
    for q, key in enumerate(keys):
        m, s = m_f[:, q], s_f[:, q]
        if key in LOG_QUANTITIES:
            if np.any(m <= 0):
                continue
            m, s = np.log(m), s / m
        if m.size > 1:  # each point stands for its cell: its mean spread evenly over it (a density, not a staircase)
            s = np.sqrt(s**2 + (0.5 * (np.diff(m, prepend=m[0]) + np.diff(m, append=m[-1]))) ** 2 / 12.0)
        span = np.linspace(np.min(m - 8 * s), np.max(m + 8 * s), 4001)
        if not np.all(np.isfinite(span)) or span[-1] <= span[0]:
            continue
        cdf = np.sum(ww[:, None] * ndtr((span[None, :] - m[:, None]) / np.maximum(s[:, None], 1e-300)), axis=0)
        lo[q], hi[q] = np.interp(0.025, cdf, span), np.interp(0.975, cdf, span)
        if key in LOG_QUANTITIES:
            lo[q], hi[q] = math.exp(lo[q]), math.exp(hi[q])
    u_hat = np.array([c.to_u(float(theta[STATE_PARAMETERS.index(n)])) for c, n in zip(coords, free)])
    du = lerp(u_free) - u_hat[None]
    return {"lo": lo, "hi": hi, "spread_u": np.einsum("b,bi,bj->ij", ww, du, du), "weights": ww}


# --------------------------------------------------------------------------- one profile

@dataclass
class StateEstimate:
    """The state from one profile (docs/formats.md §7.1).

    - ``quantities``: key of :data:`QUANTITIES` → ``{value, lo, hi, sd, unit, status}`` in the file's units
      (``status`` "estimated", "fixed" (held at a stated value or the tyre file's law is missing) or
      "not told" (the data do not bound it: its interval is its prior's)); intervals carry the ring's covariance.
    - ``correlation``: ``{names, matrix}`` of :data:`CORRELATED` (the estimated ones).
    - ``untold``: sentences naming what the data could not tell (apart).
    - ``status``, ``converged``, ``rms`` ``{radial, tangential}`` [m/s²], ``flags``; ``nuisances``.
    - ``fit``: the engine's :class:`~ringfit.fit.result.FitResult`; ``load``: the load estimate that started it.
    - ``discrepancy``: §11's discrepancy ratio κ ≥ 1 of the fit's harmonic bands (every statistical variance × κ);
      ``ridge``: the :class:`RidgeProfile` in tread depth (None with d held); ``spread_u``: its slices' spread about
      the fit in the free parameters' solver coordinates.
    - ``theta``, ``cov_u``: θ (natural) and the covariance of the free parameters' solver coordinates (κ × the
      Laplace covariance + ``spread_u``: what every revolution's held quantities carry);
      ``gradient_u`` ``(Q, k)``: d quantity/du; ``ring_sd`` ``(Q,)`` the ring's part of each σ (SI);
      ``names_u``: the parameters of ``cov_u`` and ``gradient_u`` (the fit's, and the tread depth when the new
      tread's bound holds it, §13.4).
    """

    quantities: dict
    correlation: dict
    untold: list
    status: str
    converged: bool
    rms: dict
    flags: list
    nuisances: dict
    fit: object = None
    load: LoadEstimate | None = None
    theta: np.ndarray | None = None
    cov_u: np.ndarray | None = None
    gradient_u: np.ndarray | None = None
    ring_sd: np.ndarray | None = None
    omega: float = 0.0
    k_max: int = 0
    fixed: dict = field(default_factory=dict)
    discrepancy: float = 1.0
    ridge: RidgeProfile | None = None
    spread_u: np.ndarray | None = None
    names_u: tuple | None = None
    #: the grid check (docs/physics.md §13.4 *the model's grid*): ``{"grid": [M, 2M], "shift": (Q,) SI}`` — how far
    #: each quantity moves when the model's grid is refined at the fit; in every interval in quadrature
    grid_check: dict | None = None
    #: the wider harmonic band tried first and its discrepancy ratio κ, ``{k_max: κ}``, when its form error sent the
    #: fit to the narrower band (:data:`KAPPA_BAND_LIMIT`); None otherwise
    band_kappa: dict | None = None
    #: a drifting recording fitted as stretches (:func:`estimate_stretches`): ``{"revolutions": [...], "load_share":
    #: [...], "slip_shift": [...]}`` per stretch; None: one averaged profile
    stretches: dict | None = None

    def value(self, key: str) -> float:
        """The estimate of quantity ``key`` (:data:`QUANTITIES`) in the unit its name says (the unit in
        :data:`QUANTITIES`: ``tread_depth_mm`` in mm, ``pressure_bar`` in bar, ``speed_kmh`` in km/h)."""
        return float(self.quantities[key]["value"])

    def _grid_record(self) -> dict:
        shift = np.asarray(self.grid_check["shift"])
        return {"grid": list(self.grid_check["grid"]),
                "shift": {k: float(shift[i]) * QUANTITIES[k][1] for i, k in enumerate(QUANTITIES)},
                "applied": bool(self.grid_check.get("applied", False))}

    def to_record(self) -> dict:
        """The ``state`` object of docs/formats.md §7.1."""
        return {"quantities": self.quantities, "correlation": self.correlation, "not_told_apart": list(self.untold),
                "fit": {"status": self.status, "converged": self.converged, "rms_ms2": self.rms,
                        "channels": ["radial", "tangential"], "harmonics": [2, self.k_max], "flags": list(self.flags),
                        "discrepancy_ratio": float(self.discrepancy),
                        **({"wider_band": {"harmonics": [2, k], "discrepancy_ratio": v}
                            for k, v in self.band_kappa.items()} if self.band_kappa else {}),
                        **({"grid_check": self._grid_record()} if self.grid_check is not None else {}),
                        **({"stretches": self.stretches} if self.stretches is not None else {})},
                "nuisances": self.nuisances,
                **({"ridge": self.ridge.to_record(self.discrepancy)} if self.ridge is not None else {})}


def band_rows(rows: np.ndarray, k_max: int) -> np.ndarray:
    """Rows ``(..., 4K')`` (radial Re, Im, tangential Re, Im of harmonics 2…K' + 1) cut to harmonics 2…k_max
    ``(..., 4(k_max − 1))``; the rows themselves when they have that band; a ``ValueError`` when they have less."""
    K = int(k_max) - 1
    Kr = rows.shape[-1] // 4
    if rows.shape[-1] != 4 * Kr or Kr < K:
        raise ValueError(f"rows of {rows.shape[-1]} columns: expected 4 × ({K} or more) harmonics")
    if Kr == K:
        return rows
    return rows.reshape(rows.shape[:-1] + (4, Kr))[..., :K].reshape(rows.shape[:-1] + (4 * K,))


def profile_rows(profile, n_grid: int, k_max: int) -> np.ndarray:
    """Rows ``(4K,)`` radial (Re, Im) then tangential (Re, Im) of harmonics 2…k_max of a profile."""
    from ringfit.io.profiles import resample_profile

    grid = resample_profile(profile, n_grid)
    return np.concatenate([amplitude_rows(harmonic_amplitudes(grid[i], 2, k_max)) for i in (0, 1)])


def channel_weights(resid_rows: np.ndarray, leverage: float = 0.0, series: int = 1) -> np.ndarray:
    """1/σ per row ``(4K,)`` [s²/m] from residual rows ``(4K,)`` (radial Re, Im, tangential Re, Im): the profile
    block's noise model (:func:`ringfit.fit.profile_block.noise_from_residual`, docs/physics.md §11 *profiles*) of
    each channel, ``leverage`` the share of the rows' degrees of freedom the fit took, ``series`` the residual series
    each row's power averages.

    Absolute (not normalised): the rows are then in units of their noise, as the priors are (§13.4)."""
    rows = np.asarray(resid_rows, dtype=np.float64)
    two = rows.reshape(rows.shape[:-1] + (2, rows.shape[-1] // 2))
    sigma = noise_from_residual(two, np.array([float(leverage)]), k_min=2, series=series)
    return 1.0 / sigma.reshape(rows.shape)


def estimate_state(profile, geometry: TyreGeometry, ring: RingParams, laws: TyreLaws, *,
                   settings: EstimateSettings = EstimateSettings(k_max=STATE_K_MAX), fixed: dict | None = None,
                   omega: float | None = None, omega_source: str | None = None, response=None, ring_covariance=None,
                   load: LoadEstimate | None = None, k_tread_in_file: bool = True) -> StateEstimate:
    """The tyre's state from one rolling profile (docs/physics.md §13.4; docs/formats.md §3 → §7.1).

    **Arguments:** ``profile`` (both channels; its sidecar's load and pressure are not used unless ``fixed``
    says so), the reference tyre ``geometry``, ``ring``, ``laws``; ``fixed``: θ names → natural values held
    (``{"pressure_pa": 2.4e5}``); ``omega``/``omega_source``, ``response`` (``(K,)`` the acquisition's gain) as
    for :func:`~ringfit.fit.estimate.load.estimate_load`; ``ring_covariance``: the tyre file's, carried into every
    interval; ``load``: a load estimate of the same profile to start from (default: computed).

    **Returns:** :class:`StateEstimate`. Never raises on non-convergence (check ``converged``).
    """
    common = dict(fixed=fixed, omega=omega, omega_source=omega_source, response=response,
                  ring_covariance=ring_covariance, k_tread_in_file=k_tread_in_file)
    if state_band(profile, settings, response) <= STATE_K_FALLBACK:
        return _estimate_state(profile, geometry, ring, laws, settings=settings, load=load, **common)
    # the wide band continued from the narrow band's fit (its first passes started from the priors' means stopped on
    # the ridge far from the optimum at a high signal-to-noise ratio, §13.6), and the narrow one where the wide band's
    # form error shows (§13.4 *the harmonic band*)
    # the narrow band's fit is only the wide one's start unless it is the answer: its ridge in tread depth (a
    # batch of fits along the depth) is profiled only then, by the same narrow fit made again with it
    narrow = dataclasses.replace(settings, k_max=STATE_K_FALLBACK)
    low = _estimate_state(profile, geometry, ring, laws, settings=narrow, load=load, ridge=False, **common)
    start = np.asarray(low.fit.theta) if np.all(np.isfinite(low.fit.theta)) else None
    est = _estimate_state(profile, geometry, ring, laws, settings=settings, load=low.load, start=start, **common)
    if est.discrepancy > KAPPA_BAND_LIMIT or not est.converged:
        low = _estimate_state(profile, geometry, ring, laws, settings=narrow, load=load, **common)
        why = (f"the model's form error showed above harmonic {STATE_K_FALLBACK} (discrepancy ratio κ = "
               f"{est.discrepancy:.3g} > {KAPPA_BAND_LIMIT:g})" if est.converged else "the fit did not converge")
        low.flags.append(f"harmonics 2…{est.k_max}: {why}; fitted on 2…{low.k_max} (κ = {low.discrepancy:.3g}), "
                         "docs/physics.md §13.4")
        low.band_kappa = {int(est.k_max): float(est.discrepancy)}
        return low
    return est


def state_band(profile, settings: EstimateSettings, response=None) -> int:
    """The top harmonic the state fits: :func:`~ringfit.fit.estimate.load.band_top` of the profile, and no higher than
    the harmonics whose acquisition gain ``response`` (``(K,)``, harmonics 2…K + 1) is given."""
    top = band_top(len(profile), settings)
    return top if response is None else min(top, int(np.size(response)) + 1)


def _estimate_state(profile, geometry: TyreGeometry, ring: RingParams, laws: TyreLaws, *, settings, fixed, omega,
                    omega_source, response, ring_covariance, load, k_tread_in_file, start=None,
                    ridge: bool = True) -> StateEstimate:
    """:func:`estimate_state` on the harmonics 2…``settings.k_max`` (within the profile's band); ``start``: θ
    (:data:`STATE_PARAMETERS` order) the passes start from (default: the load estimate's load and nuisances, the
    priors' means for the rest); ``ridge``: as for :func:`_state_passes`."""
    fixed = dict(fixed or {})
    for name in fixed:
        if name not in STATE_NAMES:
            raise ValueError(f"cannot fix {name!r}; expected one of {STATE_NAMES}")
    d_new = new_tread_depth(laws)
    if d_new is not None and TREAD in fixed and float(fixed[TREAD]) > d_new * (1 + 1e-9):
        raise InputError(f"the stated tread depth {1e3 * float(fixed[TREAD]):g} mm is deeper than the tyre file's new "
                         f"tread (tread_depth_new_mm = {1e3 * d_new:g}): wear only removes tread")
    if load is None:
        load = estimate_load(profile, geometry, ring, settings=dataclasses.replace(settings, grid_check=False),
                             k_tread_in_file=k_tread_in_file, omega=omega, omega_source=omega_source,
                             response=response, laws=laws)
    omega = load.omega
    from ringfit.fit.estimate.revolutions import refuse_dead_channel

    # the state reads both channels: a dead tangential one is refused (the averaged revolution's swing)
    refuse_dead_channel("tangential", float(np.ptp(np.asarray(profile.acc_tangential_ms2, dtype=np.float64))),
                        float(omega), geometry, profile.source or None)
    k_max = state_band(profile, settings, response)  # the state's own band (the load estimate is only its start)
    K = k_max - 1
    resp = np.ones(K) if response is None else np.asarray(response, dtype=np.float64)[:K]
    measured = profile_rows(profile, settings.n_grid, k_max)
    arrays = StateArrays(geometry=geometry, ring=ring, laws=laws, omega=np.array([omega]),
                         roads=flat_or_drum(load.drum_diameter_m, 1), response=resp[None], measured=measured[None],
                         weight=np.ones((1, 4 * K)), correction=np.zeros((1, 4 * K)))
    free = free_parameters(laws, fixed)
    entries = {k: v for k, v in state_priors(geometry, laws).items() if k in free}
    prior = GaussianPrior.independent(entries)
    # the first pass's rows are not in units of their noise (unknown yet): the state's priors would weigh
    # arbitrarily against them, so it has the nuisances' priors only
    prior0 = GaussianPrior.independent({k: v for k, v in entries.items()
                                        if k in (CORNER, TILT, GAIN_TANGENTIAL, LINER_OFFSET)})
    nv = load.fit.values
    at = {LOAD: load.load_n, PRESSURE: float(geometry.pressure), SLIP: 0.0, TREAD: float(laws.tread_depth_ref),
          GAIN: nv[GAIN], ANGLE_OFFSET: nv[ANGLE_OFFSET], CORNER: max(nv[CORNER], 1e-3), TILT: nv[TILT],
          GAIN_TANGENTIAL: 1.0, LINER_OFFSET: LINER_OFFSET_PRIOR[0]}
    if start is not None:
        at.update(zip(STATE_PARAMETERS, (float(v) for v in start)))
    at.update(fixed)
    theta0 = np.array([at[n] for n in STATE_PARAMETERS])
    # first pass: each channel's rows scaled by its RMS (the tangential reading is ~5× smaller than the radial)
    half = 2 * K
    scale = np.array([np.sqrt(np.mean(measured[:half] ** 2)), np.sqrt(np.mean(measured[half:] ** 2))])
    w0 = np.concatenate([np.full(half, 1 / scale[0]), np.full(half, 1 / scale[1])])
    arrays = eqx.tree_at(lambda a: a.weight, arrays, (w0 / w0.mean())[None])
    opts = dict(max_steps=settings.max_steps, rtol=settings.rtol, atol=settings.atol)
    # with no prior to hold them, the pressure and tread depth ran along the load–pressure–depth ridge (§13.6)
    # from the start, some to a bound (where the bounded coordinate's slope vanishes and the second pass cannot
    # bring them back): the first pass fits with them held at their priors' means, then frees them from there
    # (its residual, which weights the second pass, is then the free fit's); one that still ends at (within 1e-3
    # of) a bound stays held in it
    prob0 = state_problem(arrays, settings, k_max, prior0)
    free0 = tuple(n for n in free if n not in (PRESSURE, TREAD))

    def first_pass(theta):
        first = least_squares(prob0, theta, free0, **opts)
        if free0 != free and np.all(np.isfinite(first.theta)):
            freed = least_squares(prob0, first.theta, free, **opts)
            if np.all(np.isfinite(freed.theta)) and not near_bound(freed.theta, free):
                first = freed
        return first

    first = first_pass(theta0)
    if start is None and SLIP in free0:
        # the slip has more than one basin (§13.4 *the slip's basins*): the patch's fore-aft asymmetry read as a
        # drive at a heavier load, or as a brake at the right one. The first pass is also started at ± SLIP_STARTS;
        # its weights and priors are the same for every start, so the lowest −2 ln L among them is the basin kept
        same = dataclasses.replace(prob0, sigma="fixed")
        best = _total_chi2(same, first.theta, tuple(first.names)) if np.all(np.isfinite(first.theta)) else np.inf
        for s0 in (-SLIP_START, SLIP_START):
            other = first_pass(np.where(np.arange(theta0.size) == STATE_PARAMETERS.index(SLIP), s0, theta0))
            if np.all(np.isfinite(other.theta)):
                cost = _total_chi2(same, other.theta, tuple(other.names))
                if cost < best:
                    first, best = other, cost
    # a parameter the first pass left on a bound (or not finite) restarts from its start: on a bound the solver's
    # sine transform has no slope, and the second pass's priors are what hold a weakly told quantity
    theta1 = np.where(np.isfinite(first.theta), first.theta, theta0)
    for name in first.extra["at_bound"]:
        theta1[STATE_PARAMETERS.index(name)] = theta0[STATE_PARAMETERS.index(name)]
    # then the profile block's noise passes (docs/physics.md §11 *profiles*, §13.4): σ per channel and harmonic from
    # the first pass's residual, the fit (the 4M model's, by the grid's defect correction), σ from its residual, the
    # fit again — each warm from the last fit and its correction
    sigma0 = 1.0 / channel_weights(np.asarray(first.extra["aux"])[0] - measured, leverage=len(free0) / (4 * K))
    est = _state_passes(arrays, theta1, sigma0, free, prior, load, geometry, ring, laws, omega, settings, fixed,
                        ring_covariance, k_max, d_new, opts, ridge=ridge)
    return _speed_source(est, load)


def _speed_source(est: StateEstimate, load: LoadEstimate) -> StateEstimate:
    if str(load.rotation_source).startswith("speed_kmh"):  # Ω from the nominal speed: V = Ω·r_road says it back
        est.quantities["speed_kmh"]["status"] = "not told"
        est.untold.append("speed_kmh: no encoder rate (rotation_hz): Ω came from the nominal speed_kmh, so the "
                          "speed V = Ω·r_road only restates it; the rolling radius and slip do not rest on it")
    return est


def _state_passes(arrays: StateArrays, theta1, sigma0, free, prior, load, geometry, ring, laws, omega, settings, fixed,
                  ring_covariance, k_max, d_new, opts, passes: bool = True, ridge: bool = True) -> StateEstimate:
    """The state fit from θ ``theta1`` and a first σ ``sigma0`` (the shape of ``arrays.measured``): the profile block's
    noise passes with the grid's defect correction, the ridge in tread depth (and the new tread's bound), then
    :func:`_finish_state` — one profile, or the stretches of a drifting recording (:func:`estimate_stretches`).
    ``passes=False``: σ is ``sigma0``, known up to an inflation (the engine's ``"inflate"``), no noise passes.
    ``ridge=False``: the ridge is profiled only where the fit went deeper than the new tread (to hold it there)."""
    profile_ridge = ridge
    K = int(k_max) - 1
    measured = np.asarray(arrays.measured)
    last = dict(theta=theta1, correction=None)

    def fit_at(sigma):
        arr = eqx.tree_at(lambda a: a.weight, arrays, (1.0 / np.asarray(sigma)).reshape(np.shape(arrays.measured)))
        prob = state_problem(arr, settings, k_max, prior, sigma="estimate" if passes else "inflate")
        if last["correction"] is not None:
            prob = with_correction(prob, last["correction"])
        new = least_squares(prob, last["theta"], free, **opts)
        if settings.grid_check and np.all(np.isfinite(new.theta)):
            prob, new = grid_corrected(prob, new, settings, k_max, **opts)
        if np.all(np.isfinite(new.theta)):
            last.update(theta=np.asarray(new.theta), correction=np.asarray(prob.data.correction))
        return new

    P = np.shape(arrays.measured)[0]
    if passes:
        fit, _, _ = fit_profile_block(fit_at, np.asarray(sigma0).reshape(P, 2, 2 * K), k_min=2)
    else:
        fit = fit_at(sigma0)
    problem = fit.problem
    corrected = fit
    ridge, deeper = None, False
    if TREAD in free and np.all(np.isfinite(fit.theta)) and (
            profile_ridge or (d_new is not None and float(fit.values[TREAD]) > d_new * (1 + 1e-9))):
        # the ridge's profile (§13.4 *intervals along the ridge*): on a flat, curved ridge the free fit can stop short
        # of its optimum; a slice well below it restarts the fit there
        ridge = ridge_profile(problem, fit, depth_max=d_new, **opts)
        ok = ridge.converged & np.isfinite(ridge.deviance)
        if ok.any() and np.min(ridge.deviance[ok]) < -RIDGE_BETTER:
            b = int(np.argmin(np.where(ok, ridge.deviance, np.inf)))
            refit = least_squares(problem, ridge.theta[b], free, **opts)
            if np.all(np.isfinite(refit.theta)):
                s0 = float(fit.extra["sigma_scale"])
                data = eqx.tree_at(lambda a: a.weight, problem.data, np.asarray(problem.data.weight) / s0)
                scaled = dataclasses.replace(problem, data=data, sigma="fixed")
                gain = _total_chi2(scaled, refit.theta, free) - _total_chi2(scaled, fit.theta, free)
                if gain < 0:
                    fit = refit
                    ridge = dataclasses.replace(ridge, deviance=ridge.deviance - gain)
        deeper = d_new is not None and float(fit.values[TREAD]) > d_new * (1 + 1e-9)
        if deeper:
            deeper = 1e3 * float(fit.values[TREAD])
            fit, ridge = _at_new_depth(problem, fit, ridge, d_new, **opts)
    if settings.grid_check and fit is not corrected and np.all(np.isfinite(fit.theta)):
        problem, fit = grid_corrected(problem, fit, settings, k_max, **opts)  # moved along the ridge: at its state
    est = _finish_state(fit, problem, load, geometry, ring, laws, omega, settings, fixed, ring_covariance, measured,
                        prior, k_max, ridge, d_new)
    if ridge is not None and deeper and TREAD in fit.names:
        est.flags.append(f"{TREAD}: the free fit went deeper ({deeper:.3g} mm) than the new tread "
                         f"({1e3 * d_new:.3g} mm, the tyre file's tread_depth_new_mm); refitted from the ridge's best "
                         "depth within it (docs/physics.md §13.4)")
    return est


def new_tread_depth(laws: TyreLaws) -> float | None:
    """d_new [m], the new tread's depth the tyre file states (``tread_depth_new_mm``, docs/formats.md §1) — the bound
    on the estimated depth (docs/physics.md §13.3) — or None (not stated, or no tread law)."""
    if not laws.has_tread_depth or laws.tread_depth_new is None:
        return None
    return float(laws.tread_depth_new)


def _at_new_depth(problem: Problem, fit, ridge: RidgeProfile, d_new: float, **opts):
    """The fit within d ≤ d_new (docs/physics.md §13.4 *the new tread's bound*) when the free fit went deeper than
    the new tread: the posterior's mode within the bound is either a minimum of the ridge below it — the best of
    the ridge's slices (all at d ≤ d_new) is inside, and the free fit restarted there stays within — or on the
    bound, the rest fitted with d held at the deepest slice, d_new. Returns ``(fit, ridge)``, the ridge's deviance
    relative to the new fit; unchanged if no slice converged or the refit failed."""
    ok = ridge.converged & np.isfinite(ridge.deviance)
    if not ok.any():
        return fit, ridge
    b = int(np.argmin(np.where(ok, ridge.deviance, np.inf)))
    j = STATE_PARAMETERS.index(TREAD)
    new = None
    if b < ridge.depth.size - 1:  # a minimum below the bound: the free fit from there
        refit = least_squares(problem, ridge.theta[b], tuple(fit.names), **opts)
        if np.all(np.isfinite(refit.theta)) and float(refit.theta[j]) <= d_new * (1 + 1e-9):
            new = refit
    if new is None:  # on the bound: d held at the slice, the rest fitted
        b = ridge.depth.size - 1 if ok[-1] else b
        held = least_squares(problem, ridge.theta[b], tuple(n for n in fit.names if n != TREAD), **opts)
        if not np.all(np.isfinite(held.theta)):
            return fit, ridge
        new = held
    s0 = float(fit.extra["sigma_scale"])
    data = eqx.tree_at(lambda a: a.weight, problem.data, np.asarray(problem.data.weight) / s0)
    scaled = dataclasses.replace(problem, data=data, sigma="fixed")
    shift = _total_chi2(scaled, new.theta, tuple(new.names)) - _total_chi2(scaled, fit.theta, tuple(fit.names))
    return new, dataclasses.replace(ridge, deviance=ridge.deviance - shift)


def _finish_state(fit, problem, load, geometry, ring, laws, omega, settings, fixed, ring_covariance, measured, prior,
                  k_max, ridge: RidgeProfile | None = None, d_new: float | None = None) -> StateEstimate:
    free = tuple(fit.names)
    # the depth held at a ridge slice by the new tread's bound (not by the user or a missing law): still estimated
    bounded = ridge is not None and TREAD not in free and TREAD not in fixed and laws.has_tread_depth
    theta = np.asarray(fit.theta, dtype=np.float64)
    finite = bool(np.all(np.isfinite(theta)))
    names = ()
    if ring_covariance is not None:  # the ring's parameters and the state laws identified with it (k_x, the shares)
        names = tuple(ring_covariance.names)
    from ringfit.physics.operating import Drum, FlatRoad

    drum = load.drum_diameter_m
    road1 = Drum(float(drum)) if drum else FlatRoad()
    value, jt, jr = state_quantities(theta, geometry, ring, laws, omega, road1, ring_names=names, settings=settings)
    idx = [STATE_PARAMETERS.index(n) for n in free]
    G = jt[:, idx] * _du_dtheta(theta)[idx][None, :]  # d quantity / du_free
    cov = np.asarray(fit.covariance_log)
    # the model's form error as its held-out harmonic bands show it (§11's discrepancy ratio κ, §13.4): every
    # statistical variance × κ
    kappa = discrepancy_ratio(np.asarray(fit.jacobian), np.asarray(fit.residuals),
                              band_folds(np.arange(fit.residuals.size), (k_max - 1))) if finite else 1.0
    cov = kappa * cov
    var = np.einsum("qi,ij,qj->q", G, cov, G)
    ring_sd = np.zeros(len(value))
    if names and finite:
        # the ring's covariance: û moves with ln q by −(JᵀJ)⁻¹ Jᵀ ∂r/∂ln q (the rows the solver minimised), and
        # the quantities depend on the ring directly too (docs/physics.md §13.4, as §10)
        du_dq, _ = optimum_ring_shift(fit, ring, names, laws)
        total = G @ du_dq + jr
        idx_c = [ring_covariance.names.index(n) for n in names]
        sigma_q = np.asarray(ring_covariance.ln)[np.ix_(idx_c, idx_c)]
        ring_var = np.einsum("qi,ij,qj->q", total, sigma_q, total)
        ring_sd = np.sqrt(np.maximum(ring_var, 0.0))
        var = var + ring_var
    grid = None
    if settings.grid_check and finite:
        # the model's own grid (§13.4, as §10's load estimate): how far each quantity moves when the grid is refined
        # at the fit; its square joins every variance (the revolutions' too: the same error in each)
        shift_u = state_grid_shift(fit, problem, settings, k_max)
        grid = {"grid": [settings.n_grid, GRID_FINE * settings.n_grid], "shift": G @ shift_u, "applied": True}
        # Richardson's extrapolation to the continuum: the value is moved by the shift still to come, and the
        # shift's square stays in the variance (the extrapolation's own error is of its order at worst)
        value = value + grid["shift"]
        var = var + grid["shift"] ** 2
    sd = np.sqrt(np.maximum(var, 0.0))
    z = float(ndtri(0.975))
    along = None
    # held on the new tread's bound, the depth is still uncertain along the ridge below it: every revolution's held
    # quantities carry it (its column in the gradient, its spread over the slices; its Laplace variance is 0)
    names_u, G_u, cov_l = free, G, cov
    if bounded and finite:
        names_u = free + (TREAD,)
        idx_u = [STATE_PARAMETERS.index(n) for n in names_u]
        G_u = jt[:, idx_u] * _du_dtheta(theta)[idx_u][None, :]
        cov_l = np.zeros((len(names_u),) * 2)
        cov_l[:-1, :-1] = cov
    if ridge is not None and finite:
        anchor = None
        if TREAD in free:  # the fit's own point on the ridge (§13.4; ridge.free: the fit's free but the depth)
            C = np.asarray(fit.covariance_log, dtype=np.float64)
            i_r = [free.index(n) for n in ridge.free]
            i_d = free.index(TREAD)
            if np.all(np.isfinite(C)) and C[i_d, i_d] > 0:
                anchor = C[np.ix_(i_r, i_r)] - np.outer(C[i_r, i_d], C[i_d, i_r]) / C[i_d, i_d]
        along = _along_ridge(ridge, kappa, theta, names_u, geometry, ring, laws, omega, road1, settings,
                             ring_sd if names else np.zeros(len(value)), anchor_cov=anchor)
    cov_u = cov_l
    if along is not None:  # the held quantities of every revolution carry the spread along the ridge (§13.4)
        cov_u = cov_l + along["spread_u"]
    # which quantities are held, which not told
    prior_sd = {PRESSURE: PRESSURE_PRIOR_SD, SLIP: SLIP_PRIOR_SD / 0.01, TREAD: TREAD_PRIOR_SD}
    held = {LOAD: LOAD not in free, PRESSURE: PRESSURE not in free, SLIP: SLIP not in free,
            TREAD: TREAD not in free and not bounded}
    untold_param = {}
    for n, psd in prior_sd.items():
        if n in free:
            i = free.index(n)
            untold_param[n] = math.sqrt(max(cov[i, i], 0.0)) >= UNTOLD_SHARE * psd
    keys = list(QUANTITIES)
    source_of = {"load_n": LOAD, "pressure_bar": PRESSURE, "slip": SLIP, "fx_n": SLIP, "torque_nm": SLIP,
                 "tread_depth_mm": TREAD}
    quantities = {}
    for q, key in enumerate(keys):
        unit, scale, what = QUANTITIES[key]
        v = float(value[q])
        param = source_of.get(key)
        if param is not None and held[param]:
            status = "fixed"
        elif param is not None and untold_param.get(param, False):
            status = "not told"
        else:
            status = "estimated"
        lo, hi = v - z * sd[q], v + z * sd[q]
        if key in LOG_QUANTITIES and v > 0:  # log-normal in the log coordinates
            s = sd[q] / v
            lo, hi = v * math.exp(-z * s), v * math.exp(z * s)
        if along is not None and status != "fixed" and np.isfinite(along["lo"][q]):
            lo, hi = min(lo, along["lo"][q]), max(hi, along["hi"][q])  # the wider: the ridge's or the Laplace's
        if key == "tread_depth_mm" and d_new is not None and status != "fixed":
            hi = min(hi, d_new)  # the new tread's depth bounds it (§13.3)
            lo = min(lo, hi)
        if along is not None and status != "fixed" and np.isfinite(along["lo"][q]):
            sd[q] = max(sd[q], (hi - lo) / (2 * z) if key not in LOG_QUANTITIES or v <= 0 or lo <= 0
                        else v * math.log(hi / lo) / (2 * z))
        quantities[key] = {"value": v * scale, "lo": lo * scale, "hi": hi * scale, "sd": float(sd[q]) * scale,
                           "unit": unit, "status": status, "what": what,
                           **({"ring_sd": float(ring_sd[q]) * scale} if names else {})}
    # correlation of the quantities (from the statistical covariance and the ring's, together)
    sel = [keys.index(k) for k in CORRELATED if quantities[k]["status"] != "fixed" and sd[keys.index(k)] > 0]
    cq = G[sel] @ cov @ G[sel].T
    if names and finite:
        cq = cq + total[sel] @ sigma_q @ total[sel].T
    d = np.sqrt(np.maximum(np.diag(cq), 1e-300))
    corr = cq / np.outer(d, d)
    corr_names = [keys[i] for i in sel]
    untold = []
    for key in keys:
        if quantities[key]["status"] == "not told":
            untold.append(f"{key}: the data do not bound it — its interval is as wide as its prior "
                          f"(docs/physics.md §13.4); the value is the prior's, not a measurement")
    for a in range(len(sel)):
        for b in range(a + 1, len(sel)):
            if abs(corr[a, b]) > RIDGE_CORRELATION and {corr_names[a], corr_names[b]} not in ONE_QUANTITY:
                untold.append(f"{corr_names[a]} and {corr_names[b]} are not told apart (correlation "
                              f"{corr[a, b]:+.3f}): their intervals are along the ridge (marginal)")
    # fit quality per channel
    model_rows = np.asarray(fit.extra["aux"])
    resid = (model_rows - np.reshape(measured, model_rows.shape)).reshape(-1, model_rows.shape[-1])
    half = resid.shape[-1] // 2  # per profile (a drifting recording's stretches: their mean)
    rms = {"radial": float(np.sqrt(0.5 * np.mean(np.sum(resid[:, :half] ** 2, axis=1)))),
           "tangential": float(np.sqrt(0.5 * np.mean(np.sum(resid[:, half:] ** 2, axis=1))))}
    at_bound = [n for n in fit.extra["at_bound"] if n in STATE_NAMES or n == GAIN]
    at_bound += [n for n in near_bound(theta, free) if n not in at_bound]
    converged = bool(fit.converged and finite and not at_bound)
    flags = [f for f in fit.flags if "solver did not converge" in f or any(f.startswith(n) for n in STATE_NAMES)]
    if bounded:
        flags.append(f"{TREAD}: the free fit went deeper than the new tread ({1e3 * d_new:.3g} mm, the tyre file's "
                     f"tread_depth_new_mm); held at the ridge's best depth within it, "
                     f"{1e3 * float(theta[STATE_PARAMETERS.index(TREAD)]):.3g} mm, its interval along the ridge "
                     "(docs/physics.md §13.4)")
    nuisances = {}
    for n, key, s in ((GAIN, "gain", 1.0), (ANGLE_OFFSET, "angle_offset_deg", 180 / math.pi), (CORNER, "corner_hz", 1.0),
                      (TILT, "tilt_gain", 1.0), (GAIN_TANGENTIAL, "gain_tangential", 1.0),
                      (LINER_OFFSET, "liner_offset_mm", 1e3)):
        nuisances[key] = {"value": float(fit.values[n]) * s, "stderr": float(fit.stderr.get(n, math.nan)) * s}
    return StateEstimate(quantities=quantities, correlation={"names": corr_names, "matrix": corr.tolist()},
                         untold=untold, status=fit.status, converged=converged, rms=rms, flags=flags,
                         nuisances=nuisances, fit=fit, load=load, theta=theta, cov_u=cov_u, gradient_u=G_u,
                         ring_sd=ring_sd, omega=float(omega), k_max=int(k_max), fixed=dict(fixed),
                         discrepancy=float(kappa), ridge=ridge, spread_u=None if along is None else along["spread_u"],
                         names_u=tuple(names_u), grid_check=grid)


#: The state's model grid (docs/physics.md §13.4 *the model's grid*): the fit's model is the one at GRID_FINE × M,
#: by defect correction of the M model; at most GRID_PASSES corrections, until the fit moves less than GRID_MOVE
#: of its σ in every free coordinate.
GRID_FINE = 4
GRID_PASSES = 4
GRID_MOVE = 0.05


def _rows_at(problem: Problem, theta, settings: EstimateSettings, k_max: int, n_grid: int) -> np.ndarray:
    """The model's rows ``(P, 4K)`` at θ on the grid ``n_grid``, without the defect correction."""
    data = eqx.tree_at(lambda a: a.correction, problem.data, as_traced(np.zeros(np.shape(problem.data.correction))))
    prob = state_problem(data, dataclasses.replace(settings, n_grid=int(n_grid)), k_max, problem.prior)
    return np.asarray(residuals(prob, theta)[1])


def grid_correction(problem: Problem, theta, settings: EstimateSettings, k_max: int, factor: int = GRID_FINE):
    """The defect correction ``(P, 4K)`` at θ: the rows on the grid factor·M less those on M (§13.4)."""
    return (_rows_at(problem, theta, settings, k_max, factor * settings.n_grid)
            - _rows_at(problem, theta, settings, k_max, settings.n_grid))


def with_correction(problem: Problem, correction) -> Problem:
    """``problem`` with the model rows' defect correction ``correction`` ``(P, 4K)``."""
    return dataclasses.replace(problem, data=eqx.tree_at(lambda a: a.correction, problem.data,
                                                         as_traced(np.asarray(correction, dtype=np.float64))))


def grid_corrected(problem: Problem, fit, settings: EstimateSettings, k_max: int, factor: int = GRID_FINE, **opts):
    """The fit of the model on the grid factor·M by defect correction (docs/physics.md §13.4 *the model's grid*):
    the M model's rows plus the difference factor·M − M evaluated at the last fit, refitted from it, until the fit
    moves less than :data:`GRID_MOVE` σ (at most :data:`GRID_PASSES` times). The correction changes slowly with the
    state, so each pass takes the fit most of the way; the Jacobian stays the M model's. Returns ``(problem with the
    last correction, fit)``; the input fit if a pass fails."""
    free = tuple(fit.names)
    for _ in range(GRID_PASSES):
        prob = with_correction(problem, grid_correction(problem, fit.theta, settings, k_max, factor))
        new = least_squares(prob, fit.theta, free, **opts)
        if not np.all(np.isfinite(new.theta)):
            break
        fs = free_set(prob, free)
        moved = fs.u_of_theta(prob, new.theta) - fs.u_of_theta(prob, fit.theta)
        sd = np.sqrt(np.maximum(np.diag(np.asarray(new.covariance_log)), 1e-300))
        problem, fit = prob, new
        if np.max(np.abs(moved) / sd) < GRID_MOVE:
            break
    return problem, fit


def state_grid_shift(fit, problem: Problem, settings: EstimateSettings, k_max: int) -> np.ndarray:
    """The change of the free parameters' solver coordinates ``(k,)`` still to come when the model's grid is refined
    beyond the fit's, GRID_FINE·M (docs/physics.md §13.4 *the model's grid*), by Richardson's rule on the fit's own
    moves: δu_a and δu_b, the Gauss–Newton steps of the rows' change M → GRID_FINE/2·M and GRID_FINE/2·M →
    GRID_FINE·M at the fit (its Jacobian, σ scale as fitted), and ρ = |δu_a|/|δu_b| in the metric of the fit's
    covariance, clipped to [2, 16] (at worst a first-order error, as large as the last move): δu_b/(ρ − 1). Three
    residual evaluations at the fit."""
    M = settings.n_grid
    grids = [M * 2**j for j in range(int(round(math.log2(GRID_FINE))) + 1)]
    rows = [_rows_at(problem, fit.theta, settings, k_max, g) for g in grids]
    w = np.asarray(problem.data.weight) / float(fit.extra["sigma_scale"])
    return grid_moves(fit, [r * w for r in rows])[1]


# --------------------------------------------------------------------------- per revolution

@dataclass
class StateRevolutions:
    """Per-revolution state of a recording (docs/formats.md §7.1): ``revolution``, ``t_s``, ``rotation_hz``
    ``(R,)``; ``values``, ``lo``, ``hi`` — key of :data:`QUANTITIES` → ``(R,)`` in the file's units (95 %,
    statistical); ``rms`` ``(R,)`` the whitened residual of each revolution relative to its noise; ``noise_scale``
    s_r; ``steps`` Gauss–Newton steps taken."""

    revolution: np.ndarray
    t_s: np.ndarray
    rotation_hz: np.ndarray
    values: dict
    lo: dict
    hi: dict
    rms: np.ndarray
    noise_scale: float
    steps: int = 1
    free: tuple = ()

    def __len__(self) -> int:
        return int(self.revolution.size)

    def columns(self) -> dict:
        """Column name → ``(R,)``: revolution, t_s, rotation_hz, then each quantity with ``_lo``, ``_hi``."""
        cols = {"revolution": self.revolution, "t_s": self.t_s, "rotation_hz": self.rotation_hz}
        for key in self.values:
            cols[key] = self.values[key]
            cols[key + "_lo"] = self.lo[key]
            cols[key + "_hi"] = self.hi[key]
        cols["rms_ratio"] = self.rms
        return cols

    def summary(self) -> dict:
        """The per-revolution run in a few numbers for the JSON: revolutions, noise scale, steps, what was stepped."""
        return {"revolutions": len(self), "noise_scale": self.noise_scale, "gauss_newton_steps": self.steps,
                "stepped": list(self.free),
                **{f"{k}_median": float(np.median(v)) for k, v in self.values.items()}}


def _one_profile(data: StateArrays) -> StateArrays:
    """``data`` as one profile at θ's state: a drifting recording's stretches (:func:`estimate_stretches`) collapsed to
    their mean — Ω averaged, the grid's defect correction averaged (it changes slowly with the state), the measured
    rows averaged; one profile's data unchanged."""
    if data.load_scale is None:
        return data
    mean = lambda x: as_traced(np.mean(np.asarray(x), axis=0, keepdims=True))  # noqa: E731
    first = lambda x: as_traced(np.asarray(x)[:1])  # noqa: E731
    return StateArrays(geometry=data.geometry, ring=data.ring, laws=data.laws, omega=mean(data.omega),
                       roads=jax.tree.map(first, data.roads), response=first(data.response),
                       measured=mean(data.measured), weight=first(data.weight), correction=mean(data.correction))


def state_revolutions(rows: np.ndarray, rotation_hz: np.ndarray, reference: StateEstimate, *,
                      settings: EstimateSettings = EstimateSettings(), revolution=None, t_s=None,
                      steps: int = 1, free: tuple = REVOLUTION_FREE) -> StateRevolutions:
    """The state of every revolution (docs/physics.md §13.4 *per revolution*): from the averaged profile's fit
    ``reference``, one Gauss–Newton step per revolution with the reference's Jacobian (computed once), all
    revolutions in one matrix product; ``steps=2`` adds a second step with each revolution's own model rows
    (a batched model evaluation: slower).

    Per revolution only ``free`` (default :data:`REVOLUTION_FREE`: load, slip, gain, angle offset — what changes
    from one revolution to the next) are stepped; the pressure, tread depth, high-pass corner and tilt, which do
    not change within a recording, stay at the averaged fit, and their uncertainty there is carried into every
    revolution's interval (the marginal: the step's sensitivity to them, −(JᵀJ + Λ)⁻¹Jᵀ J_held, through the
    averaged fit's covariance).

    ``rows`` ``(R, 4K)`` each revolution's radial and tangential harmonic rows (as :func:`profile_rows`);
    ``rotation_hz`` ``(R,)`` from the encoder. The weights are each channel's noise spectrum (:func:`channel_weights`, the
    profile block's) of the successive differences of revolutions (noise, blind to a state that changes slowly), and
    the noise scale
    s_r the whitened differences' RMS. **Returns:** :class:`StateRevolutions`.
    """
    fit = reference.fit
    problem = fit.problem
    rows = band_rows(np.asarray(rows, dtype=np.float64), reference.k_max)
    R = rows.shape[0]
    if R < 2:
        raise InputError(f"{R} revolution(s): the per-revolution state needs at least 2")
    diff = np.diff(rows, axis=0) / math.sqrt(2.0)
    weight = channel_weights(np.sqrt(np.mean(diff**2, axis=0)), series=R - 1)
    s_r = float(np.sqrt(np.mean((diff * weight) ** 2)))
    data = eqx.tree_at(lambda a: a.weight, _one_profile(problem.data), as_traced(weight[None]))
    data = eqx.tree_at(lambda a: a.measured, data, as_traced(np.mean(rows, axis=0)[None]))
    prob = dataclasses.replace(problem, data=data)
    # the parameters of the reference's covariance: the fit's, and the tread depth held on the new tread's bound
    names = tuple(reference.names_u or fit.names)
    theta = np.asarray(fit.theta, dtype=np.float64)
    lin = linearize(prob, theta, names)
    J_all = lin.jacobian / s_r
    model_rows = np.asarray(lin.aux)[0]
    fr = [i for i, n in enumerate(names) if n in free]
    hd = [i for i, n in enumerate(names) if n not in free]
    sub = tuple(names[i] for i in fr)
    J, J_h = J_all[:, fr], J_all[:, hd]
    coords = [STATE_COORDS[STATE_PARAMETERS.index(n)] for n in sub]
    u_hat = np.array([c.to_u(theta[STATE_PARAMETERS.index(n)]) for c, n in zip(coords, sub)])
    Wp, mean = problem.prior.rows(sub, len(sub)) if problem.prior is not None else (np.zeros((len(sub),) * 2),
                                                                                    np.zeros(len(sub)))
    Lam = Wp.T @ Wp
    cov = np.linalg.inv(J.T @ J + Lam)
    E = (model_rows[None, :] - rows) * weight[None, :] / s_r  # (R, m): whitened residual at û per revolution
    du = -(E @ J + (Lam @ (u_hat - mean))[None, :]) @ cov.T  # (R, k)
    E_lin = E + du @ J.T  # the linearised residual after the step
    if steps >= 2:  # a second step at each revolution's own model rows, the same Jacobian
        from ringfit.fit.engine import residuals_batch

        th = np.repeat(theta[None], R, axis=0)
        for j, (c, n) in enumerate(zip(coords, sub)):
            th[:, STATE_PARAMETERS.index(n)] = c.from_u(u_hat[j] + du[:, j])
        zero = dataclasses.replace(prob, data=eqx.tree_at(lambda a: a.measured, data,
                                                          as_traced(np.zeros((1, rows.shape[1])))))
        model_r = residuals_batch(zero, th) / weight[None, :]
        E2 = (model_r - rows) * weight[None, :] / s_r
        step = -(E2 @ J + (u_hat[None, :] + du - mean[None, :]) @ Lam.T) @ cov.T
        du = du + step
        E_lin = E2 + step @ J.T
    # quantities: linear in du through the reference's gradient; their σ with the held coordinates' uncertainty
    G = reference.gradient_u
    G_f, G_h = G[:, fr], G[:, hd]
    keys = list(QUANTITIES)
    v0 = np.array([reference.quantities[k]["value"] / QUANTITIES[k][1] for k in keys])
    vals = v0[None, :] + du @ G_f.T
    S = -cov @ (J.T @ J_h)  # d u_free / d u_held of the step
    C_h = np.asarray(reference.cov_u)[np.ix_(hd, hd)]
    T = G_f @ S + G_h
    var = np.einsum("qi,ij,qj->q", G_f, cov, G_f) + np.einsum("qi,ij,qj->q", T, C_h, T)
    # the model's form error (κ > 1, §11) is the same in every revolution: the averaged fit's discrepancy variance
    # of the stepped quantities, (κ − 1) × their statistical variance there, is added to each revolution's
    kappa = float(reference.discrepancy)
    if kappa > 1.0:
        spread = 0.0 if reference.spread_u is None else np.asarray(reference.spread_u)
        C_f = ((np.asarray(reference.cov_u) - spread) / kappa)[np.ix_(fr, fr)]
        var = var + (kappa - 1.0) * np.einsum("qi,ij,qj->q", G_f, C_f, G_f)
    if reference.grid_check is not None:  # the model's grid error (§13.4) is the averaged fit's in every revolution
        var = var + np.asarray(reference.grid_check["shift"]) ** 2
    sd = np.sqrt(np.maximum(var, 0.0))
    z = float(ndtri(0.975))
    omega_r = 2 * math.pi * np.asarray(rotation_hz, dtype=np.float64)
    iq = {k: i for i, k in enumerate(keys)}
    values, lo, hi = {}, {}, {}
    for k in keys:
        s = QUANTITIES[k][1]
        v = vals[:, iq[k]]
        sdk = np.full(R, sd[iq[k]])
        if k == "speed_kmh":  # V = Ω_r·r_road per revolution
            r_road = vals[:, iq["rolling_radius_m"]]
            v = omega_r * r_road
            sdk = omega_r * sd[iq["rolling_radius_m"]]
        values[k] = v * s
        lo[k] = (v - z * sdk) * s
        hi[k] = (v + z * sdk) * s
        if k != "speed_kmh" and not np.any(G_f[iq[k]]):
            # not moved by the step (the pressure, the tread depth): every revolution's value is the averaged fit's,
            # and so is its interval — the marginal along the ridge, cut at the new tread's depth (§13.4), of which
            # the Gaussian of the held coordinates' covariance is only an approximation
            lo[k] = np.full(R, float(reference.quantities[k]["lo"]))
            hi[k] = np.full(R, float(reference.quantities[k]["hi"]))
    rms = np.sqrt(np.mean(E_lin**2, axis=1))
    return StateRevolutions(revolution=np.arange(R) if revolution is None else np.asarray(revolution),
                            t_s=np.zeros(R) if t_s is None else np.asarray(t_s), rotation_hz=np.asarray(rotation_hz),
                            values=values, lo=lo, hi=hi, rms=rms, noise_scale=s_r, steps=int(steps), free=sub)


#: A drift of the state within a recording is flagged when its linear trend over the recording changes Fx or the load
#: by more than this share of the load and by more than DRIFT_Z standard errors of the trend (docs/physics.md §13.6
#: *what the misses are*: an Fx ramp of 8.5 % of the load biased the averaged fit by −4 % in load, one of 2.1 % did
#: not).
DRIFT_SHARE = 0.05
DRIFT_Z = 3.0


def state_drift(revs: StateRevolutions, load_n: float, stretches: int = 0) -> str | None:
    """A flag (or ``None``) when the per-revolution states drift within the recording (docs/physics.md §13.6): the
    least-squares line of each revolution's Fx and load against time, its change over the recording against
    :data:`DRIFT_SHARE` of the load and :data:`DRIFT_Z` standard errors of the slope (from the line's residual
    scatter). The averaged fit assumes one state: a drift smears the patch's features in the averaged profile, and
    the pressure and tread depth read from it — and every revolution's, which carry them — can be biased.
    ``stretches``: the fit was redone on that many stretches (:func:`estimate_stretches`), and the flag says so."""
    t = np.asarray(revs.t_s, dtype=np.float64)
    if t.size < 4 or np.ptp(t) <= 0:
        return None
    span = float(np.ptp(t))
    said = []
    for key, what in (("fx_n", "Fx"), ("load_n", "the load")):
        v = np.asarray(revs.values[key], dtype=np.float64)
        ok = np.isfinite(v)
        if ok.sum() < 4:
            continue
        x, y = t[ok] - t[ok].mean(), v[ok]
        b = float(x @ (y - y.mean()) / (x @ x))
        resid = y - y.mean() - b * x
        se = math.sqrt(float(resid @ resid) / (y.size - 2) / float(x @ x))
        change = b * span
        if abs(change) > DRIFT_SHARE * abs(load_n) and abs(b) > DRIFT_Z * se:
            said.append(f"{what} by {change:+.4g} N ({100 * change / abs(load_n):+.1f} % of the load)")
    if not said:
        return None
    head = f"the state drifted within the recording: {' and '.join(said)} over {span:.3g} s (per-revolution trend); "
    if stretches:
        return head + (f"the state was fitted on {stretches} stretches of the recording, each at its own load and slip "
                       "from the revolutions, sharing the pressure, tread depth and sensor (docs/physics.md §13.4 "
                       "*a drifting state*)")
    return head + ("the averaged fit assumes one state, and the pressure and tread depth read from a drifting "
                   "recording can be biased (docs/physics.md §13.6) — a shorter or steadier stretch reads them better")


def estimate_recording_state(record, geometry: TyreGeometry, ring: RingParams, laws: TyreLaws, *,
                             settings: EstimateSettings = EstimateSettings(k_max=STATE_K_MAX),
                             fixed: dict | None = None,
                             k_tread_in_file: bool = True, per_revolution: bool = True, progress: bool = False,
                             ring_covariance=None, steps: int = 1):
    """The state of a continuous recording (docs/physics.md §13.4): one pass over it for both channels
    (:func:`~ringfit.fit.estimate.revolutions.recording_revolutions` with ``tangential``), the load estimate of
    the averaged profile (as ``ringfit estimate`` without ``--state``), its state (:func:`estimate_state`) and,
    with ``per_revolution``, every revolution's (:func:`state_revolutions`).

    **Returns:** ``(LoadEstimate, StateEstimate, StateRevolutions or None)``.
    """
    from ringfit.fit.estimate.revolutions import recording_revolutions

    data = recording_revolutions(record, k_max=settings.k_max, progress=progress, geometry=geometry, tangential=True,
                                 clamp=True)
    omega = 2 * math.pi * float(np.mean(data.rotation_hz))
    load = estimate_load(data.profile, geometry, ring, settings=settings, k_tread_in_file=k_tread_in_file, omega=omega,
                         omega_source=data.rotation_source, response=data.response, noise_per_angle=data.noise,
                         noise_source=data.noise_source, ring_covariance=ring_covariance, laws=laws)
    state = estimate_state(data.profile, geometry, ring, laws, settings=settings, fixed=fixed, omega=omega,
                           omega_source=data.rotation_source, response=data.response, ring_covariance=ring_covariance,
                           load=load, k_tread_in_file=k_tread_in_file)
    revs = None
    if per_revolution:
        rows = np.concatenate([data.rows, data.rows_tangential], axis=1)
        revs = state_revolutions(rows, data.rotation_hz, state, settings=settings, revolution=data.revolution,
                                 t_s=data.t_s, steps=steps)
        state, revs = drifting_state(data, state, revs, geometry, ring, laws, settings=settings,
                                     ring_covariance=ring_covariance, steps=steps, rows=rows)
    return load, state, revs


#: A drifting recording (:func:`state_drift`) is fitted on at most DRIFT_STRETCHES stretches of consecutive
#: revolutions, each of at least STRETCH_REVOLUTIONS (docs/physics.md §13.4 *a drifting state*): the smear of a ramp
#: within a stretch falls as the square of its share of the recording (a quarter of the ramp: 1/16).
DRIFT_STRETCHES = 4
STRETCH_REVOLUTIONS = 8


def _as_wide_as(est: StateEstimate, reference: StateEstimate, d_new: float | None) -> None:
    """The stretches' intervals no narrower than the averaged fit's (docs/physics.md §13.4 *a drifting state*): each
    quantity's interval is the wider of its own and the averaged fit's moved to the new value (by ratio for
    :data:`LOG_QUANTITIES`), its σ the larger; the covariance the revolutions carry (``cov_u``, ``spread_u``, κ) the
    averaged fit's where both fitted the same parameters. The stretches' slips are the revolutions' steps at the
    averaged fit's tread depth: held fixed while the fit moves the depth, the force each stretch adds would tell the
    depth through the brush's stiffness — information the data do not hold. They remove the smear's bias; they add
    nothing to what the recording tells of the shared state."""
    for key, q in est.quantities.items():
        r = reference.quantities[key]
        if q["status"] == "fixed" or r["status"] == "fixed":
            continue
        v, vr = q["value"], r["value"]
        if key in LOG_QUANTITIES and v > 0 and vr > 0 and r["lo"] > 0:
            lo, hi = v * r["lo"] / vr, v * r["hi"] / vr
        else:
            lo, hi = v - (vr - r["lo"]), v + (r["hi"] - vr)
        q["lo"], q["hi"] = min(q["lo"], lo), max(q["hi"], hi)
        if key == "tread_depth_mm" and d_new is not None:
            q["hi"] = min(q["hi"], 1e3 * d_new)
            q["lo"] = min(q["lo"], q["hi"])
        q["sd"] = max(q["sd"], r["sd"])
    if tuple(est.names_u or ()) == tuple(reference.names_u or ()) and reference.cov_u is not None:
        est.cov_u, est.spread_u, est.discrepancy = reference.cov_u, reference.spread_u, reference.discrepancy


def drifting_state(data, state: StateEstimate, revs: StateRevolutions, geometry: TyreGeometry, ring: RingParams,
                   laws: TyreLaws, *, settings: EstimateSettings, ring_covariance=None, steps: int = 1, rows=None):
    """``(state, revs)`` of a recording after its drift check (:func:`state_drift`): unchanged when the state held
    still; when it drifted, the state fitted on stretches of the recording (:func:`estimate_stretches`) and every
    revolution stepped from that fit, flagged either way. ``data``: the recording's
    :func:`~ringfit.fit.estimate.revolutions.recording_revolutions`; ``rows``: its radial and tangential rows side by
    side, as :func:`state_revolutions` took them (default: joined here). ``state`` itself is left as it was but for a
    flag (its quantities are the averaged fit's)."""
    load_n = float(state.quantities["load_n"]["value"])
    drift = state_drift(revs, load_n)
    if not drift:
        return state, revs
    if rows is None:
        rows = np.concatenate([data.rows, data.rows_tangential], axis=1)
    new = estimate_stretches(rows, data.rotation_hz, state, revs, geometry, ring, laws, settings=settings,
                             ring_covariance=ring_covariance)
    if new is None or (state.converged and not new.converged):
        why = ("" if new is None else
               "; the fit on stretches did not converge and the averaged fit is kept")
        state.flags.append(drift + why)
        return state, revs
    new_revs = state_revolutions(rows, data.rotation_hz, new, settings=settings, revolution=data.revolution,
                                 t_s=data.t_s, steps=steps)
    new.flags.append(state_drift(revs, load_n, stretches=len(new.stretches["revolutions"])))
    return new, new_revs


#: Central-difference steps of a stretch's ln load and slip for :func:`_drift_basis` (about the drift's own size: the
#: contact's active set makes the rows a fine staircase in the load).
BASIS_STEP = (2e-3, 2e-4)


def _drift_basis(arrays: StateArrays, weight, theta, settings, k_max, n) -> np.ndarray | None:
    """The directions ``(S·4K, 2S − 2)`` (orthonormal) of the stretches' weighted rows that their own load and slip
    move about their mean (docs/physics.md §13.4 *a drifting state*): the rows' derivative in each stretch's ln load
    and slip (central differences at θ), combined so that the revolution-weighted mean load share and slip shift stay
    put (the mean is θ's, fitted). Taken out of the residual, the differences between stretches — which the fixed
    deviations would otherwise ask the shared state to explain through the model's response to load and force —
    tell nothing; what the stretches share does."""
    S = int(np.shape(arrays.omega)[0])
    prob = state_problem(eqx.tree_at(lambda a: a.weight, arrays, weight), settings, k_max)
    scale0, shift0 = np.asarray(arrays.load_scale, dtype=np.float64), np.asarray(arrays.slip_shift, dtype=np.float64)

    def rows_at(scale, shift):
        data = eqx.tree_at(lambda a: (a.load_scale, a.slip_shift), prob.data, as_traced((scale, shift)))
        return np.asarray(residuals(dataclasses.replace(prob, data=data), theta)[1]) * weight

    cols = []
    for which, h in ((0, BASIS_STEP[0]), (1, BASIS_STEP[1])):
        for s in range(S):
            up, dn = [scale0.copy(), shift0.copy()], [scale0.copy(), shift0.copy()]
            if which == 0:
                up[0][s] *= math.exp(h)
                dn[0][s] *= math.exp(-h)
            else:
                up[1][s] += h
                dn[1][s] -= h
            cols.append(((rows_at(*up) - rows_at(*dn)) / (2 * h)).ravel())
    D = np.stack(cols, axis=1)  # (S·4K, 2S): ln load of each stretch, then slip of each
    if not np.all(np.isfinite(D)):  # a contact solve failed at a stretch's moved state: no basis, no stretches
        return None
    C = np.zeros((2, 2 * S))
    C[0, :S], C[1, S:] = n, n
    from scipy.linalg import null_space

    A = D @ null_space(C)
    u, sv, _ = np.linalg.svd(A, full_matrices=False)
    keep = sv > 1e-9 * (sv[0] if sv.size else 0.0)
    return u[:, keep]


def estimate_stretches(rows: np.ndarray, rotation_hz: np.ndarray, reference: StateEstimate, revs: StateRevolutions,
                       geometry: TyreGeometry, ring: RingParams, laws: TyreLaws, *,
                       settings: EstimateSettings = EstimateSettings(k_max=STATE_K_MAX), ring_covariance=None,
                       stretches: int = DRIFT_STRETCHES) -> StateEstimate | None:
    """The state of a drifting recording (docs/physics.md §13.4 *a drifting state*): its revolutions in
    ``stretches`` runs of consecutive revolutions, each run's averaged rows a profile of its own, at the load and
    slip of the recording's mean state moved by the run's mean per-revolution drift (``revs``, stepped from the
    averaged fit ``reference``: a drift the revolutions measure to first order), all sharing the pressure, tread
    depth and sensor; the fit, ridge and new tread's bound of :func:`estimate_state` on the reference's band,
    started from its θ, each stretch weighted by the reference's σ × √(R/n_s) (no noise passes), its intervals no
    narrower than the reference's (:func:`_as_wide_as`). The reported state is the recording's mean.

    ``rows`` ``(R, 4K)`` and ``rotation_hz`` ``(R,)`` as :func:`state_revolutions`'. **Returns:**
    :class:`StateEstimate` with ``stretches``, or None when the recording has fewer than two stretches'
    worth of revolutions (:data:`STRETCH_REVOLUTIONS` each), the reference's fit is not finite, or the model fails at
    a stretch's moved state."""
    rows = band_rows(np.asarray(rows, dtype=np.float64), reference.k_max)
    R = rows.shape[0]
    S = min(int(stretches), R // STRETCH_REVOLUTIONS)
    theta1 = np.asarray(reference.theta, dtype=np.float64)
    if S < 2 or not np.all(np.isfinite(theta1)):
        return None
    parts = np.array_split(np.arange(R), S)
    n = np.array([p.size for p in parts], dtype=np.float64)
    load_r, slip_r = np.asarray(revs.values["load_n"]), np.asarray(revs.values["slip"])
    mean_load = np.array([np.mean(load_r[p]) for p in parts])
    mean_slip = np.array([np.mean(slip_r[p]) for p in parts])
    scale = mean_load / (n @ mean_load / n.sum())
    shift = mean_slip - n @ mean_slip / n.sum()
    k_max = int(reference.k_max)
    K = k_max - 1
    settings = dataclasses.replace(settings, k_max=k_max)
    base = reference.fit.problem.data
    roads = jax.tree.map(lambda x: np.repeat(np.asarray(x)[:1], S, axis=0), base.roads)
    omega = np.array([2 * math.pi * float(np.mean(np.asarray(rotation_hz)[p])) for p in parts])
    measured = np.stack([np.mean(rows[p], axis=0) for p in parts])
    arrays = StateArrays(geometry=geometry, ring=ring, laws=laws, omega=omega, roads=roads,
                         response=np.repeat(np.asarray(base.response)[:1], S, axis=0), measured=measured,
                         weight=np.ones((S, 4 * K)), correction=np.zeros((S, 4 * K)), load_scale=scale,
                         slip_shift=shift)
    fixed = dict(reference.fixed)
    free = free_parameters(laws, fixed)
    prior = GaussianPrior.independent({k: v for k, v in state_priors(geometry, laws).items() if k in free})
    # σ of each stretch: the averaged fit's (its noise passes' σ × its residual scale), × √(R/n_s) — not each
    # stretch's own residual: the model's form error is the same in every stretch, and a σ from each stretch's
    # residual would count it as independent noise S times (intervals √S too narrow where it dominates); the
    # engine's "inflate" widens them where the stretches' residual exceeds it
    sigma_ref = float(reference.fit.extra["sigma_scale"]) / np.asarray(base.weight)[0]
    sigma0 = sigma_ref[None, :] * np.sqrt(R / n)[:, None]
    basis = _drift_basis(arrays, 1.0 / sigma0, theta1, settings, k_max, n)
    if basis is None:
        return None
    arrays = eqx.tree_at(lambda a: a.basis, eqx.tree_at(lambda a: a.weight, arrays, 1.0 / sigma0), basis,
                         is_leaf=lambda x: x is None)
    opts = dict(max_steps=settings.max_steps, rtol=settings.rtol, atol=settings.atol)
    est = _state_passes(arrays, theta1, sigma0, free, prior, reference.load, geometry, ring, laws, reference.omega,
                        settings, fixed, ring_covariance, k_max, new_tread_depth(laws), opts, passes=False,
                        ridge=False)  # its intervals are the averaged fit's (along its ridge) or wider
    _as_wide_as(est, reference, new_tread_depth(laws))
    est.stretches = {"revolutions": [int(p.size) for p in parts], "load_share": [float(v) for v in scale],
                     "slip_shift": [float(v) for v in shift]}
    est.band_kappa = reference.band_kappa
    est.flags = [f for f in reference.flags if f.startswith("harmonics 2…")] + est.flags
    return _speed_source(est, reference.load)


# --------------------------------------------------------------------------- Fisher information

@dataclass
class StateFisher:
    """Per-revolution Fisher information of the state (docs/physics.md §13.5): ``names`` (keys of
    :data:`QUANTITIES` that vary), ``value``, ``sd`` (SI units of the quantity; the file's units in
    :meth:`table`), ``correlation`` ``(Q, Q)``; ``free``: the θ names free in it; ``information`` ``(k, k)`` in u."""

    names: list
    value: np.ndarray
    sd: np.ndarray
    correlation: np.ndarray
    free: tuple
    information: np.ndarray

    def table(self) -> dict:
        """key → {value, sd, sd_pct, unit} in the file's units (σ per revolution)."""
        out = {}
        for i, k in enumerate(self.names):
            unit, scale, _ = QUANTITIES[k]
            v = float(self.value[i]) * scale
            out[k] = {"value": v, "sd": float(self.sd[i]) * scale, "unit": unit,
                      "sd_pct": 100 * float(self.sd[i]) / abs(float(self.value[i])) if self.value[i] else math.inf}
        return out

    def corr(self, a: str, b: str) -> float:
        """The correlation of quantities ``a`` and ``b`` per revolution."""
        return float(self.correlation[self.names.index(a), self.names.index(b)])


def state_fisher(geometry: TyreGeometry, ring: RingParams, laws: TyreLaws, state: TyreState, noise_ms2: float, *,
                 samples_per_revolution: int = 1024, settings: EstimateSettings = EstimateSettings(k_max=STATE_K_MAX),
                 gain: float = 1.0, corner_hz: float = 0.3, tilt: float = 0.5, with_priors: bool = False,
                 fixed: tuple = (), drum_diameter_m=None) -> StateFisher:
    """The Fisher information of one revolution at white noise σ = ``noise_ms2`` per sample in each channel
    (docs/physics.md §13.5): harmonic k's Re and Im have variance 2σ²/N (N samples per revolution), the rows
    are both channels' harmonics 2…k_max (default the state's band, :data:`STATE_K_MAX`), the nuisances (gain,
    offset, corner, tilt) free. ``with_priors`` adds §13.4's weak priors (default: the data alone); ``fixed``: θ
    names held.

    **Returns:** :class:`StateFisher`: σ per revolution of every quantity (load, pressure, κ, Fx, depth, speed …)
    and their correlation (delta method through the inverse information).
    """
    k_max = settings.k_max
    K = k_max - 1
    sigma_row = noise_ms2 * math.sqrt(2.0 / samples_per_revolution)
    slip = 0.0 if state.slip is None else float(state.slip)
    theta = np.array([float(state.load), float(state.pressure), slip, float(state.tread_depth), gain, 0.0,
                      corner_hz, tilt, 1.0, LINER_OFFSET_PRIOR[0]])
    omega = float(state.omega)
    arrays = StateArrays(geometry=geometry, ring=ring, laws=laws, omega=np.array([omega]),
                         roads=flat_or_drum(drum_diameter_m, 1), response=np.ones((1, K)),
                         measured=np.zeros((1, 4 * K)), weight=np.full((1, 4 * K), 1.0 / sigma_row),
                         correction=np.zeros((1, 4 * K)))
    free = free_parameters(laws, {n: None for n in fixed})
    prior = GaussianPrior.independent({k: v for k, v in state_priors(geometry, laws).items() if k in free}) \
        if with_priors else None
    problem = state_problem(arrays, settings, k_max, prior, sigma="fixed")
    lin = linearize(problem, theta, free)
    F = lin.jacobian.T @ lin.jacobian
    if prior is not None:
        W, _ = prior.rows(free, len(free))
        F = F + W.T @ W
    cov = np.linalg.pinv(F)
    from ringfit.physics.operating import Drum, FlatRoad

    road = Drum(float(drum_diameter_m)) if drum_diameter_m else FlatRoad()
    value, jt, _ = state_quantities(theta, geometry, ring, laws, omega, road, settings=settings)
    idx = [STATE_PARAMETERS.index(n) for n in free]
    G = jt[:, idx] * _du_dtheta(theta)[idx][None, :]
    cq = G @ cov @ G.T
    keys = list(QUANTITIES)
    keep = [i for i in range(len(keys)) if cq[i, i] > 0]
    cq = cq[np.ix_(keep, keep)]
    sd = np.sqrt(np.diag(cq))
    return StateFisher(names=[keys[i] for i in keep], value=value[keep], sd=sd, correlation=cq / np.outer(sd, sd),
                       free=free, information=F)


__all__ = ["grid_corrected", "STATE_PARAMETERS", "STATE_NAMES", "STATE_COORDS", "PRESSURE", "SLIP", "TREAD", "QUANTITIES", "StateArrays",
           "StateResiduals", "state_problem", "state_priors", "free_parameters", "state_quantities", "StateEstimate",
           "estimate_state", "profile_rows", "channel_weights", "StateRevolutions", "state_revolutions",
           "StateFisher", "state_fisher", "state_of", "estimate_recording_state", "state_drift", "drifting_state",
           "estimate_stretches", "DRIFT_STRETCHES", "STRETCH_REVOLUTIONS", "DRIFT_SHARE", "DRIFT_Z"]
