"""Pre-processing of roving-sensor impact records as the source study did it (seed §4.2–4.3).

- :func:`impact_indices` — the hammer impact in each record: first sample
  where the force reaches ``threshold`` × its peak.
- :func:`align_on_impact` — cut every record so that sample 0 is the impact,
  removing a user-set delay between the force and acceleration channels
  (the source measured it by striking the accelerometer with the hammer).
- :func:`drop_after_impact` — drop the first ``skip_s`` after the impact
  (default 0.0127 s = 324 samples at 25.6 kHz) so SSI sees free decay.
- Without a force channel: :func:`round_trip_time` estimates t_cycle from a
  record near the impact point (the impulse passes it once per round trip),
  :func:`group_velocity` gives ``v_g = 2πR / t_cycle`` (seed eq. 21), and
  :func:`sync_by_group_velocity` aligns every record on its largest
  acceleration, then shifts it back by the travel time of the impulse along
  the shorter arc ``R·|θ|`` from the impact point: ``t = R|θ| / v_g``.

Arrays: ``acc`` ``(records, axes, samples)`` as in the file; the result is the
same layout with a common length.
"""

from __future__ import annotations

import numpy as np

from ringfit.errors import InputError
from ringfit.io.records import Records

#: Seed §4.3: first 0.0127 s after the impact removed (324 samples at 25.6 kHz).
SKIP_AFTER_IMPACT_S = 0.0127


def check_band(records: Records, f_max_hz: float) -> None:
    """The top of the band of interest must lie below the records' Nyquist frequency."""
    if not 0 < f_max_hz < records.fs_hz / 2:
        raise InputError(f"band top {f_max_hz:g} Hz is not below the records' Nyquist frequency "
                         f"{records.fs_hz / 2:g} Hz", source=records.source)


def check_angles(angle_deg, source=None) -> None:
    """The records must hold at least three sensor angles (modulo 360°): the circumferential order n of a mode
    is read from how its shape changes round the tyre, by harmonics up to (angles − 1)/2
    (:func:`~ringfit.targets.shapes.max_harmonic`); with one or two angles every mode would read n = 0.

    **Raises** :class:`InputError` naming the angles found.
    """
    a = np.asarray(angle_deg, dtype=np.float64)
    found = np.unique(np.round(np.mod(a, 360.0), 9) % 360.0)
    if not a.size or found.size >= 3:
        return
    tail = ("the circumferential order n of a mode cannot be told from {}; expected records at three or more "
            "angles round the tyre (the sensor angles in the file, or angle_deg in the channel map)")
    if found.size == 1:
        raise InputError(f"every record ({a.size}) is at the one sensor angle {float(a[0]):g}°: "
                         + tail.format("a single angle"), source=source)
    raise InputError(f"the records ({a.size}) hold only two sensor angles, {found[0]:g}° and {found[1]:g}°: "
                     + tail.format("two (every mode would read n = 0)"), source=source)


def impact_indices(force: np.ndarray, threshold: float = 0.1) -> np.ndarray:
    """Index of the first sample with ``|F| ≥ threshold · max|F|`` in each record.

    **Arguments:** ``force`` (records, samples) [N]; ``threshold`` in (0, 1].

    **Returns:** int array (records,).
    """
    if not 0 < threshold <= 1:
        raise InputError(f"force threshold {threshold}; expected a fraction of the peak in (0, 1]")
    f = np.abs(np.asarray(force, dtype=np.float64))
    peak = f.max(axis=1, keepdims=True)
    if (peak <= 0).any():
        raise InputError(f"record {int(np.argmin(peak[:, 0]))}: force channel is all zero; no impact found")
    return np.argmax(f >= threshold * peak, axis=1)


def _cut(acc: np.ndarray, start: np.ndarray, pre: int = 0) -> np.ndarray:
    """acc[r, :, start_r - pre : start_r - pre + L] with the largest common L."""
    start = np.asarray(start, dtype=np.int64) - pre
    if (start < 0).any():
        raise InputError(f"record {int(np.argmin(start))}: the impact lies too close to the start of the record")
    length = int(acc.shape[-1] - start.max())
    if length < 2:
        raise InputError("records too short after alignment")
    return np.stack([acc[r, :, s:s + length] for r, s in enumerate(start)])


def align_on_impact(
    records: Records, *, threshold: float = 0.1, delay_s: float = 0.0, pre_s: float = 0.0
) -> tuple[np.ndarray, np.ndarray | None]:
    """Align records on the hammer impact (force threshold) and remove the force/acc delay.

    **Arguments:**

    - ``threshold``: impact = first sample with |F| ≥ threshold · peak.
    - ``delay_s``: the acceleration channels lag the force by this [s]; removed.
    - ``pre_s``: keep this much [s] before the impact (for FRF windows).

    **Returns:** ``(acc, force)``: acc ``(records, axes, samples)`` with the
    impact at sample ``round(pre_s·fs)``, force ``(records, samples)`` aligned the same way.
    """
    if records.force is None:
        raise InputError("no force channel; use sync_by_group_velocity for records without force", source=records.source)
    fs = records.fs_hz
    idx = impact_indices(records.force, threshold)
    pre = int(round(pre_s * fs))
    delay = int(round(delay_s * fs))
    force = _cut(records.force[:, None, :], idx, pre)[:, 0]
    acc = _cut(records.acc, idx + delay, pre)
    n = min(acc.shape[-1], force.shape[-1])
    return acc[..., :n], force[:, :n]


def drop_after_impact(acc: np.ndarray, fs_hz: float, skip_s: float = SKIP_AFTER_IMPACT_S, impact_index: int = 0) -> np.ndarray:
    """Drop the samples up to ``skip_s`` after the impact (seed §4.3), last axis = samples."""
    start = impact_index + int(round(skip_s * fs_hz))
    if start >= acc.shape[-1] - 1:
        raise InputError(f"skip of {skip_s} s leaves no samples")
    return acc[..., start:]


def round_trip_time(signal: np.ndarray, fs_hz: float, t_min: float = 2e-3, t_max: float = 0.1) -> float:
    """Round-trip time t_cycle [s] of the impulse, from the record at the impact point.

    The impulse passes the impact point once per round trip (both waves meet
    there again), so the envelope repeats with period t_cycle: the first
    maximum of the envelope's autocorrelation in ``[t_min, t_max]``.

    **Arguments:** ``signal`` (samples,) or (axes, samples) [m/s²].
    """
    from scipy.signal import hilbert

    x = np.atleast_2d(np.asarray(signal, dtype=np.float64))
    env = np.abs(hilbert(x - x.mean(axis=-1, keepdims=True), axis=-1)).sum(axis=0)
    env = env - env.mean()
    n = env.size
    spec = np.fft.rfft(env, 2 * n)
    ac = np.fft.irfft(np.abs(spec) ** 2)[:n]
    lo, hi = max(int(np.ceil(t_min * fs_hz)), 1), min(int(t_max * fs_hz), n - 2)
    if hi <= lo + 2:
        raise InputError(f"cannot find the impulse's round-trip time ({t_min * 1e3:g}-{t_max * 1e3:g} ms) in "
                         f"{n} samples at {fs_hz:g} Hz; expected a longer record sampled above {3 / t_max:g} Hz, "
                         "or a force channel")
    k = lo + int(np.argmax(ac[lo:hi]))
    if 0 < k < n - 1:  # parabolic refinement
        a, b, c = ac[k - 1], ac[k], ac[k + 1]
        den = a - 2 * b + c
        k = k + (0.5 * (a - c) / den if den != 0 else 0.0)
    return float(k / fs_hz)


def group_velocity(radius_m: float, t_cycle_s: float) -> float:
    """``v_g = 2πR / t_cycle`` [m/s] (seed eq. 21, docs/physics.md §3.5)."""
    if not (np.isfinite(t_cycle_s) and t_cycle_s > 0):
        raise InputError(f"round-trip time {t_cycle_s!r} s: expected a positive time to derive the group velocity")
    return 2 * np.pi * radius_m / t_cycle_s


def sync_by_group_velocity(
    records: Records, radius_m: float, *, t_cycle_s: float | None = None, pre_s: float = 0.0
) -> tuple[np.ndarray, float]:
    """Synchronise records without a force channel (seed §4.2).

    Each record is first aligned on its largest |acceleration| (the first
    pass of the impulse), then shifted back by the travel time
    ``R·|θ| / v_g`` along the shorter arc from the impact point, with
    ``v_g = 2πR / t_cycle`` (eq. 21); t_cycle from :func:`round_trip_time` on
    the record closest to the impact point unless given.

    **Returns:** ``(acc, t_cycle_s)``, acc ``(records, axes, samples)`` with the
    (estimated) impact at sample ``round(pre_s·fs)``.
    """
    fs = records.fs_hz
    acc = records.acc
    if t_cycle_s is None:
        near = int(np.argmin(np.abs(_wrap_deg(records.sensor_angle_deg))))
        try:
            t_cycle_s = round_trip_time(acc[near], fs)
        except InputError as exc:
            raise InputError(f"group-velocity sync: {exc}", source=records.source) from None
    try:
        v_g = group_velocity(radius_m, t_cycle_s)
    except InputError as exc:
        raise InputError(f"group-velocity sync: {exc}", source=records.source) from None
    arc = radius_m * np.abs(np.deg2rad(_wrap_deg(records.sensor_angle_deg)))
    peak = np.argmax(np.abs(acc).max(axis=1), axis=1)
    start = peak - np.round(arc / v_g * fs).astype(np.int64)
    return _cut(acc, start, int(round(pre_s * fs))), float(t_cycle_s)


def _wrap_deg(a):
    return (np.asarray(a, dtype=np.float64) + 180.0) % 360.0 - 180.0
