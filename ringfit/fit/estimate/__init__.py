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
- **Weights.** The profile block's noise model (:func:`ringfit.fit.profile_block.fit_profile_block`, the same
  passes as ``fit-rolling`` and ``identify``): each harmonic weighted by 1/σ_k from the fit's residual spectrum
  (a power law, the ±4 neighbouring harmonics' average, ν/(ν − 4) and the fit's degrees of freedom), refitted.
  Periodic stationary noise has independent Fourier coefficients, so coloured noise is whitened and the
  Laplace interval holds for it too (docs/physics.md §10, §11 *profile noise*).

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

**Modules** (one concern each; every name below is importable from ``ringfit.fit.estimate``):

| module | concern |
|---|---|
| :mod:`~ringfit.fit.estimate.harmonics` | revolution harmonics of a grid signal, residual rows, the noise spectrum |
| :mod:`~ringfit.fit.estimate.problem` | parameters, coordinates, priors, settings, data arrays, residuals, the engine problem |
| :mod:`~ringfit.fit.estimate.feature` | the classic edge-peak method |
| :mod:`~ringfit.fit.estimate.curves` | the model at a grid of loads (patch and edge-peak spacing against load) |
| :mod:`~ringfit.fit.estimate.load` | the estimate of one profile (:func:`estimate_load`, :class:`LoadEstimate`) |
| :mod:`~ringfit.fit.estimate.revolutions` | a continuous recording, averaged and revolution by revolution |
| :mod:`~ringfit.fit.estimate.state` | the tyre's state (load, pressure, slip and Fx, tread depth, speed), per revolution, its Fisher information (docs/physics.md §13) |
"""

from ringfit.fit.estimate.harmonics import (NOISE_SMOOTHING, band_signal, grid_signal, harmonic_amplitudes,
                                            amplitude_rows, smoothed_noise)
from ringfit.fit.estimate.problem import (ANGLE_OFFSET, COORDS, CORNER, GAIN, GAIN_RANGE, K_TREAD, LOAD, LOAD_RANGE,
                                          PARAMETERS, TILT, EstimateArrays, EstimateResiduals, EstimateSettings,
                                          estimate_problem, nuisance_priors)
from ringfit.fit.profile_block import CORNER_PRIOR, TILT_PRIOR  # the sensor's priors, one for every reader
from ringfit.fit.estimate.feature import PEAK_GRID, PEAK_SEARCH_DEG, FeatureEstimate, edge_peaks, feature_estimate
from ringfit.fit.estimate.curves import LoadCurves, load_curves
from ringfit.fit.estimate.load import (DEFAULT_K_TREAD_SD, MODEL_FLOOR, OFFSET_WARN_DEG, POOR_FIT_RATIO, LoadEstimate,
                                       check_sign, estimate_load, profile_amplitudes, rotation_from_profile)
from ringfit.fit.estimate.revolutions import (REVOLUTION_BATCH, REVOLUTION_MAX_STEPS, REVOLUTION_TOL,
                                              RecordingRevolutions, RevolutionEstimates, estimate_recording,
                                              estimate_revolutions, first_rotation_hz, recording_revolutions)
from ringfit.fit.estimate.state import (QUANTITIES, STATE_PARAMETERS, StateEstimate, StateFisher, StateRevolutions,
                                        estimate_state, state_fisher, state_problem, state_revolutions)

__all__ = [
    "estimate_load", "estimate_revolutions", "estimate_recording", "recording_revolutions", "RevolutionEstimates",
    "RecordingRevolutions", "LoadEstimate", "EstimateSettings", "EstimateResiduals", "EstimateArrays", "estimate_problem",
    "load_curves", "LoadCurves", "feature_estimate", "FeatureEstimate", "edge_peaks", "harmonic_amplitudes",
    "amplitude_rows", "band_signal", "PARAMETERS", "COORDS", "LOAD_RANGE", "DEFAULT_K_TREAD_SD",
]
# the state estimate's names (ringfit.fit.estimate.state) are importable from here too; __all__ keeps the load
# estimate's (tests/test_estimate.py pins it to the names of the old module)
