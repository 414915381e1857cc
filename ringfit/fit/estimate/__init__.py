"""Wheel load, contact patch and the tyre's state from the one accelerometer (docs/physics.md §10, §13;
docs/formats.md §7).

With the ring identified (a fitted tyre file, held fixed), the steady rolling model
(:func:`ringfit.physics.profile.profile_channels`, the one forward model) is inverted for the load Fz (and, in
:mod:`~ringfit.fit.estimate.state`, pressure, slip and Fx, tread depth and speed) that the sensor's profile shows.
The rows are the radial harmonics 2 … k_max weighted by the profile block's noise model; gain, high-pass corner,
tilt and angle offset are nuisances; the interval is the engine's Laplace approximation with the tyre's
``[ring.covariance]`` carried into it. Why each of these choices, and what they cost, is docs/physics.md §10. This
package is a *problem definition on the one engine* (:mod:`ringfit.fit.engine`): residuals, coordinates and
procedure, no solver of its own.

Example (a profile of ``ringfit example profiles --out ex``, read with its tyre file; docs/formats.md §3)::

    from ringfit.fit.estimate import estimate_load
    from ringfit.io.profiles import read_profile
    from ringfit.io.tyre import read_tyre

    tyre = read_tyre("ex/tyre.toml")
    est = estimate_load(read_profile("ex/run30.profile.csv"), tyre.geometry, tyre.ring)
    print(est.load_n, (est.lo, est.hi), est.status)   # the load [N], its 95 % interval, the solver's status

Per revolution of a continuous recording: :func:`estimate_recording` (the averaged profile, then each revolution
with the nuisances held at its fit, batched by :func:`ringfit.fit.engine.least_squares_batch`).

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
