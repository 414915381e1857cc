"""The load and contact patch from one profile (docs/physics.md §10; docs/formats.md §3 → §7).

:func:`estimate_load`: Ω from the sidecar, the load curves and the feature method for starting values,
then the engine on :func:`~ringfit.fit.estimate.problem.estimate_problem` in the profile block's noise passes
(:func:`~ringfit.fit.profile_block.fit_profile_block`: whitened per harmonic), and :class:`LoadEstimate` with the interval, the patch, the fit's quality
and its flags.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import equinox as eqx
import numpy as np
from scipy.special import ndtri

from ringfit.errors import InputError
from ringfit.fit.engine import GaussianPrior, least_squares, residuals
from ringfit.fit.estimate.curves import LoadCurves, load_curves
from ringfit.fit.estimate.feature import FeatureEstimate, _num, feature_estimate
from ringfit.fit.estimate.harmonics import band_signal, grid_signal, harmonic_amplitudes, amplitude_rows
from ringfit.fit.estimate.problem import (ANGLE_OFFSET, CORNER, GAIN, K_TREAD, LOAD, LOAD_RANGE, TILT, EstimateArrays,
                                          EstimateSettings, estimate_problem, nuisance_priors, optimum_ring_shift)
from ringfit.fit.profile_block import fit_profile_block
from ringfit.fit.result import FitResult, gauss_newton_step
from ringfit.params import BAR, RingParams, TyreGeometry, TyreLaws

if TYPE_CHECKING:
    from ringfit.io.tyre import RingCovariance
from ringfit.physics.operating import KMH
from ringfit.physics.profile import effective_rolling_radius, flat_or_drum

#: σ of ln k_trd used when the tyre file has no k_tread (a ±60 % range at 95 %): the *load estimate's* prior
#: (docs/physics.md §10, *k_trd held by default*). It differs from the other two k_trd σ on purpose: in one
#: profile the load and k_trd are ~99 % correlated, so the data cannot pin k_trd and this σ alone sets how wide
#: the load's interval is — it must be informative. The profile baseline's prior
#: (:data:`ringfit.gap.profile.K_TREAD_PRIOR_SD`, 1.0) can be weak because there every profile's load is stated
#: and the profiles determine k_trd; the loaded-table condition's σ
#: (:data:`ringfit.gap.modal_conditions.K_TREAD_PRIOR_SD`, 0.5) is no prior of a fit but the spread propagated
#: into a contact patch computed from the stated load.
DEFAULT_K_TREAD_SD = 0.3
#: An angle offset beyond this [deg] is flagged (the profile's zero is not the patch centre).
OFFSET_WARN_DEG = 10.0
#: A residual RMS above this multiple of the noise is flagged as a poor fit …
POOR_FIT_RATIO = 1.5
#: … when it is also above this fraction of the reading's RMS in the fitted band (the estimator's own
#: discretisation leaves ~0.1 %: noise-free profiles of the same model are not "poor").
MODEL_FLOOR = 0.005


@dataclass
class LoadEstimate:
    """An estimate of the load and the contact patch from one profile (docs/formats.md §7).

    - ``load_n``, ``lo``, ``hi``: the load and its 95 % interval [N]: the Laplace σ of ln(load) and
      the grid check's shift (``grid_check``) in quadrature.
    - ``patch``: ``length_mm``, ``leading_deg``, ``trailing_deg`` (docs/physics.md §4.4, φ from the
      vertical) of the model at the load, and ``length_lo_mm``/``length_hi_mm`` at the interval's ends.
    - ``rotation_hz``, ``rotation_source``: Ω/2π used and where it came from.
    - ``status``: the solver's status; ``converged``: solver converged, load inside its range and
      contact patch inside the solver window.
    - ``rms``, ``noise``, ``noise_source``: residual RMS and noise level in the fitted band [m/s²].
    - ``nuisances``: gain, angle offset [deg], corner [Hz], tilt, k_trd [N/m²] with standard errors.
    - ``feature``: the classic method (:class:`FeatureEstimate`); ``flags``: warnings.
    - ``fit``: the engine's :class:`~ringfit.fit.result.FitResult` (second pass); ``curves``: the
      :class:`LoadCurves`; ``angle_deg``, ``measured``, ``model``: the input's angles and the radial
      reading and model in the fitted band ``(N,)`` [m/s²] (for plots); ``k_max``: top harmonic fitted.
    - ``grid_check``: ``grid`` [M, 2M], ``load_shift_pct`` (the load's change when the grid is refined,
      :func:`grid_shift`), ``statistical_sd_pct`` and ``sd_pct`` (σ of ln load without and with it, in %);
      None when the check is off (``EstimateSettings.grid_check``).
    - ``ring_propagation``: the tyre's ``[ring.covariance]`` carried into the load (:func:`ring_propagation`):
      ``names``, ``sensitivity`` (∂ln load/∂ln θ per ring parameter), ``k_tread_prior_sd`` (σ of ln k_trd given
      the others, the prior of the fitted k_trd), ``load_sd_pct`` (the ring's part of σ of ln load, in %),
      ``sd_pct`` (σ of ln load with everything); None without a covariance.
    """

    load_n: float
    lo: float
    hi: float
    patch: dict
    rotation_hz: float
    rotation_source: str
    status: str
    converged: bool
    rms: float
    noise: float
    noise_source: str
    nuisances: dict
    feature: FeatureEstimate
    flags: list = field(default_factory=list)
    fit: FitResult | None = None
    curves: LoadCurves | None = None
    angle_deg: np.ndarray | None = None
    measured: np.ndarray | None = None
    model: np.ndarray | None = None
    k_max: int = 0
    omega: float = 0.0
    drum_diameter_m: float | None = None
    grid_check: dict | None = None
    ring_propagation: dict | None = None

    def to_record(self, input_name: str) -> dict:
        """The docs/formats.md §7 JSON object."""
        return {
            "input": str(input_name),
            "load_n": {"value": self.load_n, "lo": self.lo, "hi": self.hi},
            "patch": {k: _num(v) for k, v in self.patch.items()},
            "rotation_hz": {"value": self.rotation_hz, "source": self.rotation_source},
            "fit": {"status": self.status, "converged": self.converged, "rms": self.rms, "noise": self.noise,
                    "unit": "m/s^2", "noise_source": self.noise_source, "harmonics": [2, self.k_max],
                    "channel": "radial", "flags": list(self.flags),
                    **({"grid_check": self.grid_check} if self.grid_check is not None else {}),
                    **({"ring_propagation": self.ring_propagation} if self.ring_propagation is not None else {})},
            "nuisances": self.nuisances,
            "feature_method": self.feature.to_record(),
        }


def rotation_from_profile(profile, geometry: TyreGeometry, ring: RingParams, load_guess: float,
                          settings: EstimateSettings = EstimateSettings()) -> tuple[float, str, list[str]]:
    """Ω [rad/s], its source and warnings for a profile (docs/formats.md §3).

    ``rotation_hz`` (the rim encoder) when the sidecar has it; else ``speed_kmh/R_e`` with
    R_e = R_out − δ/3 at ``load_guess`` — with a warning: the speed is nominal, and the load
    does not depend on it (the free gain absorbs Ω²), only the fitted high-pass corner does.
    """
    if profile.rotation_hz is not None:
        return 2 * math.pi * profile.rotation_hz, "sidecar rotation_hz (rim encoder)", []
    speed = profile.condition.get("speed_kmh")
    if speed is None or not speed > 0:
        raise InputError("no rotation_hz and no positive speed_kmh in the sidecar: Ω unknown", source=profile.source)
    r_e = effective_rolling_radius(ring, geometry, load_guess, profile.drum_diameter_m,
                                   solver=settings.solver)
    omega = speed * KMH / r_e
    msg = (f"WARNING: no rotation_hz in {profile.source or 'the sidecar'}: Ω = speed_kmh/R_e = {omega:.4g} rad/s from "
           f"the nominal speed {speed:g} km/h (R_e = {r_e:.4f} m at {load_guess:.0f} N). The load does not rest on it "
           "(the gain absorbs Ω²); the reported rotation rate and high-pass corner do.")
    return omega, f"speed_kmh / R_e (nominal speed, R_e = {r_e:.4f} m)", [msg]


def _geometry_at_pressure(geometry: TyreGeometry, profile, ring: RingParams | None = None, laws=None):
    """The geometry at the profile's pressure (with a warning when it differs from the tyre file's by > 5 %).

    With ``laws`` that scale the ring with pressure (:class:`~ringfit.params.TyreLaws`, docs/physics.md §13.1) the
    ring and geometry are carried to the stated pressure by them, without a warning. **Returns**
    ``(geometry, notes)``, or ``(geometry, ring, notes)`` when ``ring`` is given."""
    notes = []
    pb = profile.condition.get("pressure_bar")
    if pb is not None and laws is not None and laws.has_pressure_law:
        from ringfit.physics.state import state_tyre

        geometry, ring, _ = state_tyre(geometry, ring, laws, pb * BAR, laws.tread_depth_ref)
        geometry = TyreGeometry(float(geometry.radius), float(geometry.width), float(geometry.pressure),
                                float(geometry.tread_thickness), geometry.tread_rib_width, name=geometry.name)
        ring = RingParams(**{k: float(v) for k, v in ring.as_dict().items()})
        return geometry, ring, notes
    if pb is not None:
        tyre_bar = float(geometry.pressure) / BAR
        if abs(pb - tyre_bar) > 0.05 * tyre_bar:
            notes.append(f"WARNING: the profile's pressure_bar = {pb:g} differs from the tyre file's {tyre_bar:g} bar "
                         "by more than 5 %; the model uses the profile's pressure with the tyre file's ring")
        geometry = TyreGeometry(geometry.radius, geometry.width, pb * BAR, geometry.tread_thickness,
                                geometry.tread_rib_width, name=geometry.name)
    return (geometry, notes) if ring is None else (geometry, ring, notes)


def check_sign(amplitudes, curves: LoadCurves, source) -> None:
    """Refuse a radial reading that is the model turned upside down (positive outward, docs/formats.md §3).

    The circular cross-correlation of the measured and the model reading (4 kN, harmonics 2…k_max) is
    largest in magnitude at the patch's shift; a negative value there means the sign convention is
    inverted. **Raises** :class:`InputError` naming ``source``.
    """
    model = curves.amplitudes[int(np.argmin(np.abs(np.log(curves.load_n / 4000.0))))]
    xcorr = grid_signal(np.asarray(amplitudes) * np.conj(model), 2, 1024)
    peak = xcorr[int(np.argmax(np.abs(xcorr)))]
    if peak < 0:
        raise InputError("the radial reading looks inverted (the contact patch shows as a peak): docs/formats.md §3 "
                         "wants acc_radial_ms2 positive toward the wheel centre", source=source or None)


def band_top(n_angles: int, settings: EstimateSettings) -> int:
    """The top harmonic an estimate fits: ``settings.k_max``, below what ``n_angles`` angles resolve ((N − 1)/2 − 1)
    and the model grid's Nyquist (M/2 − 2)."""
    return int(min(settings.k_max, (int(n_angles) - 1) // 2 - 1, settings.n_grid // 2 - 2))


def profile_amplitudes(profile, n_grid: int, k_max: int) -> np.ndarray:
    """Radial harmonic amplitudes ``(K,)`` (k = 2…k_max) of a profile (band-limited, trapezoid weights)."""
    from ringfit.io.profiles import resample_profile

    grid = resample_profile(profile, n_grid)[0]
    return harmonic_amplitudes(grid, 2, k_max)


def estimate_load(profile, geometry: TyreGeometry, ring: RingParams, *, settings: EstimateSettings = EstimateSettings(),
                  k_tread_in_file: bool = True, omega: float | None = None, omega_source: str | None = None,
                  noise_per_angle: np.ndarray | None = None, noise_source: str | None = None,
                  response: np.ndarray | None = None, ring_covariance=None, laws=None) -> LoadEstimate:
    """Estimate the load and contact patch from one rolling profile (docs/formats.md §3 → §7).

    **Arguments:**

    - ``profile``: a :class:`~ringfit.io.profiles.Profile` (its ``load_n`` is not used); radial
      channel, angles from the patch centre; ``rotation_hz``/``speed_kmh``, ``drum_diameter_m``,
      ``pressure_bar`` from its sidecar.
    - ``geometry``, ``ring``: the fitted tyre (fixed).
    - ``settings``: :class:`EstimateSettings`; ``k_tread_in_file``: whether the tyre file gave k_trd
      (if not, it gets the prior :data:`DEFAULT_K_TREAD_SD` unless the settings set one).
    - ``omega``, ``omega_source``: Ω [rad/s] and its source, when known from elsewhere (a recording).
    - ``noise_per_angle``: ``(N,)`` standard error of the profile per angle [m/s²] (e.g. the
      revolution spread / √revolutions), used for the reported noise (``noise_source`` says what it
      is); default: the spread columns of a ``ringfit profile`` output, else the residual away from
      the patch.
    - ``response``: ``(k_max − 1,)`` the acquisition's gain on harmonics 2…k_max (default 1).
    - ``ring_covariance``: the tyre file's :class:`~ringfit.io.tyre.RingCovariance` (ln θ, docs/formats.md §1.1):
      propagated into the load's interval (:func:`ring_propagation`, docs/physics.md §10). Its k_trd part
      frees k_trd with the prior σ of ln k_trd *given* the other ring parameters (unless ``settings.k_tread_sd``
      is set, which wins); the other parameters enter through the estimate's sensitivities.
    - ``laws``: the tyre file's state laws (:class:`~ringfit.params.TyreLaws`): with a pressure law, a profile at
      another stated pressure is read with the ring carried there (docs/physics.md §13.1), without a warning.

    **Returns:** :class:`LoadEstimate`. Never raises on non-convergence (check ``converged``).
    """
    geometry, ring, flags = _geometry_at_pressure(geometry, profile, ring, laws)
    N = len(profile)
    k_max = band_top(N, settings)
    if k_max < 8:
        raise InputError(f"{N} angles resolve harmonics up to {(N - 1) // 2}; the estimate needs at least 8",
                         source=profile.source)
    amp = profile_amplitudes(profile, settings.n_grid, k_max)
    resp = np.ones(k_max - 1) if response is None else np.asarray(response, dtype=np.float64)[: k_max - 1]
    drum = profile.drum_diameter_m
    # Ω (its uncertainty hardly matters: the gain absorbs Ω²) and the model curves
    if omega is None:
        omega, omega_source, notes = rotation_from_profile(profile, geometry, ring, 4000.0, settings)
        flags += notes
    curves = load_curves(geometry, ring, omega, drum, settings=settings, k_max=k_max)
    check_sign(amp, curves, profile.source)
    feature = feature_estimate(amp, curves, float(geometry.outer_radius))

    # starting values: the feature method's load and patch position, the gain from the load curve's reading
    load0 = feature.load_n if math.isfinite(feature.load_n) else 4000.0
    offset0 = 0.0
    if math.isfinite(feature.leading_deg) and math.isfinite(feature.trailing_deg):
        # φ = α + offset: the model's peak midpoint at the start load minus the data's
        model_mid = float(curves._interp(curves.peak_mid_deg, load0))
        offset0 = math.radians(model_mid - 0.5 * (feature.leading_deg + feature.trailing_deg))
    sd = settings.k_tread_sd
    spread = ring_spread(ring_covariance, use_k_tread=sd is None)
    if spread is not None and spread["k_tread_sd"] is not None:
        sd = spread["k_tread_sd"]
    if sd is None and not k_tread_in_file:
        sd = DEFAULT_K_TREAD_SD
        flags.append(f"WARNING: the tyre file has no k_tread_n_per_m2: the model uses {float(ring.k_tread):.3g} N/m² "
                     f"with a ±{100 * sd:.0f} % (1σ) prior, propagated into the load's interval; the load and k_trd "
                     "are ~99 % correlated in a profile, so this interval is wide")
    free = [LOAD, GAIN, ANGLE_OFFSET, CORNER, TILT]
    entries = nuisance_priors()
    if sd is not None and sd > 0:
        entries[K_TREAD] = (math.log(float(ring.k_tread)), float(sd))
        free.append(K_TREAD)
    prior = GaussianPrior.independent(entries)
    K = amp.shape[-1]
    measured = amplitude_rows(amp)[None]
    arrays = EstimateArrays(geometry=geometry, ring=ring, omega=np.array([omega]), roads=flat_or_drum(drum, 1),
                            response=resp[None], measured=measured, weight=np.ones((1, 2 * K)))
    theta0 = np.array([load0, curves.gain_at(load0, amp), offset0, 0.3, 0.5, float(ring.k_tread)])
    state = dict(theta=theta0)

    def fit_at(sigma):  # one pass of the profile block's noise passes, warm-started from the last converged one
        weighted = eqx.tree_at(lambda a: a.weight, arrays, 1.0 / sigma)
        fit = least_squares(estimate_problem(weighted, settings, k_max, prior, sigma="fixed"), state["theta"],
                            tuple(free), max_steps=settings.max_steps, rtol=settings.rtol, atol=settings.atol)
        if fit.converged:
            state["theta"] = fit.theta.copy()
        return fit

    # the profile block's noise model (docs/physics.md §11 *profiles*): σ per harmonic from the residual's
    # spectrum, refitted; the first σ (a tenth of the rows' RMS, every row alike) only starts it
    sigma0 = np.full_like(measured, 0.1 * max(float(np.sqrt(np.mean(measured**2))), 1e-300))
    fit, _, _ = fit_profile_block(fit_at, sigma0, k_min=2)
    finite = bool(np.all(np.isfinite(fit.theta)))
    shift = grid_shift(fit, settings) if settings.grid_check and finite else None
    propagated = ring_propagation(fit, ring, spread) if spread is not None and spread["names"] and finite else None
    return _finish(fit, profile, curves, feature, amp, omega, omega_source, flags, k_max, drum, settings,
                   noise_per_angle, noise_source, shift, propagated)


def ring_spread(covariance, use_k_tread: bool = True) -> dict | None:
    """How the tyre's ``[ring.covariance]`` enters an estimate (docs/physics.md §10, *the tyre's uncertainty*).

    Splits ln θ into k_trd (fitted by the estimate with a prior) and the rest q (propagated):
    ``k_tread_sd`` = σ of ln k_trd given q, √(Σ_kk − Σ_kq Σ_qq⁻¹ Σ_qk), and ``shift`` = Σ_qq⁻¹ Σ_qk, how the
    prior's mean moves with q. Without k_trd in the covariance (or ``use_k_tread`` false: a σ given by the
    user wins), ``k_tread_sd`` is None and ``shift`` zero. **Returns** ``dict(names, cov, k_tread_sd, shift)``
    or None without a covariance.
    """
    if covariance is None:
        return None
    fields = {f.name for f in dataclasses.fields(RingParams)}
    names = [n for n in covariance.names if n in fields and n != K_TREAD]
    idx = [covariance.names.index(n) for n in names]
    cov = np.asarray(covariance.ln, dtype=np.float64)
    cqq = cov[np.ix_(idx, idx)]
    out = dict(names=tuple(names), cov=cqq, k_tread_sd=None, shift=np.zeros(len(names)))
    if use_k_tread and K_TREAD in covariance.names:
        k = covariance.names.index(K_TREAD)
        ckq = cov[k, idx]
        shift = np.linalg.lstsq(cqq, ckq, rcond=None)[0] if names else np.zeros(0)  # Σ_qq⁻¹ Σ_qk (Σ_qq symmetric)
        out["k_tread_sd"] = math.sqrt(max(float(cov[k, k] - ckq @ shift), 1e-24))
        out["shift"] = shift
    return out


def ring_propagation(fit: FitResult, ring: RingParams, spread: dict) -> dict:
    """The ring parameters' uncertainty carried into ln(load) by linear propagation (docs/physics.md §10).

    The fit's optimum û moves with a ring parameter q_j (held fixed in the fit) by
    ``∂û/∂ln q = −(JᵀJ)⁻¹ Jᵀ ∂r/∂ln q`` (J the Jacobian of the rows the fit minimised, its prior rows
    included, ∂r/∂ln q the engine's Jacobian of the same rows in ln q, :func:`ringfit.fit.engine.linearize`),
    and with the k_trd prior's mean μ by ``∂û/∂μ = (JᵀJ)⁻¹ e_k / σ_k²``; the prior's mean moves with q by
    ``spread["shift"]`` (:func:`ring_spread`). With g = ∂ln load/∂ln q in total, the ring adds ``gᵀ Σ_qq g`` to
    the variance of ln(load). The rows are those the solver minimised (weights of mean 1, not divided by the
    fitted σ scale s), so g is the estimator's own sensitivity. **Returns** ``dict(names, sensitivity,
    k_tread_prior_sd, load_sd_pct)``.
    """
    names = tuple(spread["names"])
    du_dq, cov = optimum_ring_shift(fit, ring, names)
    iL = list(fit.names).index(LOAD)
    g = du_dq[iL]
    if K_TREAD in fit.names and spread["k_tread_sd"] is not None:
        ik = list(fit.names).index(K_TREAD)
        g = g + cov[iL, ik] / spread["k_tread_sd"] ** 2 * spread["shift"]
    var = float(g @ spread["cov"] @ g)
    return dict(names=list(names), sensitivity={n: float(x) for n, x in zip(names, g)},
                k_tread_prior_sd=spread["k_tread_sd"], load_sd_pct=100.0 * math.sqrt(max(var, 0.0)))


def grid_shift(fit: FitResult, settings: EstimateSettings, factor: int = 2) -> float:
    """The change of ln(load) when the model's grid M is refined to ``factor``·M at the fit (docs/physics.md §10).

    The contact solve's discrete active set makes the load–shape relation a fine staircase (up to ~0.2 %
    at light loads for M = 512, where the patch spans few grid points). One Gauss–Newton step from the
    fit, with its Jacobian (prior rows included, σ scale as fitted), on the residual rows of the same data
    and weights under the refined model estimates how far the optimum moves: ``δu = −J⁺ Δr``. Against
    an independent finite-difference truth this shift predicts the M = 512 estimate's error to within
    ~0.07 % (``experiments/light_load_bias.py refine``). One residual evaluation at ``factor``·M.
    """
    coarse = fit.problem
    fine = estimate_problem(coarse.data, dataclasses.replace(settings, n_grid=factor * settings.n_grid),
                            coarse.model.k_max, coarse.prior)
    return float(grid_step(fit, fine)[list(fit.names).index(LOAD)])


def grid_step(fit: FitResult, fine) -> np.ndarray:
    """One Gauss–Newton step ``δu = −J⁺ Δr`` (the free parameters' solver coordinates) from ``fit`` to the optimum of
    the ``fine`` problem — the same data and weights under a refined model: ``Δr`` the rows' change at the fit (σ
    scale as fitted; the prior's rows unchanged), ``J`` the fit's Jacobian (docs/physics.md §10, §13.4)."""
    r_fine, _ = residuals(fine, fit.theta)
    return gauss_newton_step(fit, np.asarray(r_fine)[:fit.residuals.size] / float(fit.extra["sigma_scale"]) - fit.residuals)


def _finish(fit, profile, curves, feature, amp, omega, omega_source, flags, k_max, drum, settings,
            noise_per_angle, noise_source=None, shift=None, propagated=None) -> LoadEstimate:
    """The :class:`LoadEstimate` of a fit: interval, patch, fit quality, flags, nuisances.

    ``shift``: :func:`grid_shift` (ln load), and ``propagated`` (:func:`ring_propagation`), the ring's part of
    σ of ln(load), added in quadrature to the Laplace σ of ln(load).
    """
    load = fit.values[LOAD]
    lo, hi = fit.interval(LOAD)
    z = float(ndtri(0.975))
    s_stat = math.log(hi / lo) / (2 * z)
    grid = None
    s = s_stat
    if shift is not None and math.isfinite(shift):
        s = math.hypot(s_stat, shift)
        grid = {"grid": [settings.n_grid, 2 * settings.n_grid], "load_shift_pct": 100 * math.expm1(shift),
                "statistical_sd_pct": 100 * s_stat, "sd_pct": 100 * s}
    if propagated is not None and math.isfinite(propagated["load_sd_pct"]):
        s = math.hypot(s, propagated["load_sd_pct"] / 100.0)
        propagated = dict(propagated, sd_pct=100 * s)
    if s != s_stat:
        lo, hi = load * math.exp(-z * s), load * math.exp(z * s)
    model_rows = np.asarray(fit.extra["aux"])[0]
    K = amp.shape[-1]
    model_amp = model_rows[:K] + 1j * model_rows[K:]
    resid_amp = amp - model_amp
    alpha = np.radians(profile.angle_deg)
    offset_deg = math.degrees(fit.values[ANGLE_OFFSET])
    # fit quality in the fitted band: RMS over the revolution (Parseval), noise level
    rms = float(np.sqrt(0.5 * np.sum(np.abs(resid_amp) ** 2)))
    N = len(profile)
    if noise_per_angle is None:
        noise_per_angle = _spread_noise(profile)
    if noise_per_angle is not None:
        noise = float(np.sqrt(np.mean(np.asarray(noise_per_angle) ** 2) * 2 * K / N))
        noise_source = noise_source or "revolution spread / √revolutions, in the fitted band"
    else:
        resid = band_signal(resid_amp, 2, alpha)
        far = np.abs((profile.angle_deg + offset_deg + 180.0) % 360.0 - 180.0) > 60.0
        noise = float(np.sqrt(np.mean(resid[far] ** 2))) if far.any() else rms
        noise_source = "residual RMS away from the patch (|φ| > 60°)"
    sol_ok = bool(np.all(curves.ok[(curves.load_n >= 0.8 * lo) & (curves.load_n <= 1.25 * hi)]))
    at_bound = LOAD in fit.extra["at_bound"] or not (
        LOAD_RANGE[0] * 1.001 < load < LOAD_RANGE[1] * 0.999)
    converged = fit.converged and not at_bound and sol_ok
    flags = list(flags)
    for f in fit.flags:
        if f.startswith(LOAD) or f.startswith(K_TREAD) or "solver did not converge" in f:
            flags.append(f)
    if not sol_ok:
        flags.append(f"the contact patch at {load:.0f} N does not fit inside the ±{settings.window_deg:g}° solver window")
    if abs(offset_deg) > OFFSET_WARN_DEG:
        flags.append(f"the profile's angle zero is {offset_deg:+.1f}° from the patch centre (angle offset); "
                     "check the encoder offset or the angle convention (docs/formats.md §3)")
    signal_rms = float(np.sqrt(0.5 * np.sum(np.abs(amp) ** 2)))
    if rms > POOR_FIT_RATIO * noise and rms > MODEL_FLOOR * signal_rms:
        flags.append(f"poor fit: residual RMS {rms:.3g} m/s² is {rms / max(noise, 1e-300):.1f}× the noise level "
                     f"({noise:.3g} m/s²): the model does not explain this profile to its noise; the load may be "
                     "biased beyond its interval")
    patch = curves.patch_at(load)
    patch_lo, patch_hi = curves.patch_at(lo), curves.patch_at(hi)
    patch = {"length_mm": float(patch["length_mm"]), "leading_deg": float(patch["leading_deg"]),
             "trailing_deg": float(patch["trailing_deg"]), "length_lo_mm": float(patch_lo["length_mm"]),
             "length_hi_mm": float(patch_hi["length_mm"])}
    nuisances = {}
    for name, key, scale in ((GAIN, "gain", 1.0), (ANGLE_OFFSET, "angle_offset_deg", 180 / math.pi),
                             (CORNER, "corner_hz", 1.0), (TILT, "tilt_gain", 1.0), (K_TREAD, "k_tread_n_per_m2", 1.0)):
        value = fit.values[name] * scale
        entry = {"value": value, "free": name in fit.names}
        if name in fit.names:
            entry["stderr"] = _num(fit.stderr[name] * scale)
        nuisances[key] = entry
    if CORNER in fit.names and fit.values[CORNER] < 0.01:
        nuisances["corner_hz"]["note"] = "below 0.01 Hz: no high-pass resolved"
    return LoadEstimate(
        load_n=float(load), lo=float(lo), hi=float(hi), patch=patch, rotation_hz=omega / (2 * math.pi),
        rotation_source=str(omega_source), status=fit.status, converged=bool(converged), rms=rms, noise=noise,
        noise_source=noise_source, nuisances=nuisances, feature=feature, flags=flags, fit=fit, curves=curves,
        angle_deg=profile.angle_deg, measured=band_signal(amp, 2, alpha), model=band_signal(model_amp, 2, alpha),
        k_max=k_max, omega=float(omega), drum_diameter_m=drum, grid_check=grid, ring_propagation=propagated)


def _spread_noise(profile) -> np.ndarray | None:
    """Standard error per angle of a ``ringfit profile`` output (spread / √revolutions), or None."""
    col = profile.extra.get("acc_radial_spread_ms2")
    revs = profile.condition.get("revolutions")
    if col is None or not revs or revs < 2:
        return None
    try:
        spread = np.array([float(x) for x in col])
    except ValueError:
        return None
    if not np.all(np.isfinite(spread)):
        return None
    return spread / math.sqrt(float(revs))


def stated_load_check(profiles, geometry: TyreGeometry, ring: RingParams, *, laws: TyreLaws | None = None,
                       covariance: RingCovariance | None = None) -> list[str]:
    """What each free-rolling profile's own reading says of its stated ``load_n`` (one sentence per contradiction).

    ``ringfit identify`` fits every profile at its stated load (:func:`ringfit.fit.identify.identify`). A profile
    whose sidecar states the wrong load is then absorbed by the profile block's σ scale and the other parameters,
    without a word. So the command reads each profile without a stated torque by :func:`estimate_load` with the
    identified tyre (the identified ``covariance`` carried into its interval; across states ``laws`` reads the
    profile at its stated pressure), and its stated load is compared with that reading as ``ringfit estimate``
    compares a stated condition (:func:`ringfit.io.conditions.stated_against_estimate`: beyond 3.29 σ of the
    interval's half on its side). A profile the estimate could not read converged is not judged (said so)."""
    from ringfit.io.conditions import stated_against_estimate

    notes = []
    for prof in profiles:
        cond = dict(prof.condition or {})
        if cond.get("load_n") is None or float(cond.get("torque_nm") or 0.0) != 0.0:
            continue
        name = Path(str(prof.source)).name if prof.source else "a profile"
        try:
            est = estimate_load(prof, geometry, ring, laws=laws, ring_covariance=covariance)
        except InputError as exc:
            notes.append(f"{name}: its stated load_n was not checked: the load estimate refused it ({exc})")
            continue
        if not est.converged:
            notes.append(f"{name}: its stated load_n was not checked: the load estimate did not converge "
                         f"({est.status})")
            continue
        for row in stated_against_estimate({"load_n": {"value": est.load_n, "lo": est.lo, "hi": est.hi}}, cond,
                                           source=prof.source):
            if not row["consistent"]:
                notes.append(row["sentence"].rsplit(": check", 1)[0] + " with the identified tyre: check its "
                             "sidecar (identify fits each profile at its stated load)")
    return notes
