"""Wheel load and contact patch from the one accelerometer (docs/physics.md §4–5; docs/formats.md §7).

Once the ring is identified (ρA, EI, k_w, k_v, ζ, k_trd and the geometry from a
fitted tyre file, all fixed here), the steady rolling model
(:func:`ringfit.physics.profile.profile_channels`, the one forward model) is
inverted for the vertical load Fz that the sensor's profile shows. This module is a
*problem definition on the one engine* (:mod:`ringfit.fit.engine`): the residuals,
their coordinates and the fitting procedure; no solver of its own.

**What is fitted, and why these choices.**

- **Radial channel only.** For the inextensible ring the tangential reading is
  gravity plus terms that exist only through the sensor mounting (tilt γ, offset e)
  and the tread's shear (docs/physics.md §5 identities, §6): its load content is
  borrowed from the least certain parts of the model. The radial reading maps the belt
  curvature, ``s_rad = Ω²R²κ + g cos(φ − ψ)``: its shape around the patch is set by the
  ring's stiffness and the pressure it carries, i.e. by the load.
- **Revolution harmonics k = 2 … k_max of that channel.** k = 0 (the mean, removed by
  the model, docs/physics.md §6 baseline) and k = 1 are left out: for the inextensible
  ring the k = 1 harmonic of the reading is gravity alone (``a_r,n ∝ (n² − 1)W_n``,
  docs/physics.md §4.6), so its amplitude (1 g or a calibration error), its phase and
  the high-pass's large effect on it carry no load information and cannot bias the load.
  ``k_max`` (default 40) keeps nearly all of the information (the patch's bending
  features sit below harmonic ~30 for a passenger tyre) while staying clear of the
  model's grid resolution and of a data set's band limit or fine tread detail.
- **Free gain.** A factor on the whole reading (log, 0.5–2). For χ = 1 and the
  inextensible ring the rolling shape does not depend on Ω and the accelerations scale
  with Ω² (docs/physics.md §4.1), so an error in Ω (a nominal ``speed_kmh``), in the
  sensor's sensitivity, or its offset e inward of the belt (which enters the radial
  channel as the factor 1 − 2e/R, to first order) is absorbed by the gain: **the load
  comes from the shape of the reading around the patch, not from its amplitude.**
  Ω then matters only through the high-pass, whose corner is fitted as well.
- **Nuisances modelled** (docs/physics.md §5): the IEPE high-pass corner
  ``corner_hz`` (first order, log, weak prior :data:`CORNER_PRIOR`; below ~0.01 Hz it has
  no effect and is reported as unresolved), the axes' tilt ``tilt_gain`` γ (linear, weak
  prior :data:`TILT_PRIOR`: in the radial channel it enters only through γψ·g sin φ, so it
  also absorbs a data set without gravity, γ = 0) with gravity at 1 g, and the recorded-angle offset
  ``angle_offset`` (φ = α + offset; unbounded, started from the patch found in the
  data and flagged beyond 10°).
- **Tread stiffness.** The tyre file's k_trd is fixed by default: in one profile the
  load and k_trd are ~99 % correlated (a stiffer tread and a larger load make a similar
  patch), so the load is only as good as the k_trd the tyre was fitted with
  (``ringfit fit-rolling`` at known loads). ``k_tread_sd`` (σ of ln k_trd) frees it with
  a log-normal prior, so its uncertainty is propagated into the load's interval; a tyre
  file without k_trd gets :data:`DEFAULT_K_TREAD_SD` and a warning.
- **Weights.** Two passes (feasible generalised least squares): a first fit with equal
  weights; then each harmonic is weighted by 1/σ_k, σ_k² the first fit's residual power
  averaged over ±:data:`NOISE_SMOOTHING` neighbouring harmonics. Periodic stationary noise
  has independent Fourier coefficients, so coloured noise (and harmonics where the model
  is poorer) is whitened, and the Laplace interval of the second fit (engine covariance,
  σ estimated from the residual) holds for coloured noise too.

**Starting values and the classic method.** :func:`feature_estimate` is the
tyre-sensor field's method: the two edge peaks of the (band-limited) radial reading,
their spacing → load through the model's load–spacing curve (:func:`load_curves`, the
same feature computed on the model at a grid of loads). It starts the fit and is
reported beside it.

**Outputs.** The load and its 95 % Laplace interval (log-normal in the load), the
contact patch of the model at that load (:func:`ringfit.physics.contact.patch_edges`,
:func:`~ringfit.physics.contact.contact_length`, interpolated on the load curve), Ω with
its source, the fit's status, residual RMS and the noise level in the fitted band
(:class:`LoadEstimate`).

Per revolution of a continuous recording: :func:`estimate_revolutions` (load and angle
offset free, the nuisances fixed at the averaged profile's fit, batches of revolutions
solved by :func:`ringfit.fit.engine.least_squares_batch`, each batch warm-started from the
previous one).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ringfit.errors import InputError
from ringfit.io.profiles import grid_angles_deg
from ringfit.fit.engine import (LINEAR, LOG, AbstractResiduals, Coordinate, GaussianPrior, Problem, least_squares,
                                least_squares_batch)
from ringfit.fit.result import FitResult
from ringfit.params import BAR, RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, as_traced, contact_length, patch_edges
from ringfit.physics.operating import KMH
from ringfit.physics.profile import (FlatOrDrum, ProfileModel, effective_rolling_radius, flat_or_drum, full_band,
                                     profile_channels, rolling_state)
from ringfit.physics.sensor import STANDARD_GRAVITY

LOAD, GAIN, ANGLE_OFFSET, CORNER, TILT, K_TREAD = "load_n", "gain", "angle_offset", "corner_hz", "tilt_gain", "k_tread"
#: Every parameter of the estimate problem, in θ order.
PARAMETERS = (LOAD, GAIN, ANGLE_OFFSET, CORNER, TILT, K_TREAD)
#: Plausible loads [N]: the load's bounds (a fit that ends there has failed).
LOAD_RANGE = (200.0, 20000.0)
#: Range of the gain on the reading.
GAIN_RANGE = (0.5, 2.0)
#: Weak priors on the sensor nuisances (natural units): the high-pass corner's median [Hz] and σ of
#: its logarithm (0.005–16 Hz at 2σ; below ~0.01 Hz it has no effect on harmonics k ≥ 2), the tilt's
#: mean and σ (γ ∈ 0–1.1 with gravity, 0 without, docs/physics.md §6). They keep the nuisances finite
#: where the data say little (a high speed, no gravity) and are propagated like any other parameter.
CORNER_PRIOR = (0.3, 2.0)
TILT_PRIOR = (0.5, 0.5)
#: σ of ln k_trd used when the tyre file has no k_tread (a ±60 % range at 95 %).
DEFAULT_K_TREAD_SD = 0.3
#: Harmonics averaged on either side for the second pass's noise spectrum.
NOISE_SMOOTHING = 4
#: An angle offset beyond this [deg] is flagged (the profile's zero is not the patch centre).
OFFSET_WARN_DEG = 10.0
#: A residual RMS above this multiple of the noise is flagged as a poor fit …
POOR_FIT_RATIO = 1.5
#: … when it is also above this fraction of the reading's RMS in the fitted band (the estimator's own
#: discretisation leaves ~0.1 %: noise-free profiles of the same model are not "poor").
MODEL_FLOOR = 0.005

COORDS = (
    Coordinate(LOAD, LOG, lo=LOAD_RANGE[0], hi=LOAD_RANGE[1]),
    Coordinate(GAIN, LOG, lo=GAIN_RANGE[0], hi=GAIN_RANGE[1]),
    Coordinate(ANGLE_OFFSET, LINEAR, scale=math.radians(1.0)),
    Coordinate(CORNER, LOG),
    Coordinate(TILT, LINEAR, scale=0.1),
    Coordinate(K_TREAD, LOG, lo=1e5, hi=1e9),
)


@dataclass(frozen=True)
class EstimateSettings:
    """How the estimate is computed.

    - ``n_grid``: model grid M of the contact solve (docs/physics.md §4.4–4.5). The fitted harmonics
      converge by M = 256, but the patch's discrete active set makes the load–shape relation a
      staircase: fitting M = 2048 profiles, M = 256 is biased by up to 1 % (at some loads), 384 by
      0.3 %, 512 by < 0.1 % (``benchmarks/bench_estimate.py``).
    - ``k_max``: highest revolution harmonic fitted (lowered to the data's band limit).
    - ``window_deg``: contact candidate window (the patch must lie inside).
    - ``k_tread_sd``: σ of ln k_trd; ``None`` = fixed at the tyre file's value (when the file has one).
    - ``highpass_order``: stages of the modelled high-pass (1: the IEPE sensor).
    - ``max_steps``, ``rtol``, ``atol``: Levenberg–Marquardt step cap and Cauchy tolerances (solver
      coordinates: log load, degrees of offset; residual rows in m/s²).
    - ``revolution_window_deg``: candidate window for the per-revolution fits (the patch must fit; a
      smaller window is a smaller dense contact solve: 20° holds loads up to ~10 kN on the Table 9 tyre
      and is widened automatically when a recording's patch needs more).
    - ``curve_points``, ``curve_grid``: loads and model grid of the load curves (patch, feature).
    """

    n_grid: int = 512
    k_max: int = 40
    window_deg: float = 35.0
    k_tread_sd: float | None = None
    highpass_order: int = 1
    max_steps: int = 100
    rtol: float = 1e-6
    atol: float = 1e-6
    revolution_window_deg: float = 20.0
    curve_points: int = 48
    curve_grid: int = 512

    @property
    def solver(self) -> ContactSolver:
        return ContactSolver(n_grid=self.n_grid, window_deg=self.window_deg)

    def profile_model(self) -> ProfileModel:
        """The forward model: baseline ring, gravity on, tilt and high-pass set per fit (traced)."""
        return ProfileModel().with_sensor(gravity=STANDARD_GRAVITY, highpass_order=self.highpass_order)


# ----------------------------------------------------------------------------- harmonics


def harmonic_amplitudes(signal, k_min: int, k_max: int):
    """Complex amplitudes ``a_k`` (k = k_min … k_max) of grid signals ``(..., M)`` on φ_j = −π + 2πj/M.

    ``x(α) = Σ_k Re(a_k e^{ikα})`` (k ≥ 1): ``a_k = (2/M)(−1)^k rfft(x)_k``. Works on JAX and
    NumPy arrays (returns the same kind). **Returns:** ``(..., k_max − k_min + 1)`` [units of x].
    """
    xp = jnp if isinstance(signal, jax.Array) else np
    M = signal.shape[-1]
    k = np.arange(k_min, k_max + 1)
    spec = xp.fft.rfft(signal, axis=-1)[..., k_min : k_max + 1]
    return spec * (2.0 / M) * np.where(k % 2, -1.0, 1.0)


def harmonic_rows(amplitudes) -> np.ndarray:
    """Real residual rows ``[Re a_k …, Im a_k …]`` ``(..., 2K)`` of complex amplitudes ``(..., K)``."""
    xp = jnp if isinstance(amplitudes, jax.Array) else np
    return xp.concatenate([amplitudes.real, amplitudes.imag], axis=-1)


def band_signal(amplitudes, k_min: int, angle_rad) -> np.ndarray:
    """``Σ_k Re(a_k e^{ikα})`` at angles ``α`` [rad] ``(N,)`` of amplitudes ``(..., K)`` → ``(..., N)``."""
    k = np.arange(k_min, k_min + np.shape(amplitudes)[-1])
    return np.real(np.asarray(amplitudes) @ np.exp(1j * np.outer(k, angle_rad)))


def grid_signal(amplitudes, k_min: int, n_points: int) -> np.ndarray:
    """:func:`band_signal` on the grid α_j = −π + 2πj/n (one inverse FFT) → ``(..., n_points)``."""
    amplitudes = np.asarray(amplitudes)
    K = amplitudes.shape[-1]
    k = np.arange(k_min, k_min + K)
    spec = np.zeros(amplitudes.shape[:-1] + (n_points // 2 + 1,), dtype=complex)
    spec[..., k_min : k_min + K] = amplitudes * np.where(k % 2, -1.0, 1.0) * (n_points / 2.0)
    return np.fft.irfft(spec, n_points, axis=-1)


# ----------------------------------------------------------------------------- the problem


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
        rows = harmonic_rows(harmonic_amplitudes(radial, self.k_min, self.k_max) * data.response)
        return ((rows - data.measured) * data.weight).ravel(), rows


def nuisance_priors() -> dict:
    """``name -> (mean, sd)`` in solver coordinates of the high-pass corner and tilt priors."""
    tilt = COORDS[PARAMETERS.index(TILT)]
    return {CORNER: (math.log(CORNER_PRIOR[0]), CORNER_PRIOR[1]),
            TILT: ((TILT_PRIOR[0] - tilt.center) / tilt.scale, TILT_PRIOR[1] / tilt.scale)}


def estimate_problem(arrays: EstimateArrays, settings: EstimateSettings, k_max: int,
                     prior: GaussianPrior | None = None) -> Problem:
    """The engine :class:`~ringfit.fit.engine.Problem` of an estimate (σ estimated from the residual)."""
    residuals = EstimateResiduals(settings.profile_model(), settings.solver, 2, int(k_max))
    return Problem(residuals, as_traced(arrays), COORDS, prior=prior, sigma="estimate",
                   plausible={LOAD: LOAD_RANGE}, data_label="this profile")


def smoothed_noise(rows: np.ndarray, half_width: int = NOISE_SMOOTHING) -> np.ndarray:
    """σ per row ``(..., 2K)`` from residual rows ``(..., 2K)``: power per harmonic averaged over ±half_width harmonics."""
    K = rows.shape[-1] // 2
    power = 0.5 * (rows[..., :K] ** 2 + rows[..., K:] ** 2)
    kernel = np.ones(2 * half_width + 1)
    num = np.apply_along_axis(lambda p: np.convolve(p, kernel, mode="same"), -1, power)
    den = np.convolve(np.ones(K), kernel, mode="same")
    sigma = np.sqrt(num / den)
    sigma = np.maximum(sigma, 1e-6 * max(float(np.max(sigma)), 1e-300))
    return np.concatenate([sigma, sigma], axis=-1)


# ----------------------------------------------------------------------------- load curves


@dataclass(frozen=True)
class LoadCurves:
    """The model at a grid of loads (same tyre, road, Ω): patch and edge-peak feature vs load.

    ``load_n`` ``(G,)``; ``length_mm``, ``leading_deg``, ``trailing_deg`` ``(G,)`` the contact patch
    (docs/physics.md §4.4); ``peak_spacing_deg`` ``(G,)`` the angle between the radial reading's two
    edge peaks (band-limited to k ≤ ``k_max``); ``ok`` ``(G,)`` contact solved inside its window.
    """

    load_n: np.ndarray
    length_mm: np.ndarray
    leading_deg: np.ndarray
    trailing_deg: np.ndarray
    peak_spacing_deg: np.ndarray
    peak_mid_deg: np.ndarray
    amplitudes: np.ndarray
    ok: np.ndarray
    k_max: int

    def _interp(self, y, load):
        good = self.ok
        return np.interp(np.log(np.asarray(load, dtype=np.float64)), np.log(self.load_n[good]), y[good])

    def patch_at(self, load) -> dict:
        """Patch length [mm], leading and trailing edge [deg] at ``load`` [N] (scalar or array)."""
        return {"length_mm": self._interp(self.length_mm, load), "leading_deg": self._interp(self.leading_deg, load),
                "trailing_deg": self._interp(self.trailing_deg, load)}

    def gain_at(self, load: float, amplitudes) -> float:
        """Least-squares gain of measured amplitudes ``(K,)`` on the curve's model at the nearest load (0.6–1.6)."""
        model = self.amplitudes[int(np.argmin(np.abs(np.log(self.load_n / load))))]
        g = np.sum(np.abs(np.asarray(amplitudes) * model)) / max(float(np.sum(np.abs(model) ** 2)), 1e-300)
        return float(np.clip(g, 0.6, 1.6))

    def load_from_spacing(self, spacing_deg) -> np.ndarray:
        """Load [N] whose model edge-peak spacing is ``spacing_deg`` (NaN outside the curve)."""
        good = self.ok & np.isfinite(self.peak_spacing_deg)
        s, L = self.peak_spacing_deg[good], np.log(self.load_n[good])
        order = np.argsort(s)
        s, L = s[order], L[order]
        x = np.asarray(spacing_deg, dtype=np.float64)
        out = np.exp(np.interp(x, s, L))
        return np.where((x >= s[0]) & (x <= s[-1]), out, np.nan)


@eqx.filter_jit
def _curve_states(model, ring, geometry, omega, loads, roads, solver):
    def one(load, road):
        from ringfit.physics.operating import OperatingPoint

        sol, ch = rolling_state(model, ring, geometry, OperatingPoint(omega, load, road), solver)
        lead, trail = patch_edges(sol)
        return ch[0], lead, trail, contact_length(sol), sol.ok

    return jax.vmap(one)(loads, roads)


def load_curves(geometry: TyreGeometry, ring: RingParams, omega: float, drum_diameter_m=None, *,
                settings: EstimateSettings = EstimateSettings(), k_max: int | None = None) -> LoadCurves:
    """The model's patch and edge-peak spacing at ``settings.curve_points`` loads log-spaced over
    :data:`LOAD_RANGE` (one vmapped solve on ``settings.curve_grid`` points; baseline sensor).

    **Arguments:** the tyre, Ω [rad/s] (the shape does not depend on it for χ = 1), the drum
    diameter [m] or None (flat road), the settings; ``k_max``: band limit of the peak feature.
    """
    k_max = settings.k_max if k_max is None else int(k_max)
    G = settings.curve_points
    loads = np.exp(np.linspace(math.log(LOAD_RANGE[0]), math.log(LOAD_RANGE[1]), G))
    solver = ContactSolver(n_grid=settings.curve_grid, window_deg=settings.window_deg)
    roads = flat_or_drum(drum_diameter_m, G)
    rad, lead, trail, length, ok = _curve_states(*as_traced((ProfileModel(), ring, geometry)), np.float64(omega),
                                                  loads, roads, solver)
    amp = harmonic_amplitudes(np.asarray(rad), 2, k_max)
    peaks = edge_peaks(amp, 2)[:, :2]
    return LoadCurves(load_n=loads, length_mm=1e3 * np.asarray(length), leading_deg=np.degrees(np.asarray(lead)),
                      trailing_deg=np.degrees(np.asarray(trail)), peak_spacing_deg=peaks[:, 1] - peaks[:, 0],
                      peak_mid_deg=peaks.mean(axis=1), amplitudes=amp, ok=np.asarray(ok), k_max=k_max)


# ----------------------------------------------------------------------------- the feature method

#: Points of the band-limited reading searched for the edge peaks (0.09° spacing).
PEAK_GRID = 4096
#: The edge peaks are searched within this angle [deg] of the dip.
PEAK_SEARCH_DEG = 60.0


def edge_peaks(amplitudes, k_min: int = 2) -> np.ndarray:
    """Edge peaks of radial readings given by their harmonic amplitudes ``(..., K)`` (k = k_min…).

    The patch is the deepest dip of the band-limited reading; the edge peaks are its
    maxima within :data:`PEAK_SEARCH_DEG` before and after the dip (refined by a parabola
    through the three highest points). **Returns:** ``(..., 4)``: leading, trailing [deg]
    (the reading's angle), their spacing and the dip's angle [deg]; NaN where no peak stands out.
    """
    x = grid_signal(amplitudes, k_min, PEAK_GRID)
    flat = x.reshape(-1, PEAK_GRID)
    out = np.array([_edge_peaks_one(row) for row in flat])
    return out.reshape(x.shape[:-1] + (4,))


def _edge_peaks_one(x: np.ndarray) -> tuple[float, float, float, float]:
    step = 360.0 / PEAK_GRID
    i_dip = int(np.argmin(x))
    reach = int(PEAK_SEARCH_DEG / step)
    idx = (i_dip + np.arange(-reach, reach + 1)) % PEAK_GRID
    seg = x[idx]
    centre = reach

    def peak(lo, hi):
        j = lo + int(np.argmax(seg[lo:hi]))
        if j in (lo, hi - 1):  # the maximum sits at the end of the search range: no peak
            return math.nan
        y0, y1, y2 = seg[j - 1], seg[j], seg[j + 1]
        den = y0 - 2 * y1 + y2
        frac = 0.5 * (y0 - y2) / den if den < 0 else 0.0
        return (j - centre + frac) * step

    lead, trail = peak(0, centre), peak(centre + 1, 2 * reach + 1)
    dip = -180.0 + i_dip * step
    return dip + lead, dip + trail, trail - lead, dip


@dataclass(frozen=True)
class FeatureEstimate:
    """The classic method: edge-peak angles [deg] of the radial reading, their spacing as a length
    along the outer radius [mm], and the load [N] whose model shows that spacing (NaN if outside)."""

    load_n: float
    leading_deg: float
    trailing_deg: float
    spacing_mm: float

    def to_record(self) -> dict:
        """The feature estimate as a JSON-ready dict (docs/formats.md §7)."""
        return {"load_n": _num(self.load_n), "peak_leading_deg": _num(self.leading_deg),
                "peak_trailing_deg": _num(self.trailing_deg), "peak_spacing_mm": _num(self.spacing_mm),
                "method": "edge peaks of the radial reading (harmonics 2…k_max) → load through the model's "
                          "load–spacing curve"}


def feature_estimate(amplitudes, curves: LoadCurves, outer_radius: float) -> FeatureEstimate:
    """The classic feature method on measured radial amplitudes ``(K,)`` (k = 2…, band limited like ``curves``)."""
    lead, trail, spacing, _ = edge_peaks(amplitudes, 2)
    load = float(curves.load_from_spacing(spacing)) if math.isfinite(spacing) else math.nan
    return FeatureEstimate(load, lead, trail, 1e3 * outer_radius * math.radians(spacing))


def _num(x):
    x = float(x)
    return x if math.isfinite(x) else None


# ----------------------------------------------------------------------------- the estimate


@dataclass
class LoadEstimate:
    """An estimate of the load and the contact patch from one profile (docs/formats.md §7).

    - ``load_n``, ``lo``, ``hi``: the load and its 95 % Laplace interval [N].
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

    def to_record(self, input_name: str) -> dict:
        """The docs/formats.md §7 JSON object."""
        return {
            "input": str(input_name),
            "load_n": {"value": self.load_n, "lo": self.lo, "hi": self.hi},
            "patch": {k: _num(v) for k, v in self.patch.items()},
            "rotation_hz": {"value": self.rotation_hz, "source": self.rotation_source},
            "fit": {"status": self.status, "converged": self.converged, "rms": self.rms, "noise": self.noise,
                    "unit": "m/s^2", "noise_source": self.noise_source, "harmonics": [2, self.k_max],
                    "channel": "radial", "flags": list(self.flags)},
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


def _geometry_at_pressure(geometry: TyreGeometry, profile) -> tuple[TyreGeometry, list[str]]:
    """The geometry at the profile's pressure (with a warning when it differs from the tyre file's by > 5 %)."""
    notes = []
    pb = profile.condition.get("pressure_bar")
    if pb is not None:
        tyre_bar = float(geometry.pressure) / BAR
        if abs(pb - tyre_bar) > 0.05 * tyre_bar:
            notes.append(f"WARNING: the profile's pressure_bar = {pb:g} differs from the tyre file's {tyre_bar:g} bar "
                         "by more than 5 %; the model uses the profile's pressure with the tyre file's ring")
        geometry = TyreGeometry(geometry.radius, geometry.width, pb * BAR, geometry.tread_thickness,
                                geometry.tread_rib_width, name=geometry.name)
    return geometry, notes


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


def profile_amplitudes(profile, n_grid: int, k_max: int) -> np.ndarray:
    """Radial harmonic amplitudes ``(K,)`` (k = 2…k_max) of a profile (band-limited, trapezoid weights)."""
    from ringfit.io.profiles import resample_profile

    grid = resample_profile(profile, n_grid)[0]
    return harmonic_amplitudes(grid, 2, k_max)


def estimate_load(profile, geometry: TyreGeometry, ring: RingParams, *, settings: EstimateSettings = EstimateSettings(),
                  k_tread_in_file: bool = True, omega: float | None = None, omega_source: str | None = None,
                  noise_per_angle: np.ndarray | None = None, noise_source: str | None = None,
                  response: np.ndarray | None = None) -> LoadEstimate:
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

    **Returns:** :class:`LoadEstimate`. Never raises on non-convergence (check ``converged``).
    """
    geometry, flags = _geometry_at_pressure(geometry, profile)
    N = len(profile)
    k_max = int(min(settings.k_max, (N - 1) // 2 - 1, settings.n_grid // 2 - 2))
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
    measured = harmonic_rows(amp)[None]
    arrays = EstimateArrays(geometry=geometry, ring=ring, omega=np.array([omega]), roads=flat_or_drum(drum, 1),
                            response=resp[None], measured=measured, weight=np.ones((1, 2 * K)))
    theta0 = np.array([load0, curves.gain_at(load0, amp), offset0, 0.3, 0.5, float(ring.k_tread)])
    problem = estimate_problem(arrays, settings, k_max, prior)
    first = least_squares(problem, theta0, tuple(free), max_steps=settings.max_steps, rtol=settings.rtol,
                          atol=settings.atol)
    # second pass: whiten the residual spectrum
    resid_rows = np.asarray(first.extra["aux"])[0] - measured[0]
    weight = 1.0 / smoothed_noise(resid_rows)
    weight = weight / np.mean(weight)
    arrays = eqx.tree_at(lambda a: a.weight, arrays, weight[None])
    problem = estimate_problem(arrays, settings, k_max, prior)
    fit = least_squares(problem, first.theta, tuple(free), max_steps=settings.max_steps, rtol=settings.rtol,
                        atol=settings.atol)
    return _finish(fit, profile, curves, feature, amp, omega, omega_source, flags, k_max, drum, settings,
                   noise_per_angle, noise_source)


def _finish(fit, profile, curves, feature, amp, omega, omega_source, flags, k_max, drum, settings,
            noise_per_angle, noise_source=None) -> LoadEstimate:
    """The :class:`LoadEstimate` of a fit: interval, patch, fit quality, flags, nuisances."""
    load = fit.values[LOAD]
    lo, hi = fit.interval(LOAD)
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
        k_max=k_max, omega=float(omega), drum_diameter_m=drum)


# ----------------------------------------------------------------------------- per revolution

#: Revolutions fitted in one call of the engine (one compiled vmap or scan; the last batch is padded).
#: 16 is the fastest on a CPU (benchmarks/bench_estimate.py); an accelerator wants more.
REVOLUTION_BATCH = 16
#: Per-revolution Gauss–Newton tolerances (Cauchy test on the solver coordinates and the residual rows;
#: near the optimum the steps shrink fast, so the error left after the last step is far below the
#: per-revolution standard error of ~0.2–0.3 %) and step cap.
REVOLUTION_TOL = 1e-4
REVOLUTION_MAX_STEPS = 30


@dataclass
class RevolutionEstimates:
    """Per-revolution estimates of a continuous recording (arrays of shape ``(R,)``).

    ``revolution`` (numbers counted from the recording's first angle), ``t_s`` (middle of the
    revolution [s]), ``rotation_hz`` (encoder), ``load_n``, ``lo``, ``hi`` (95 % Laplace interval [N];
    statistical: the high-pass corner, tilt and k_trd are fixed at the averaged profile's fit),
    ``length_mm`` (patch length of the model at the load), ``gain``, ``angle_offset_deg``, ``rms``
    [m/s²] (residual in the fitted band), ``converged``, ``iterations``, ``feature_load_n`` (the
    classic method on the revolution); ``window_deg``: the contact window used.
    """

    revolution: np.ndarray
    t_s: np.ndarray
    rotation_hz: np.ndarray
    load_n: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    length_mm: np.ndarray
    gain: np.ndarray
    angle_offset_deg: np.ndarray
    rms: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    feature_load_n: np.ndarray
    window_deg: float = 0.0

    #: Columns of the per-revolution CSV (docs/formats.md §7), in order.
    COLUMNS = ("revolution", "t_s", "rotation_hz", "load_n", "lo", "hi", "patch_length_mm", "gain",
               "angle_offset_deg", "rms_ms2", "converged", "feature_load_n")

    def __len__(self) -> int:
        return self.revolution.size

    def columns(self) -> dict:
        """Column name → ``(R,)`` array, in :attr:`COLUMNS` order."""
        return {"revolution": self.revolution, "t_s": self.t_s, "rotation_hz": self.rotation_hz,
                "load_n": self.load_n, "lo": self.lo, "hi": self.hi, "patch_length_mm": self.length_mm,
                "gain": self.gain, "angle_offset_deg": self.angle_offset_deg, "rms_ms2": self.rms,
                "converged": self.converged.astype(int), "feature_load_n": self.feature_load_n}

    def summary(self) -> dict:
        """Counts and the load's range over the revolutions (for the JSON)."""
        ok = self.converged
        load = self.load_n[ok]
        return {"revolutions": int(len(self)), "converged": int(ok.sum()),
                "load_n_median": _num(np.median(load)) if load.size else None,
                "load_n_min": _num(load.min()) if load.size else None,
                "load_n_max": _num(load.max()) if load.size else None,
                "contact_window_deg": float(self.window_deg)}


@dataclass
class RecordingRevolutions:
    """One pass over a continuous recording: each whole revolution's radial harmonics and the average.

    ``rows`` ``(R, 2K)`` harmonic rows k = 2…k_max (:func:`harmonic_rows`) [m/s²]; ``revolution``,
    ``t_s``, ``rotation_hz`` ``(R,)``; ``profile``: the averaged profile (docs/formats.md §3, the
    revolution-to-revolution spread as ``acc_radial_spread_ms2``); ``response`` ``(K,)``: the resampling's
    gain on the harmonics (sinc²(k/samples per revolution), linear interpolation); ``k_max``; ``noise``
    ``(M,)`` the standard error of the averaged profile per angle [m/s²], from the differences of
    successive revolutions (a load that changes does not count as noise, unlike in the spread).
    """

    rows: np.ndarray
    revolution: np.ndarray
    t_s: np.ndarray
    rotation_hz: np.ndarray
    profile: object
    response: np.ndarray
    k_max: int
    noise: np.ndarray | None = None
    rotation_source: str = "encoder (mean over the recording)"


def first_rotation_hz(record, samples: int = 1 << 18) -> float:
    """Rotation rate [Hz] over the first ``samples`` samples of a recording (from its encoder)."""
    n = int(min(samples, record.samples))
    ch = next(record.chunks(n, stop=n, acc=False))
    rate = (ch.angle_deg[-1] - ch.angle_deg[0]) / 360.0 / ((n - 1) / record.fs_hz)
    if not rate > 0:
        raise InputError("the encoder angle does not advance over the first samples: is the wheel turning?",
                         source=record.source)
    return float(rate)


def recording_revolutions(record, *, k_max: int = EstimateSettings.k_max, progress: bool = False
                          ) -> RecordingRevolutions:
    """Walk a continuous recording once (bounded memory): every whole revolution's radial reading on
    the angle grid (:func:`ringfit.targets.rolling_profile.revolution_grids`, M = the power of two at or
    above the samples per revolution, so that every sample takes part), its harmonics 2…k_max, and
    their average and spread over revolutions as a profile.

    The sensor angle comes from the encoder; a recording without one gets it from the patch
    passages in the radial reading (:func:`ringfit.targets.rolling_profile.patch_passages`, one more
    pass): φ = 0 at each passage, linear in time in between (the angle offset then takes up where
    the dip sits relative to the patch centre).

    **Raises** :class:`InputError` without a radial axis, without an encoder and without clear patch
    passages, with fewer than 2 whole revolutions, or with too few samples per revolution.
    """
    from ringfit.io.profiles import Profile
    from ringfit.targets.rolling_profile import patch_passages, revolution_grids

    if "radial" not in record.axes:
        raise InputError(f"no 'radial' axis (have: {', '.join(record.axes)}); the estimate reads the radial channel",
                         source=record.source)
    passages = None
    if record.has_encoder:
        spr = record.fs_hz / first_rotation_hz(record)
        source = "encoder (mean over the recording)"
    else:  # the sensor angle from the patch passages in the reading itself
        passages = patch_passages(record, progress=progress)
        spr = float(np.median(np.diff(passages)))
        source = "patch passages in the radial reading (no encoder; mean over the recording)"
    if spr < 4 * (k_max + 2):
        raise InputError(f"{spr:.0f} samples per revolution are too few to resolve harmonic {k_max} "
                         f"(need ≥ {4 * (k_max + 2)})", source=record.source)
    points = int(min(4096, max(128, 2 ** math.ceil(math.log2(spr)))))
    rows, rev, t_s, rate = [], [], [], []
    s1, s2, sd = np.zeros(points), np.zeros(points), np.zeros(points)
    previous = None
    for block in revolution_grids(record, points=points, axes=("radial",), passages=passages, progress=progress):
        values = block.values[0]
        rows.append(harmonic_rows(harmonic_amplitudes(values, 2, k_max)))
        rev.append(block.revolution)
        t_s.append(block.t_s)
        rate.append(block.rotation_hz)
        s1 += values.sum(axis=0)
        s2 += (values**2).sum(axis=0)
        chain = values if previous is None else np.concatenate([previous, values])
        sd += (np.diff(chain, axis=0) ** 2).sum(axis=0)
        previous = values[-1:]
    R = int(sum(r.size for r in rev))
    if R < 2:
        raise InputError(f"{R} whole revolution(s) in the recording; the estimate needs at least 2",
                         source=record.source)
    mean = s1 / R
    spread = np.sqrt(np.clip((s2 - R * mean**2) / (R - 1), 0.0, None))
    # noise of one revolution from successive differences: blind to a load that changes slowly or in steps
    noise = np.sqrt(sd / (2 * (R - 1)))
    rate = np.concatenate(rate)
    cond = {k: float(record.condition[k]) for k in ("speed_kmh", "pressure_bar", "drum_diameter_m")
            if record.condition.get(k) is not None}
    cond.update(revolutions=R, sample_rate_hz=float(record.fs_hz), rotation_hz=float(np.mean(rate)),
                missing_axes=["tangential"])
    angle = grid_angles_deg(points)
    profile = Profile(angle, mean, np.zeros(points), condition=cond, source=str(record.source),
                      extra={"acc_radial_spread_ms2": np.array([repr(float(x)) for x in spread], dtype=object)})
    k = np.arange(2, k_max + 1)
    return RecordingRevolutions(rows=np.concatenate(rows), revolution=np.concatenate(rev), t_s=np.concatenate(t_s),
                                rotation_hz=rate, profile=profile, response=np.sinc(k / spr) ** 2, k_max=k_max,
                                noise=noise / math.sqrt(R), rotation_source=source)


def estimate_revolutions(data: RecordingRevolutions, reference: LoadEstimate, ring: RingParams, *,
                         settings: EstimateSettings = EstimateSettings(), batch: int = REVOLUTION_BATCH,
                         mode: str = "batch", progress: bool = False) -> RevolutionEstimates:
    """Load and patch for every whole revolution (from :func:`recording_revolutions`).

    Each revolution's harmonics 2…k_max are fitted for the load, the gain and the angle offset,
    with the high-pass corner, tilt and k_trd fixed at ``reference`` (the fit to the averaged
    profile; the gain is free because the averaged profile of a recording whose load changes is not
    the profile of one load, and a gain fixed there would bias every revolution) and Ω from the
    encoder per revolution. Revolutions go ``batch`` at a time to
    :func:`ringfit.fit.engine.least_squares_batch` (one compilation):

    - ``mode="batch"`` (default): each batch vmapped, every fit warm-started from the previous
      batch's last revolution (on a CPU, batches of 16 are ~20 % faster than the chain: the small
      matrix work vectorises across the batch, and Gauss–Newton takes 3–4 steps in every fit).
    - ``mode="chain"``: in order, each fit warm-started from the previous revolution's, the whole
      batch in one compiled ``lax.scan``; each batch continues from the previous batch's last fit.

    (Fitting stretches of the recording in parallel threads deadlocked XLA's CPU runtime here:
    one thread; on a CPU the batches run at ~600 revolutions per second.)

    Each fit is undamped Gauss–Newton (``method="gauss_newton"`` of the engine: from a neighbour's
    optimum it stops after 3–4 steps); a fit that does not settle is redone alone with
    Levenberg–Marquardt from the reference. The first batch is fitted twice: its residual spectrum, averaged over its revolutions, weights
    every fit (coloured noise, as in :func:`estimate_load`). A smaller contact window
    (``settings.revolution_window_deg``, widened to 1.3 × the reference patch) makes each solve
    cheaper; a batch in which a patch comes within 1.5° of it is refitted with ``settings.window_deg``.

    **Returns:** :class:`RevolutionEstimates`.
    """
    from tqdm import tqdm

    if mode not in ("chain", "batch"):
        raise ValueError(f"mode={mode!r}; expected 'chain' or 'batch'")
    fit = reference.fit
    k_max = data.k_max
    if k_max != reference.k_max:
        raise ValueError("the reference estimate was fitted to other harmonics")
    K = k_max - 1
    geometry = fit.problem.data.geometry
    half = max(abs(reference.patch["leading_deg"]), abs(reference.patch["trailing_deg"]))
    window = float(min(settings.window_deg, max(settings.revolution_window_deg, 1.3 * half)))
    drum = reference.drum_diameter_m
    response = np.asarray(data.response, dtype=np.float64)
    template = EstimateArrays(geometry=geometry, ring=ring, omega=np.ones(1), roads=flat_or_drum(drum, 1),
                              response=response[None], measured=np.zeros((1, 2 * K)), weight=np.ones((1, 2 * K)))
    problems = {window: estimate_problem(template, dataclasses.replace(settings, window_deg=window),
                                         k_max),
                settings.window_deg: estimate_problem(template, settings, k_max)}
    free = (LOAD, GAIN, ANGLE_OFFSET)
    rows_all, omega_all = data.rows, 2 * math.pi * data.rotation_hz
    R = rows_all.shape[0]
    fixed = jax.tree.map(lambda x: np.broadcast_to(np.asarray(x), (batch,) + np.shape(x)).copy(),
                         (as_traced(geometry), as_traced(ring), flat_or_drum(drum, 1), response[None]))

    def _arrays(take, weight):
        geo, rng, roads, resp = fixed
        return EstimateArrays(geometry=geo, ring=rng, omega=omega_all[take][:, None], roads=roads, response=resp,
                              measured=rows_all[take][:, None], weight=np.broadcast_to(weight, (batch, 1, 2 * K)))

    def solve(start, theta, weight, win):
        """Fit revolutions start … start + batch − 1 (the last batch repeats its last revolution)."""
        take = np.minimum(np.arange(start, start + batch), R - 1)
        return least_squares_batch(problems[win], theta, free, _arrays(take, weight), max_steps=REVOLUTION_MAX_STEPS,
                                   rtol=REVOLUTION_TOL, atol=REVOLUTION_TOL, warm_start=mode == "chain",
                                   method="gauss_newton"), take

    def fit_batch(start, theta, weight):
        res, take = solve(start, theta, weight, window)
        patch = reference.curves.patch_at(res.values(LOAD))
        win = window
        if window < settings.window_deg and np.any(np.maximum(np.abs(patch["leading_deg"]),
                                                              np.abs(patch["trailing_deg"])) > window - 1.5):
            win = settings.window_deg
            res, take = solve(start, res.theta[0] if mode == "chain" else res.theta, weight, win)
        n = min(batch, R - start)
        for b in np.flatnonzero(~(res.converged[:n] & np.all(np.isfinite(res.theta[:n]), axis=1))):
            # Gauss–Newton did not settle: Levenberg–Marquardt from the reference, this revolution alone (the
            # averaged profile's compiled fit: same model, free set padded to its size)
            alone = dataclasses.replace(problems[settings.window_deg],
                                        data=as_traced(jax.tree.map(lambda x: x[b], _arrays(take, weight))))
            one = least_squares(alone, theta_ref, free, max_steps=settings.max_steps, rtol=settings.rtol,
                                atol=settings.atol, pad_to=len(fit.names))
            res.theta[b], res.status[b], res.iterations[b] = one.theta, one.status, one.iterations
            res.covariance_log[b], res.stderr[b] = one.covariance_log, [one.stderr[k] for k in free]
            res.residuals[b], res.chi2_raw[b] = one.residuals, one.extra["chi2_raw"]
            res.sigma_scale[b], res.aux[b] = one.extra["sigma_scale"], np.asarray(one.extra["aux"])
            res.at_bound[b] = [k in one.extra["at_bound"] for k in free]
        return res, take

    # weights from the first batch's residual spectrum
    theta_ref = np.asarray(fit.theta, dtype=np.float64).copy()
    first, take = fit_batch(0, theta_ref, np.ones(2 * K))
    n0 = min(batch, R)
    sigma = smoothed_noise(np.sqrt(np.mean((first.aux[:n0, 0] - rows_all[take[:n0]]) ** 2, axis=0)))
    weight = (1.0 / sigma) / np.mean(1.0 / sigma)

    starts = np.arange(0, R, batch)
    bar = tqdm(total=R, unit="rev", disable=not progress, desc="per-revolution fits")
    results = {}
    theta = theta_ref
    for start in starts:
        res, _ = fit_batch(int(start), theta, weight)
        n = min(batch, R - int(start))
        # a revolution whose load or gain sits on its bound did not find an optimum inside the model's range
        on_bound = res.at_bound[:n][:, [free.index(LOAD), free.index(GAIN)]].any(axis=1)
        ok = res.converged[:n] & ~on_bound & np.all(np.isfinite(res.theta[:n]), axis=1)
        if ok.any():
            theta = res.theta[np.flatnonzero(ok)[-1]].copy()
        results[int(start)] = (res, n, ok)
        bar.update(n)
    bar.close()
    parts = []
    for start in starts:
        res, n, ok = results[int(start)]
        lo, hi = res.interval(LOAD)
        resid = res.aux[:n, 0] - rows_all[start:start + n]
        parts.append(dict(load=res.values(LOAD)[:n], lo=lo[:n], hi=hi[:n], gain=res.values(GAIN)[:n],
                          offset=np.degrees(res.values(ANGLE_OFFSET)[:n]),
                          rms=np.sqrt(0.5 * np.sum(resid[:, :K] ** 2 + resid[:, K:] ** 2, axis=1)), ok=ok,
                          iterations=res.iterations[:n]))
    cat = {key: np.concatenate([r[key] for r in parts]) for key in parts[0]}
    spacing = edge_peaks(rows_all[:, :K] + 1j * rows_all[:, K:], 2)[:, 2]
    return RevolutionEstimates(
        revolution=data.revolution, t_s=data.t_s, rotation_hz=data.rotation_hz, load_n=cat["load"], lo=cat["lo"],
        hi=cat["hi"], length_mm=np.asarray(reference.curves.patch_at(cat["load"])["length_mm"]), gain=cat["gain"],
        angle_offset_deg=cat["offset"], rms=cat["rms"], converged=cat["ok"], iterations=cat["iterations"],
        feature_load_n=reference.curves.load_from_spacing(spacing), window_deg=window)


def estimate_recording(record, geometry: TyreGeometry, ring: RingParams, *,
                       settings: EstimateSettings = EstimateSettings(), k_tread_in_file: bool = True,
                       per_revolution: bool = True, batch: int = REVOLUTION_BATCH, mode: str = "batch",
                       progress: bool = False):
    """The averaged and the per-revolution estimates of a continuous recording (one pass over it).

    The averaged profile (:func:`recording_revolutions`) is estimated like any profile
    (:func:`estimate_load`; Ω the encoder's mean rate, noise the revolution spread); its nuisances then
    serve every revolution (:func:`estimate_revolutions`).

    **Returns:** ``(LoadEstimate, RevolutionEstimates or None)``.
    """
    data = recording_revolutions(record, k_max=settings.k_max, progress=progress)
    rate = float(np.mean(data.rotation_hz))
    reference = estimate_load(data.profile, geometry, ring, settings=settings, k_tread_in_file=k_tread_in_file,
                              omega=2 * math.pi * rate, omega_source=data.rotation_source,
                              response=data.response, noise_per_angle=data.noise,
                              noise_source="differences of successive revolutions / √(2·revolutions), in the fitted band")
    revs = None
    if per_revolution:
        revs = estimate_revolutions(data, reference, ring, settings=settings, batch=batch, mode=mode,
                                    progress=progress)
    return reference, revs


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


__all__ = [
    "estimate_load", "estimate_revolutions", "estimate_recording", "recording_revolutions", "RevolutionEstimates",
    "RecordingRevolutions", "LoadEstimate", "EstimateSettings", "EstimateResiduals", "EstimateArrays", "estimate_problem",
    "load_curves", "LoadCurves", "feature_estimate", "FeatureEstimate", "edge_peaks", "harmonic_amplitudes",
    "harmonic_rows", "band_signal", "PARAMETERS", "COORDS", "LOAD_RANGE", "DEFAULT_K_TREAD_SD",
]
