"""The in-memory forms of docs/formats.md §4: impact :class:`Records` and measured :class:`MeasuredFRF`.

Both validate on construction (one-line :class:`~ringfit.errors.InputError`
naming the source and key). File formats live beside them:
:mod:`ringfit.io.records` (``*.records.npz`` and the dispatch by suffix) and
:mod:`ringfit.io.uff` (Universal File Format 58), which both import this
module, so the two never import each other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ringfit.errors import InputError

#: Optional scalar keys describing the test condition (same names as the profile sidecar, docs/formats.md §3),
#: shared by continuous recordings and rig files.
CONDITION_KEYS = ("speed_kmh", "load_n", "pressure_bar", "drum_diameter_m", "rotation_hz", "torque_nm", "tread_depth_mm")
#: Condition keys that may be negative (the axle torque: + driving, − braking; docs/physics.md §13).
SIGNED_CONDITION_KEYS = ("torque_nm",)

#: Allowed sensor axes (docs/formats.md §4). Sign convention of ``radial``: positive toward the wheel centre.
AXES = ("radial", "tangential", "lateral")
#: One sensor axis, as a type (:data:`AXES`).
Axis = Literal["radial", "tangential", "lateral"]
#: Highest sample rate accepted [Hz]; a value above is a unit slip or a corrupted file.
MAX_FS_HZ = 1.0e7
#: Largest |acceleration| accepted [m/s²] (10⁷ g, beyond any accelerometer).
MAX_ACC_MS2 = 1.0e8
#: Largest |force| accepted [N].
MAX_FORCE_N = 1.0e7
#: Sensor angles accepted [deg]: one turn either way of 0…360 (a wider value is a unit slip or a corrupted file).
ANGLE_RANGE_DEG = (-360.0, 720.0)
#: Largest |accelerance| accepted [m/s²/N].
MAX_ACCELERANCE = 1.0e8


@dataclass
class Records:
    """Impact records of one roving sensor (docs/formats.md §4).

    **Fields:**

    - ``acc``: acceleration [m/s²], shape ``(records, axes, samples)``.
    - ``axes``: tuple of axis names, each one of :data:`AXES`, length ``axes``.
    - ``sensor_angle_deg``: sensor position [deg] from the excitation point, shape ``(records,)``.
    - ``fs_hz``: sample rate [Hz].
    - ``force``: hammer force [N], shape ``(records, samples)``, or ``None``.
    - ``source``: where the records came from, for messages.
    - ``notes``: one-line findings of the reader (dropped samples filled, …), carried into a mode table's
      ``preprocessing`` list.
    """

    acc: np.ndarray
    axes: tuple[str, ...]
    sensor_angle_deg: np.ndarray
    fs_hz: float
    force: np.ndarray | None = None
    source: str = field(default="<records>")
    notes: list = field(default_factory=list, compare=False)

    def __post_init__(self):
        validate_records(self)

    @property
    def n_records(self) -> int:
        return self.acc.shape[0]

    @property
    def n_samples(self) -> int:
        return self.acc.shape[2]

    def channels(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The records as one ``(channels, samples)`` matrix, channel = (record, axis).

        **Returns:** ``(y, angle_rad, axis)`` with ``y`` of shape
        ``(records·axes, samples)`` [m/s²], ``angle_rad`` (channels,) the sensor
        angle [rad] and ``axis`` (channels,) the axis name of each channel.
        """
        r, a, s = self.acc.shape
        y = self.acc.reshape(r * a, s)
        angle = np.repeat(np.deg2rad(self.sensor_angle_deg), a)
        axis = np.tile(np.array(self.axes, dtype=object), r)
        return y, angle, axis


def validate_records(rec: Records) -> Records:
    """Check shapes, axes, sample rate and finite values in place (float64 copies).

    **Raises** :class:`InputError` with one line naming the source and the key.
    """
    src = rec.source
    acc = np.asarray(rec.acc)
    if acc.ndim != 3:
        raise InputError(f"key 'acc' has shape {acc.shape}; expected (records, axes, samples)", source=src)
    if not np.issubdtype(acc.dtype, np.number) or np.iscomplexobj(acc):
        raise InputError(f"key 'acc' has dtype {acc.dtype}; expected real numbers", source=src)
    acc = acc.astype(np.float64)
    r, a, s = acc.shape
    if r < 1 or a < 1 or s < 2:
        raise InputError(f"key 'acc' has shape {acc.shape}; expected at least 1 record, 1 axis, 2 samples", source=src)
    bad = ~np.isfinite(acc)
    if bad.any():
        i, j, k = np.argwhere(bad)[0]
        raise InputError(f"key 'acc' has a non-finite value at record {i}, axis {j}, sample {k}", source=src)
    big = np.abs(acc) > MAX_ACC_MS2
    if big.any():
        i, j, k = np.argwhere(big)[0]
        raise InputError(f"key 'acc' = {acc[i, j, k]:g} at record {i}, axis {j}, sample {k}: outside the plausible "
                         f"range ±{MAX_ACC_MS2:g} m/s² (a unit slip, or a corrupted file?)", source=src)
    axes = tuple(str(x) for x in np.atleast_1d(np.asarray(rec.axes)).tolist())
    if len(axes) != a:
        raise InputError(f"key 'axes' has {len(axes)} names but 'acc' has {a} axes", source=src)
    for name in axes:
        if name not in AXES:
            raise InputError(f"key 'axes': {name!r}; expected names from {list(AXES)}", source=src)
    if len(set(axes)) != len(axes):
        raise InputError(f"key 'axes' repeats a name: {list(axes)}", source=src)
    angle = np.asarray(rec.sensor_angle_deg)
    if angle.shape != (r,):
        raise InputError(f"key 'sensor_angle_deg' has shape {angle.shape}; expected ({r},)", source=src)
    try:
        angle = angle.astype(np.float64)
    except (TypeError, ValueError):
        raise InputError("key 'sensor_angle_deg' is not numeric", source=src) from None
    if not np.isfinite(angle).all():
        raise InputError(f"key 'sensor_angle_deg' has a non-finite value at record {int(np.argmin(np.isfinite(angle)))}", source=src)
    out = (angle < ANGLE_RANGE_DEG[0]) | (angle > ANGLE_RANGE_DEG[1])
    if out.any():
        i = int(np.argmax(out))
        raise InputError(f"key 'sensor_angle_deg' = {angle[i]:g} at record {i}; expected an angle in "
                         f"[{ANGLE_RANGE_DEG[0]:g}, {ANGLE_RANGE_DEG[1]:g}] degrees", source=src)
    fs = np.asarray(rec.fs_hz)
    if fs.size != 1:
        raise InputError(f"key 'fs_hz' has shape {fs.shape}; expected a scalar", source=src)
    try:
        fs = float(fs.reshape(()))
    except (TypeError, ValueError):
        raise InputError("key 'fs_hz' is not a number", source=src) from None
    if not math.isfinite(fs) or fs <= 0:
        raise InputError(f"key 'fs_hz' = {fs}; expected a positive sample rate in Hz", source=src)
    if fs > MAX_FS_HZ:
        raise InputError(f"key 'fs_hz' = {fs:g}; outside the plausible range (0, {MAX_FS_HZ:g}] Hz", source=src)
    force = rec.force
    if force is not None:
        force = np.asarray(force)
        if not np.issubdtype(force.dtype, np.number) or np.iscomplexobj(force):
            raise InputError(f"key 'force' has dtype {force.dtype}; expected real numbers", source=src)
        if force.shape != (r, s):
            raise InputError(f"key 'force' has shape {force.shape}; expected (records, samples) = ({r}, {s})", source=src)
        force = force.astype(np.float64)
        bad = ~np.isfinite(force)
        if bad.any():
            i, k = np.argwhere(bad)[0]
            raise InputError(f"key 'force' has a non-finite value at record {i}, sample {k}", source=src)
        big = np.abs(force) > MAX_FORCE_N
        if big.any():
            i, k = np.argwhere(big)[0]
            raise InputError(f"key 'force' = {force[i, k]:g} at record {i}, sample {k}: outside the plausible "
                             f"range ±{MAX_FORCE_N:g} N", source=src)
    rec.acc, rec.axes, rec.sensor_angle_deg, rec.fs_hz, rec.force = acc, axes, angle, fs, force
    return rec


@dataclass
class MeasuredFRF:
    """Measured frequency response functions of one roving sensor (e.g. UFF58 function type 4).

    **Fields:**

    - ``freq_hz``: frequency axis [Hz], shape ``(F,)``, evenly spaced, increasing, >= 0.
    - ``frf``: accelerance [m/s²/N], complex, shape ``(records, axes, F)``.
    - ``axes``: tuple of axis names (:data:`AXES`), length ``axes``.
    - ``sensor_angle_deg``: sensor position [deg] from the excitation point, shape ``(records,)``.
    - ``coherence``: ``(records, axes, F)`` in [0, 1], or ``None`` when the file has none.
    - ``source``: where they came from, for messages.
    """

    freq_hz: np.ndarray
    frf: np.ndarray
    axes: tuple[str, ...]
    sensor_angle_deg: np.ndarray
    coherence: np.ndarray | None = None
    source: str = field(default="<frf>")

    def __post_init__(self):
        src = self.source
        f = np.asarray(self.freq_hz, dtype=np.float64)
        h = np.asarray(self.frf)
        if h.ndim != 3 or f.ndim != 1 or h.shape[2] != f.size:
            raise InputError(f"FRFs of shape {h.shape} on {f.shape} frequencies; expected (records, axes, F) on (F,)",
                             source=src)
        if f.size < 2:
            raise InputError(f"{f.size} frequency line(s); expected at least 2", source=src)
        if not (np.isfinite(f).all() and f[0] >= 0 and (np.diff(f) > 0).all()):
            raise InputError("frequency axis is not finite, >= 0 and increasing", source=src)
        h = h.astype(np.complex128)
        if not np.isfinite(h).all():
            i, j, k = np.argwhere(~np.isfinite(h))[0]
            raise InputError(f"FRF of record {i}, axis {j} has a non-finite value at {f[k]:g} Hz", source=src)
        if (np.abs(h) > MAX_ACCELERANCE).any():
            raise InputError(f"an FRF exceeds ±{MAX_ACCELERANCE:g} m/s²/N; a unit slip or a corrupted file?", source=src)
        axes = tuple(str(a) for a in self.axes)
        if len(axes) != h.shape[1] or any(a not in AXES for a in axes) or len(set(axes)) != len(axes):
            raise InputError(f"axes {list(axes)} for {h.shape[1]} FRF axes; expected distinct names from {list(AXES)}",
                             source=src)
        angle = np.asarray(self.sensor_angle_deg, dtype=np.float64)
        if angle.shape != (h.shape[0],) or not np.isfinite(angle).all():
            raise InputError(f"sensor angles of shape {angle.shape}; expected {h.shape[0]} finite angles", source=src)
        if ((angle < ANGLE_RANGE_DEG[0]) | (angle > ANGLE_RANGE_DEG[1])).any():
            bad = float(angle[(angle < ANGLE_RANGE_DEG[0]) | (angle > ANGLE_RANGE_DEG[1])][0])
            raise InputError(f"sensor angle {bad:g}; expected angles in [{ANGLE_RANGE_DEG[0]:g}, "
                             f"{ANGLE_RANGE_DEG[1]:g}] degrees", source=src)
        if self.coherence is not None:
            c = np.asarray(self.coherence, dtype=np.float64)
            if c.shape != h.shape or not np.isfinite(c).all() or (c < 0).any() or (c > 1 + 1e-9).any():
                raise InputError("coherence must match the FRFs' shape and lie in [0, 1]", source=src)
            self.coherence = np.clip(c, 0.0, 1.0)
        self.freq_hz, self.frf, self.axes, self.sensor_angle_deg = f, h, axes, angle

    @property
    def n_records(self) -> int:
        return self.frf.shape[0]
