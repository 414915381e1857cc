"""Time records — ``*.records.npz`` (docs/formats.md §4), and the dispatch by suffix to UFF58 and rig files (§17).

Impact (hammer) or cleat tests with one roving or co-rotating sensor. A
:class:`Records` holds the arrays of docs/formats.md §4 with validated shapes and
units; :func:`read_records` / :func:`write_records` read and write the npz
form and hand ``.uff``/``.unv`` files to :mod:`ringfit.io.uff` (which may also
return measured FRFs, :class:`MeasuredFRF`) and ``.tdms``/``.mat``/``.csv``
files to :mod:`ringfit.io.rig`; :func:`write_records` writes all of them. The classes live in
:mod:`ringfit.io.record_types` and are re-exported here.

Array layout follows the file: ``acc`` is ``(records, axes, samples)``.
The algorithms of :mod:`ringfit.targets` work on ``(channels, samples)``
matrices built from it by :meth:`Records.channels`.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.files import atomic_write, check_output_path, load_npz
from ringfit.io.record_types import AXES, MeasuredFRF, Records, validate_records
from ringfit.io.uff import read_uff, write_uff58

#: Suffixes read by :mod:`ringfit.io.uff`.
UFF_SUFFIXES = (".uff", ".unv")

__all__ = ["AXES", "MeasuredFRF", "Records", "read_records", "read_measurement", "validate_records",
           "write_records", "UFF_SUFFIXES"]


def read_measurement(path: str | os.PathLike, *, angles: dict | None = None,
                     axes: dict | None = None, channels: str | os.PathLike | None = None) -> Records | MeasuredFRF:
    """Time records or measured FRFs from ``*.records.npz`` (docs/formats.md §4), UFF58 (``.uff``/``.unv``)
    or a rig file — NI TDMS (``.tdms``), MATLAB ``.mat`` (v5, v7.3) or CSV (``.csv``), docs/formats.md §17.

    **Arguments:** ``angles`` — node number -> sensor angle [deg] and ``axes`` —
    UFF direction code -> axis name, for UFF files that do not say it
    themselves (see :func:`ringfit.io.uff.read_uff`); ``channels`` — a
    channel map TOML (:mod:`ringfit.io.channel_map`) for rig files that lack
    channel metadata. Each applies to its formats only: giving it for another
    is an error rather than silently ignored.

    **Returns:** :class:`Records` (time data) or :class:`MeasuredFRF` (UFF function type 4).
    """
    from ringfit.io.rig import read_rig_records, rig_format

    path = Path(path)
    suffix = path.suffix.lower()
    if channels is not None and rig_format(path) is None:
        raise InputError("--channels applies to TDMS, .mat and CSV files; an .npz or UFF file describes its own "
                         "channels", source=path)
    if suffix in UFF_SUFFIXES:
        return read_uff(path, angles=angles, axes=axes)
    if angles or axes:
        raise InputError("--angles and --axes apply to UFF files only; give a rig file's sensor angles and axes with "
                         "--channels MAP.toml; an .npz names its own", source=path)
    if rig_format(path) is not None:
        return read_rig_records(path, channels)
    data = load_npz(path)
    keys = set(data)
    for key in ("acc", "axes", "sensor_angle_deg", "fs_hz"):
        if key not in keys:
            raise InputError(f"missing key {key!r} (have: {', '.join(sorted(keys)) or 'none'})", source=path)
    return Records(
        acc=data["acc"],
        axes=tuple(str(x) for x in np.atleast_1d(data["axes"]).tolist()),
        sensor_angle_deg=data["sensor_angle_deg"],
        fs_hz=data["fs_hz"],
        force=data["force"] if "force" in keys else None,
        source=str(path),
    )


def read_records(path: str | os.PathLike, *, angles: dict | None = None, axes: dict | None = None,
                 channels: str | os.PathLike | None = None) -> Records:
    """Read time records: ``*.records.npz`` (docs/formats.md §4), a UFF type-58 file (``.uff``/``.unv``), or a
    TDMS, .mat or CSV rig file (§17; ``channels``: its channel map).

    **Raises** :class:`InputError` for a missing, truncated or corrupted file,
    a missing key, bad shape, unknown axis, non-finite or implausible value, a
    non-positive sample rate, or a UFF file that holds FRFs instead of time
    records (read those with :func:`read_measurement`).
    """
    out = read_measurement(path, angles=angles, axes=axes, channels=channels)
    if isinstance(out, MeasuredFRF):
        raise InputError("holds measured FRFs (UFF function type 4), not time records; "
                         "`ringfit frf` reads them, SSI needs time records", source=path)
    return out


def write_records(records: Records, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``records`` as ``.npz`` (docs/formats.md §4), as UFF type 58 (``.uff``/``.unv``), TDMS (``.tdms``)
    or MATLAB v5 (``.mat``), by suffix (§17).

    Refuses to overwrite an existing file unless ``overwrite``; writes atomically.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in UFF_SUFFIXES:
        return write_uff58(records, path, overwrite=overwrite)
    if suffix == ".tdms":
        from ringfit.io.tdms import write_tdms_records

        return write_tdms_records(records, path, overwrite=overwrite)
    if suffix == ".mat":
        from ringfit.io.matlab import write_mat_records

        return write_mat_records(records, path, overwrite=overwrite)
    if suffix == ".csv":
        raise ValueError("CSV records need their channel map: use ringfit.io.csv_records.write_csv_records")
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
