"""Time records — ``*.records.npz`` (DATA.md §4).

Impact (hammer) or cleat tests with one roving or co-rotating sensor. A
:class:`Records` holds the arrays of DATA.md §4 with validated shapes and
units; :func:`read_records` / :func:`write_records` read and write the npz
form and dispatch to :mod:`ringfit.io.uff` for Universal File Format type 58
(``.uff``/``.unv``).

Array layout follows the file: ``acc`` is ``(records, axes, samples)``.
The algorithms of :mod:`ringfit.targets` work on ``(channels, samples)``
matrices built from it by :meth:`Records.channels`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.files import atomic_write, check_output_path, load_npz

#: Allowed sensor axes (DATA.md §4). Sign convention of ``radial``: positive toward the wheel centre.
AXES = ("radial", "tangential", "lateral")
#: Suffixes read by :mod:`ringfit.io.uff`.
UFF_SUFFIXES = (".uff", ".unv")


@dataclass
class Records:
    """Impact records of one roving sensor (DATA.md §4).

    **Fields:**

    - ``acc``: acceleration [m/s²], shape ``(records, axes, samples)``.
    - ``axes``: tuple of axis names, each one of :data:`AXES`, length ``axes``.
    - ``sensor_angle_deg``: sensor position [deg] from the excitation point, shape ``(records,)``.
    - ``fs_hz``: sample rate [Hz].
    - ``force``: hammer force [N], shape ``(records, samples)``, or ``None``.
    - ``source``: where the records came from, for messages.
    """

    acc: np.ndarray
    axes: tuple[str, ...]
    sensor_angle_deg: np.ndarray
    fs_hz: float
    force: np.ndarray | None = None
    source: str = field(default="<records>")

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
    fs = np.asarray(rec.fs_hz)
    if fs.size != 1:
        raise InputError(f"key 'fs_hz' has shape {fs.shape}; expected a scalar", source=src)
    try:
        fs = float(fs.reshape(()))
    except (TypeError, ValueError):
        raise InputError("key 'fs_hz' is not a number", source=src) from None
    if not math.isfinite(fs) or fs <= 0:
        raise InputError(f"key 'fs_hz' = {fs}; expected a positive sample rate in Hz", source=src)
    force = rec.force
    if force is not None:
        force = np.asarray(force)
        if force.shape != (r, s):
            raise InputError(f"key 'force' has shape {force.shape}; expected (records, samples) = ({r}, {s})", source=src)
        force = force.astype(np.float64)
        bad = ~np.isfinite(force)
        if bad.any():
            i, k = np.argwhere(bad)[0]
            raise InputError(f"key 'force' has a non-finite value at record {i}, sample {k}", source=src)
    rec.acc, rec.axes, rec.sensor_angle_deg, rec.fs_hz, rec.force = acc, axes, angle, fs, force
    return rec


def read_records(path: str | os.PathLike) -> Records:
    """Read ``*.records.npz`` (DATA.md §4), or a UFF type-58 file (``.uff``/``.unv``).

    **Raises** :class:`InputError` for a missing file, missing key, bad shape,
    unknown axis, non-finite value or a non-positive sample rate.
    """
    path = Path(path)
    if path.suffix.lower() in UFF_SUFFIXES:
        from ringfit.io.uff import read_uff58

        return read_uff58(path)
    data = load_npz(path)
    with data:
        keys = set(data.files)
        for key in ("acc", "axes", "sensor_angle_deg", "fs_hz"):
            if key not in keys:
                raise InputError(f"missing key {key!r} (have: {', '.join(sorted(keys))})", source=path)
        return Records(
            acc=data["acc"],
            axes=tuple(str(x) for x in np.atleast_1d(data["axes"]).tolist()),
            sensor_angle_deg=data["sensor_angle_deg"],
            fs_hz=data["fs_hz"],
            force=data["force"] if "force" in keys else None,
            source=str(path),
        )


def write_records(records: Records, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``records`` as ``.npz`` (DATA.md §4) or, for ``.uff``/``.unv``, as UFF type 58.

    Refuses to overwrite an existing file unless ``overwrite``; writes atomically.
    """
    path = Path(path)
    if path.suffix.lower() in UFF_SUFFIXES:
        from ringfit.io.uff import write_uff58

        return write_uff58(records, path, overwrite=overwrite)
    path = check_output_path(path, overwrite=overwrite)
    payload = {
        "acc": records.acc,
        "axes": np.array(records.axes, dtype=str),
        "sensor_angle_deg": records.sensor_angle_deg,
        "fs_hz": np.float64(records.fs_hz),
    }
    if records.force is not None:
        payload["force"] = records.force

    def write(tmp: Path):
        with open(tmp, "wb") as fh:  # a file handle keeps numpy from appending '.npz' to the temp name
            np.savez(fh, **payload)

    atomic_write(path, write)
    return path
