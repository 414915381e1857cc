"""The profile block: a rolling profile's rows, its per-run nuisances and its noise model, once for every fit
that reads profiles (docs/physics.md §11 "profiles").

``ringfit identify`` (:mod:`ringfit.fit.identify`) and the diagnosis's profile baseline and candidates
(:mod:`ringfit.gap.profile`) both compose this block, so the same profile is read the same way by both:

- **rows**: :func:`profile_rows` — each ``*.profile.csv`` band-limited and resampled onto the model grid
  (:func:`rolling_data`), Ω from the sidecar's ``rotation_hz`` else V/R_e;
  :func:`harmonic_rows` turns channels into revolution-harmonic rows (real then imaginary parts), from the one
  transform :func:`harmonic_amplitudes` that the load and state estimates use too;
- **nuisances**: per profile an angle offset (linear, ±:data:`OFFSET_BOUND`) and a gain on the reading
  (log, in :data:`GAIN_RANGE`; the sensor's sensitivity and its offset from the belt), named by
  :func:`nuisance_names`, solved in :func:`nuisance_coords`, applied to the model's channels by
  :func:`read_through`. The runs share one sensor: :func:`nuisance_prior` holds the gains to a common gain
  (log sd :data:`GAIN_COMMON_SD`) with each run's own deviation of log sd :data:`GAIN_SPREAD` (a sensitivity's
  drift with the liner's temperature over a session), and the angle offsets to a common offset with each
  run's own of sd :data:`OFFSET_SPREAD` — so a run's amplitude and angle are evidence, not free scales;
- **noise**: per profile, channel and harmonic, from the residual's spectrum (:func:`noise_spectrum`: a
  power law, then the ratio averaged over the ±:data:`NOISE_SMOOTHING` neighbouring harmonics with each
  harmonic's own residual left out), widened by ν/(ν − 4) for weights estimated from ν parts and by the
  degrees of freedom the fit took (:func:`noise_from_residual`).

Example::

    rows = profile_rows(profiles, geometry, ring, solver)
    model = harmonic_rows(read_through(channels, offset, gain), k_top=rows["k_top"])
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ringfit.errors import InputError
from ringfit.fit.engine import DECREMENT_TOL, LINEAR, LOG, Coordinate, GaussianPrior
from ringfit.io.profiles import resample_profile
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver
from ringfit.physics.profile import ProfileModel, effective_rolling_radius
from ringfit.physics.rolling import RingModel
from ringfit.physics.sensor import SensorModel, shift_angle

#: Harmonics averaged on either side for a profile's noise spectrum.
NOISE_SMOOTHING = 4
#: Lowest revolution harmonic of a profile used (k = 1 carries gravity and the sensor's tilt; k = 0 is removed).
PROFILE_K_MIN = 2
#: Bounds of a profile's gain on the reading (sensor sensitivity, its offset from the belt).
GAIN_RANGE = (0.5, 2.0)
#: sd of a run's log gain about the session's common gain: one sensor, glued once, whose sensitivity drifts
#: with the liner's temperature (piezoelectric sensitivity ~0.05–0.1 %/K over the 20–40 K a drum session's
#: speeds heat the liner: 1–4 %) — docs/physics.md §11 "profiles".
GAIN_SPREAD = 0.03
#: sd of the common gain's log about 1 (the stated sensitivity): wide, the sensor's offset from the belt and its
#: calibration are not known to better than tens of per cent.
GAIN_COMMON_SD = 0.5
#: sd of a run's angle offset about the session's common offset [rad]: one sensor on one wheel, whose angle
#: origin (encoder zero or once-per-revolution trigger) moves between runs only by the trigger's latency × Ω
#: and the processing's jitter — docs/physics.md §11 "profiles".
OFFSET_SPREAD = math.radians(0.5)
#: Bound of a profile's angle offset [rad], and its solver scale.
OFFSET_BOUND = math.radians(10.0)
OFFSET_SCALE = math.radians(1.0)
#: Harmonics kept below the coarsest profile's Nyquist harmonic (its resampling's edge).
PROFILE_BAND_MARGIN = 8
#: The top revolution harmonic identify compares, as the state estimate (docs/physics.md §13.4 *the harmonic band*,
#: §11 *profiles*): above it the model's form error — its grid, the brush's discretisation — outweighs what the
#: harmonics tell (identify on the state example's calibration: the profiles' discrepancy ratio 28 on 2…255 against
#: 4.5 on 2…80, the damping +50 % against +3 %).
PROFILE_K_MAX = 80
#: Weak priors on the sensor's own nuisances (natural units; docs/physics.md §13.4, §11 *profiles*), the same for
#: every reader of a profile (the load and state estimates, identify): the IEPE high-pass corner's median [Hz] and
#: σ of its logarithm (0.005–16 Hz at 2σ; below ~0.01 Hz it has no effect on harmonics k ≥ 2), the tilt gain's
#: mean and σ (γ ∈ 0–1.1 with gravity, 0 without, docs/physics.md §6), σ of the log of the tangential axis's gain
#: relative to the radial one, and the liner offset e's mean and σ [m] (§5 layer 1).
CORNER_PRIOR = (0.3, 2.0)
TILT_PRIOR = (0.5, 0.5)
#: The corner's range in identify [Hz]: below 0.01 Hz it changes no harmonic k ≥ 2 of a rolling tyre (its
#: direction is flat, and a fit that follows it down does not converge), above 10 Hz it is no IEPE coupling.
CORNER_RANGE = (0.01, 10.0)
GAIN_TANGENTIAL_PRIOR_SD = 0.05
LINER_OFFSET_PRIOR = (1.0e-3, 3.0e-3)
#: Per run, the sensor's own nuisances that identify fits beside the gain and angle offset (θ order per run):
#: tilt gain γ, the high-pass corner f_c [Hz], the liner offset e [m] and the tangential axis's gain g_t/g_r.
SENSOR_FIELDS = ("tilt_gain", "corner_hz", "liner_offset_m", "gain_tangential")
#: The liner offset's step in :func:`sensor_reading`'s bilinear basis [m] (the reading is exactly bilinear in
#: (e, γ): any step gives the same basis up to round-off).
LINER_BASIS_STEP = 1.0e-3


def decrement_tol(sensor: bool) -> float:
    """The engine's decrement stop (``least_squares(dtol=…)``) for a fit of profiles: :data:`~ringfit.fit.engine.
    DECREMENT_TOL` when the runs' sensor nuisances are fitted (they converge only linearly), else 0 (the Cauchy test
    alone, as every other fit) — docs/physics.md §11 *convergence*; one rule for fit-rolling and identify."""
    return DECREMENT_TOL if sensor else 0.0


def nuisance_names(P: int) -> tuple[str, ...]:
    """Names of the per-profile nuisances of ``P`` profiles: ``angle_offset_i`` and ``gain_i`` (i = 1 … P)."""
    return tuple(n for i in range(P) for n in (f"angle_offset_{i + 1}", f"gain_{i + 1}"))


def nuisance_coords(P: int) -> tuple[Coordinate, ...]:
    """The solver coordinates of :func:`nuisance_names`: each angle offset linear (scale 1°, bounded by
    :data:`OFFSET_BOUND`), each gain log (bounded by :data:`GAIN_RANGE`)."""
    out = []
    for i in range(P):
        out.append(Coordinate(f"angle_offset_{i + 1}", LINEAR, scale=OFFSET_SCALE, lo=-OFFSET_BOUND, hi=OFFSET_BOUND))
        out.append(Coordinate(f"gain_{i + 1}", LOG, lo=GAIN_RANGE[0], hi=GAIN_RANGE[1]))
    return tuple(out)


def nuisance_prior_cov(P: int) -> np.ndarray:
    """Covariance ``(2P, 2P)`` of the nuisances (:func:`nuisance_names` order; angle offsets in rad, gains in
    log): per kind a common part shared by every run plus each run's own deviation, ``c²·11ᵀ + s²·I`` — offsets
    c = :data:`OFFSET_BOUND`, s = :data:`OFFSET_SPREAD`; log gains c = :data:`GAIN_COMMON_SD`, s =
    :data:`GAIN_SPREAD`. The runs share one sensor: a run's amplitude and angle are evidence, not free scales."""
    cov = np.zeros((2 * P, 2 * P))
    for k, (c, s) in enumerate(((OFFSET_BOUND, OFFSET_SPREAD), (GAIN_COMMON_SD, GAIN_SPREAD))):
        cov[k::2, k::2] = c**2 * np.ones((P, P)) + s**2 * np.eye(P)
    return cov


def nuisance_prior(P: int) -> GaussianPrior | None:
    """The engine's prior on the ``P`` runs' nuisances in their solver coordinates (:func:`nuisance_coords`:
    offset/:data:`OFFSET_SCALE`, ln gain), mean 0 (no offset, the stated sensitivity), covariance
    :func:`nuisance_prior_cov`; ``None`` for no profile."""
    if P <= 0:
        return None
    d = np.tile([OFFSET_SCALE, 1.0], P)
    return GaussianPrior(nuisance_names(P), np.zeros(2 * P), nuisance_prior_cov(P) / np.outer(d, d))


def nuisance_start(P: int) -> np.ndarray:
    """The nuisances' start ``(2P,)``: no offset, unit gain."""
    return np.tile([0.0, 1.0], P)


def sensor_names(P: int) -> tuple[str, ...]:
    """Names of the ``P`` runs' sensor nuisances (:data:`SENSOR_FIELDS`, ``tilt_gain_i`` … per run i = 1 … P)."""
    return tuple(f"{f}_{i + 1}" for i in range(P) for f in SENSOR_FIELDS)


#: Per sensor field (:data:`SENSOR_FIELDS`): its solver coordinate's kind, scale and range, and its prior's mean
#: (natural units: the start too) and σ (of the value for a linear coordinate, of its log for a log one). Below
#: CORNER_RANGE[0] a corner has no effect on harmonics k ≥ 2.
_SENSOR_TABLE = {
    "tilt_gain": (LINEAR, 0.1, (-math.inf, math.inf), TILT_PRIOR[0], TILT_PRIOR[1]),
    "corner_hz": (LOG, 1.0, CORNER_RANGE, CORNER_PRIOR[0], CORNER_PRIOR[1]),
    "liner_offset_m": (LINEAR, 1e-3, (-math.inf, math.inf), LINER_OFFSET_PRIOR[0], LINER_OFFSET_PRIOR[1]),
    "gain_tangential": (LOG, 1.0, GAIN_RANGE, 1.0, GAIN_TANGENTIAL_PRIOR_SD),
}


def sensor_coordinate(field: str, *, bounded: bool = True) -> Coordinate:
    """The solver coordinate of one sensor nuisance ``field`` (:data:`SENSOR_FIELDS`), named ``field``: γ linear
    (scale 0.1), f_c log within :data:`CORNER_RANGE`, e linear (scale 1 mm), g_t/g_r log within :data:`GAIN_RANGE`.
    ``bounded=False`` leaves the corner's log coordinate without its range: the per-revolution readers (the load and
    state estimates) solve in batches that have no active set, where a corner creeping to 0.01 Hz would end a
    revolution's fit unconverged; identify holds it there (docs/physics.md §11 *bounds*)."""
    kind, scale, (lo, hi), _, _ = _SENSOR_TABLE[field]
    if not bounded:
        lo, hi = -math.inf, math.inf
    return Coordinate(field, kind, scale=scale, lo=lo, hi=hi)


def sensor_prior_entry(coord: Coordinate, field: str) -> tuple[float, float]:
    """``(mean, sd)`` of the prior on sensor nuisance ``field`` in ``coord``'s solver coordinate (ln for a log one,
    (θ − center)/scale for a linear one): the one prior every reader of a profile puts on it."""
    mean, sd = _SENSOR_TABLE[field][3:]
    if coord.kind == LOG:
        return math.log(mean), sd
    return (mean - coord.center) / coord.scale, sd / coord.scale


def sensor_coords(P: int) -> tuple[Coordinate, ...]:
    """Solver coordinates of :func:`sensor_names` (:func:`sensor_coordinate` of each field, per run)."""
    return tuple(dataclasses.replace(sensor_coordinate(f), name=f"{f}_{i + 1}")
                 for i in range(P) for f in SENSOR_FIELDS)


def sensor_start(P: int) -> np.ndarray:
    """θ of the sensor nuisances at their priors' centres ``(4P,)`` (natural units)."""
    return np.tile([_SENSOR_TABLE[f][3] for f in SENSOR_FIELDS], P)


def sensor_prior(P: int) -> GaussianPrior | None:
    """The engine's prior on the runs' sensor nuisances in their solver coordinates: each run's own, independent,
    the priors above (a run may be a remounted sensor: nothing tied across runs). ``None`` for no profile."""
    if P == 0:
        return None
    return GaussianPrior.independent({coord.name: sensor_prior_entry(coord, f)
                                      for coord, f in zip(sensor_coords(P), SENSOR_FIELDS * P)})


def sensor_basis(solution, geometry: TyreGeometry, sensor: SensorModel) -> jax.Array:
    """The sensor's reading of one rolling ``solution`` as a bilinear basis in the liner offset e and the tilt gain
    γ, ``(4, 2, M)``: the reading at (0, 0), (:data:`LINER_BASIS_STEP`, 0), (0, 1) and (step, 1), the rest of
    ``sensor`` as given (docs/physics.md §5 layers 1 and 4: v_s = v + eψ, the axes turned by γψ; the reading is
    exactly bilinear in (e, γ) once its per-revolution mean is removed). :func:`sensor_reading` combines it."""

    from ringfit.physics.sensor import sensor_signals

    out = []
    for e, g in ((0.0, 0.0), (LINER_BASIS_STEP, 0.0), (0.0, 1.0), (LINER_BASIS_STEP, 1.0)):
        out.append(jnp.stack(sensor_signals(solution, geometry, dataclasses.replace(sensor, offset=e, tilt_gain=g))))
    return jnp.stack(out)


def profile_basis(model: ProfileModel, ring: RingParams, geometry: TyreGeometry, operating, band,
                  solver: ContactSolver) -> jax.Array:
    """One profile's reading basis ``(4, 2, M)``: the rolling state of ``ring`` (already through ``model.ring``) at
    ``operating`` (:func:`ringfit.physics.profile.rolling_state`), read by :func:`sensor_basis` and band-limited by
    the spectral stage to ``band`` ``(M//2+1,)`` — the inner stage of every reader that fits each run's sensor
    nuisances (fit-rolling, identify); :func:`sensor_reading` combines it."""
    from ringfit.physics.profile import rolling_state, spectral_stage

    sol, _ = rolling_state(model, ring, geometry, operating, solver)
    return spectral_stage(model, sensor_basis(sol, geometry, model.sensor), ring, geometry,
                          jnp.full(4, operating.omega), jnp.broadcast_to(band, (4,) + band.shape), 0.0)


def sensor_reading(basis, omega, sensor):
    """The runs' channels ``(P, 2, M)`` from their :func:`sensor_basis` ``(P, 4, 2, M)`` (after the spectral stage)
    at their sensor nuisances ``sensor`` ``(P, 4)`` (:data:`SENSOR_FIELDS` order) and Ω ``(P,)``: the bilinear
    combination in (e, γ), the IEPE high-pass at f_c (first order, docs/physics.md §5 layer 5), and the tangential
    axis's gain."""
    from ringfit.physics.sensor import iepe_highpass

    g, fc, e, gt = (sensor[:, j][:, None, None] for j in range(4))
    a = e / LINER_BASIS_STEP
    b00, b10, b01, b11 = (basis[:, j] for j in range(4))
    ch = b00 + a * (b10 - b00) + g * (b01 - b00) + a * g * (b11 - b10 - b01 + b00)
    ch = jax.vmap(iepe_highpass)(ch, omega, fc[:, 0, 0])
    return ch * jnp.concatenate([jnp.ones_like(gt), gt], axis=1)


def read_through(channels, offset, gain):
    """The model's channels ``(P, 2, M)`` as each run records them: shifted by its angle offset ``(P,)`` [rad]
    (docs/physics.md §5 layer 6, band-limited) and scaled by its gain ``(P,)``."""
    return shift_angle(channels, offset[:, None, None]) * gain[:, None, None]


def harmonic_amplitudes(signal, k_min: int, k_max: int):
    """Complex amplitudes ``a_k`` (k = k_min … k_max) of grid signals ``(..., M)`` on φ_j = −π + 2πj/M: the one
    revolution-harmonic transform of ringfit's profile rows (docs/physics.md §10).

    ``x(α) = Σ_k Re(a_k e^{ikα})`` (k ≥ 1): ``a_k = (2/M)(−1)^k rfft(x)_k``. Works on JAX and
    NumPy arrays (returns the same kind). **Returns:** ``(..., k_max − k_min + 1)`` [units of x].
    """
    xp = jnp if isinstance(signal, jax.Array) else np
    M = signal.shape[-1]
    k = np.arange(k_min, k_max + 1)
    spec = xp.fft.rfft(signal, axis=-1)[..., k_min : k_max + 1]
    return spec * (2.0 / M) * np.where(k % 2, -1.0, 1.0)


def amplitude_rows(amplitudes):
    """Real residual rows ``[Re a_k …, Im a_k …]`` ``(..., 2K)`` of complex amplitudes ``(..., K)``."""
    xp = jnp if isinstance(amplitudes, jax.Array) else np
    return xp.concatenate([amplitudes.real, amplitudes.imag], axis=-1)


def harmonic_rows(channels, k_min: int = PROFILE_K_MIN, rows_grid: int | None = None, k_top: int = 0):
    """Rows ``(..., 2H)`` of revolution harmonics k_min … M/2 − 1 of ``channels`` ``(..., M)`` in the profile
    block's normalisation: :func:`amplitude_rows` of ``(−1)^k √(M/2) a_k`` (:func:`harmonic_amplitudes`), i.e. of
    ``rfft · √(2/M)``, so that white noise of σ per sample gives each row variance σ² (the load and state
    estimates fit the amplitudes ``a_k`` themselves, σ per row from :func:`noise_spectrum`).

    ``rows_grid``: the rows of the same revolution band-limited to that many points (harmonics k_min …
    rows_grid/2 − 1), for a model evaluated on a finer grid than the data's (the grid check). ``k_top`` > 0: the
    rows stop at harmonic k_top (the profiles' band, :func:`profile_band`)."""
    channels = jnp.asarray(channels)
    M = channels.shape[-1]
    R = M if rows_grid is None else int(rows_grid)
    top = R // 2 if k_top <= 0 else min(R // 2, int(k_top) + 1)
    k = np.arange(k_min, top)
    return amplitude_rows(harmonic_amplitudes(channels, k_min, top - 1) * (np.where(k % 2, -1.0, 1.0)
                                                                            * math.sqrt(R / 2.0)))


def profile_band(n_samples, n_grid: int) -> int:
    """The highest revolution harmonic the profile rows compare: below the grid's Nyquist (M/2 − 1) and
    :data:`PROFILE_BAND_MARGIN` below what the coarsest profile resolves ((N − 1)/2 for N angles; ``n_samples``
    each profile's N) — a profile holds nothing above that, and a model row there would be compared with a zero."""
    n_min = min(int(n) for n in n_samples)
    return int(min(n_grid // 2 - 1, (n_min - 1) // 2 - PROFILE_BAND_MARGIN))


@dataclass(frozen=True)
class RollingData:
    """Profiles on the model grid, ready for a fit.

    - ``measured``: ``(P, 2, M)`` radial/tangential [m/s²] on φ_j (mean removed for the baseline sensor).
    - ``omega``, ``load``: ``(P,)`` Ω [rad/s] and Fz [N]; ``drum_diameter``: ``(P,)`` [m] or None (flat road).
    - ``speed_kmh``: ``(P,)``; ``omega_source``: per profile, where Ω came from; ``sources``: file names.
    - ``n_samples``: per profile its number of recorded angles (the band its harmonic rows compare,
      :func:`ringfit.fit.profile_block.profile_band`); empty: the grid's whole band.
    """

    measured: np.ndarray
    omega: np.ndarray
    load: np.ndarray
    drum_diameter: np.ndarray | None
    speed_kmh: np.ndarray
    omega_source: tuple[str, ...]
    sources: tuple[str, ...]
    n_samples: tuple[int, ...] = ()


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
        n_samples=tuple(len(p) for p in profiles),
    )


def block_rows(data: RollingData, k_min: int = PROFILE_K_MIN, k_max: int | None = None) -> dict:
    """The profile block's rows of prepared profiles: ``measured`` ``(P, 2, 2H)`` harmonic rows
    (:func:`ringfit.fit.profile_block.harmonic_rows`, k_min … ``k_top`` of
    :func:`ringfit.fit.profile_block.profile_band`) and the starting ``sigma`` (a tenth of each profile and
    channel's RMS row, as :func:`ringfit.fit.profile_block.profile_rows` starts it; replaced by
    :func:`ringfit.fit.profile_block.noise_from_residual` after the first pass)."""
    M = data.measured.shape[-1]
    k_top = profile_band(data.n_samples, M) if data.n_samples else M // 2 - 1
    if k_max is not None:
        k_top = min(k_top, int(k_max))
    if k_top < k_min:
        raise InputError(f"the profiles resolve revolution harmonics up to {k_top} only; the rows start at "
                         f"{k_min}: give profiles with more angles per revolution")
    measured = np.asarray(harmonic_rows(jnp.asarray(data.measured), k_min=k_min, k_top=k_top))
    sigma = np.broadcast_to(np.sqrt(np.mean(measured**2, axis=-1, keepdims=True)) * 0.1, measured.shape).copy()
    return dict(measured=measured, sigma=sigma, k_top=k_top, k_min=k_min)


def profile_rows(profiles, geometry, ring, solver, k_min: int = PROFILE_K_MIN, k_max: int | None = None) -> dict:
    """The block's rows of ``profiles``: ``measured`` ``(P, 2, 2H)`` harmonic rows (:func:`harmonic_rows`, k_min …
    :func:`profile_band`), a starting ``sigma`` of the same shape (a tenth of each profile and channel's RMS row,
    replaced by :func:`noise_from_residual` after the first fit), and per profile ``omega``, ``load``, ``drum``,
    ``speed_kmh``, ``sources`` (``P``, ``M``, ``k_top``, ``k_min``, ``grid`` the channels ``(P, 2, M)`` on the model
    grid, ``omega_source``)."""
    data = rolling_data(profiles, geometry, ring, solver=solver)
    rows = block_rows(data, k_min, k_max)
    return dict(rows, omega=np.array(data.omega, dtype=np.float64), load=data.load, drum=data.drum_diameter,
                P=rows["measured"].shape[0], M=data.measured.shape[-1], sources=data.sources,
                speed_kmh=data.speed_kmh, grid=data.measured, omega_source=list(data.omega_source))


def noise_spectrum(power: np.ndarray, k_min: int = PROFILE_K_MIN, half_width: int = NOISE_SMOOTHING) -> tuple:
    """Noise power per harmonic ``(..., H)`` (k = k_min …) from residual powers, and its degrees of freedom ``(H,)``.

    Coloured noise (docs/physics.md §11, *profile noise*): a power law ``a·k^b`` fitted to ln power per series takes
    out the spectrum's slope (pink and red noise change by ×5 over the first few harmonics, where a plain moving
    average mixes them); the ratio to it is averaged over the ±``half_width`` *neighbouring* harmonics, leaving
    each harmonic's own residual out, so a row's weight does not depend on its own noise (a bump — a structural
    mode — is followed by the average). ``dof``: 2 × the neighbours averaged (each harmonic's residual holds a
    real and an imaginary part).
    """
    H = power.shape[-1]
    k = np.arange(k_min, k_min + H, dtype=np.float64)
    X = np.stack([np.ones(H), np.log(k)], axis=1)
    floor = 1e-300 + 1e-30 * float(np.max(power)) if power.size else 1e-300
    lp = np.log(np.maximum(power, floor)).reshape(-1, H)
    coef = np.linalg.lstsq(X, lp.T, rcond=None)[0]
    trend = np.exp(X @ coef).T.reshape(power.shape)
    kernel = np.ones(2 * half_width + 1)
    kernel[half_width] = 0.0  # leave the harmonic's own residual out
    num = np.apply_along_axis(lambda p: np.convolve(p, kernel, mode="same"), -1, power / trend)
    den = np.convolve(np.ones(H), kernel, mode="same")
    return trend * num / den, 2.0 * den


def noise_from_residual(residual: np.ndarray, leverage: np.ndarray, k_min: int = PROFILE_K_MIN,
                        series: int = 1) -> np.ndarray:
    """The block's σ ``(P, 2, 2H)`` per profile, channel and harmonic from its residual rows ``(P, 2, 2H)``
    [m/s²] (:func:`noise_spectrum`) and the fit's leverage of those rows (the hat matrix's diagonal, any shape
    with their count; the degrees of freedom the fit took, shared out evenly).

    Weights estimated from ν = ``dof`` residual parts make the weighted fit's actual variance larger than
    ``(JᵀŴJ)⁻¹`` says: with ŵ = w/c, c ~ χ²_ν/ν independent of the row, the estimator's variance is
    E[1/c²]/E[1/c]² / Σ J²w and the formula's E[1/c]⁻¹ / Σ J²w, a ratio ν/(ν − 4). The σ² of each row is
    multiplied by it, so that the covariance of the fit is the weighted estimator's (docs/physics.md §11).

    ``series``: how many independent residual series each row's power averages (``residual`` the RMS over
    that many fits of the same rows, e.g. revolutions of one recording): the degrees of freedom are that many
    times one series'."""
    res = np.asarray(residual, dtype=np.float64)
    H = res.shape[-1] // 2
    power = 0.5 * (res[..., :H] ** 2 + res[..., H:] ** 2)
    noise, dof = noise_spectrum(power, k_min=k_min)
    dof = dof * max(int(series), 1)
    leverage = np.asarray(leverage, dtype=np.float64)
    used = float(leverage.sum()) / max(leverage.size, 1)
    inflate = dof / np.maximum(dof - 4.0, 1.0)
    sigma = np.sqrt(noise * inflate / max(1.0 - used, 0.5))
    sigma = np.maximum(sigma, 1e-6 * max(float(sigma.max()), 1e-300))
    return np.concatenate([sigma, sigma], axis=-1)


def fit_profile_block(fit_at, sigma0: np.ndarray, k_min: int = PROFILE_K_MIN):
    """A fit of one profile block with its noise model: σ weights the fit, the fit's residual gives σ
    (:func:`noise_from_residual`), and the fit is redone with it — the same passes as ``identify``'s profile block
    (docs/physics.md §11 *profiles*).

    ``fit_at(sigma)`` fits the problem with rows weighted by ``sigma`` (the shape of ``sigma0``: ``(..., 2H)``
    harmonic rows, k = ``k_min`` …) and returns its :class:`~ringfit.fit.result.FitResult` (the block's rows
    first, in ``sigma0``'s order, then any prior's; Jacobian likewise); a caller that warm-starts its passes keeps
    θ in the closure. At least two fits (the first σ is only a starting guess), at most
    :data:`ringfit.fit.free_block.SCALE_PASSES`, stopping at the first converged fit after the first.

    **Returns:** ``(fit, sigma_used, passes)``: the last fit, the σ it was weighted by, and the fits made.

    Runs with one BLAS thread (:func:`ringfit._threads.small_matrix_threads`): the fits' contact solves factorise
    small matrices on XLA's threads, and each pass's hat matrix and covariance are SVDs of a tall, thin Jacobian
    (thousands of rows × ≤ 15 columns), where a threaded BLAS only synchronises — on the loaded two-core machine
    such an SVD took 65 ms of CPU threaded and 0.7 ms on one thread.
    """
    from ringfit._threads import small_matrix_threads  # noqa: PLC0415 (as identify's)

    with small_matrix_threads():
        return _profile_passes(fit_at, sigma0, k_min)


def _profile_passes(fit_at, sigma0, k_min):
    from ringfit.fit.free_block import hat_diagonal, noise_passes  # noqa: PLC0415 (free_block sits beside)

    state = dict(sigma=np.asarray(sigma0, dtype=np.float64))
    m = state["sigma"].size

    def fit_once():
        state["used"] = state["sigma"]
        return fit_at(state["used"])

    def renoise(fit):  # σ per harmonic: no single scale to settle, and never "held" (the first σ only starts it)
        residual = np.asarray(fit.residuals, dtype=np.float64)[:m].reshape(state["used"].shape) * state["used"]
        state["sigma"] = noise_from_residual(residual, hat_diagonal(np.asarray(fit.jacobian))[:m], k_min=k_min)
        return 0.0, False

    fit, done = noise_passes(fit_once, renoise)
    return fit, state["used"], done


__all__ = ["decrement_tol", "RollingData", "fit_profile_block", "rolling_data", "block_rows", "profile_rows", "harmonic_rows", "profile_band", "nuisance_names", "nuisance_coords", "nuisance_start",
           "read_through", "nuisance_prior", "nuisance_prior_cov", "GAIN_SPREAD", "GAIN_COMMON_SD", "OFFSET_SPREAD", "noise_spectrum", "noise_from_residual", "GAIN_RANGE", "OFFSET_BOUND", "OFFSET_SCALE",
           "PROFILE_K_MIN", "NOISE_SMOOTHING", "PROFILE_BAND_MARGIN"]
