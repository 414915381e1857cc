"""CSV time records with a header row (docs/formats.md §17.3).

One column per channel, one row per sample, comma-separated; lines starting
with ``#`` before the header are comments. A header cell is the channel's
name with an optional unit in brackets or parentheses: ``radial [g]``,
``force (N)``. A column named ``time``, ``time_s`` or ``t`` (unit ``s`` or
``ms``, default s) gives the sample rate and must be evenly spaced; without
one, ``fs_hz`` comes from the channel map. Channels are described by their
names (``radial``, ``force``, ``encoder_angle_deg``, ``hall``, …) or by the
channel map, keyed by the name without its unit.

:func:`write_csv_records` writes impact records as ``time [s]``,
``r000_radial [m/s^2]``, …, ``r000_force [N]`` columns (17 significant
digits: an exact round trip) and returns the channel map that places them.
"""

from __future__ import annotations

import csv
import io
import os
import re
import warnings
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.channel_map import ChannelMap, ChannelSpec
from ringfit.io.files import atomic_write, check_output_path, existing_file
from ringfit.io.record_types import Records
from ringfit.io.rig_types import RawChannel, RigFile

TIME_NAMES = ("time", "time_s", "t")
_TIME_UNITS = {"s": 1.0, "sec": 1.0, "ms": 1e-3}
_HEADER = re.compile(r"^\s*(.*?)\s*(?:[\[(]\s*([^\])]*?)\s*[\])])?\s*$")
#: Relative tolerance on the spacing of a time column (CSV text keeps ~10+ digits).
TIME_TOL = 1e-4


def _split_header(cell: str) -> tuple[str, str | None]:
    m = _HEADER.match(cell)
    name, unit = m.group(1), m.group(2)
    return name, (unit if unit else None)


def read_csv_channels(path: str | os.PathLike) -> RigFile:
    """The columns of a CSV file as channels (module docstring); InputError naming file, row and column."""
    path = existing_file(Path(path), "a CSV file")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"not a readable text file ({exc.__class__.__name__})", source=path) from None
    lines = text.splitlines()
    start = 0
    while start < len(lines) and (not lines[start].strip() or lines[start].lstrip().startswith("#")):
        start += 1
    if start >= len(lines):
        raise InputError("no header row (empty file?)", source=path)
    header = next(csv.reader([lines[start]]))
    names, units = zip(*(_split_header(c) for c in header))
    if any(not n for n in names):
        raise InputError(f"row {start + 1}: column {names.index('') + 1} has an empty name", source=path)
    dup = [n for n in names if names.count(n) > 1]
    if dup:
        raise InputError(f"row {start + 1}: column name {dup[0]!r} appears twice", source=path)
    if _is_number(names[0]):
        raise InputError(f"row {start + 1}: the first row is numbers; expected a header row of channel names",
                         source=path)
    body = "\n".join(lines[start + 1:])
    if not any(line.strip() and not line.lstrip().startswith("#") for line in lines[start + 1:]):
        raise InputError(f"row {start + 1} is a header and no data rows follow; expected a time history (one row per "
                         "sample)", source=path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # loadtxt's own words name a StringIO, not the file
            data = np.loadtxt(io.StringIO(body), delimiter=",", ndmin=2, dtype=np.float64, comments="#")
    except ValueError:
        data = None
    if data is None or data.shape[1] != len(names):
        _find_bad_row(lines, start, names, path)
        raise InputError("unreadable numbers", source=path)  # pragma: no cover - _find_bad_row raises
    if data.shape[0] < 2:
        raise InputError(f"{data.shape[0]} data row(s); expected a time history", source=path)
    bad = ~np.isfinite(data)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise InputError(f"row {_data_row(lines, start, i)}, column {names[j]!r}: non-finite value", source=path)
    rig = RigFile(source=str(path), format="csv")
    fs = None
    for j, (name, unit) in enumerate(zip(names, units)):
        if name.lower() in TIME_NAMES:
            fs, gaps = _time_rate(data[:, j], unit, name, lines, start, path)
            if gaps:
                rig.gaps = [(i, m) for i, m, _ in gaps]
                rig.notes.append(f"dropped samples: the time column {name!r} jumps by more than one step at "
                                 f"{len(gaps)} row(s) (first at row {gaps[0][2]}): {sum(m for _, m, _ in gaps)} "
                                 "samples missing, filled by straight lines on the even time grid")
            continue
        rig.channels.append(RawChannel(name=name, short=name, data=data[:, j].copy(), unit=unit))
    if fs is not None:
        rig.props["fs_hz"] = fs
    if not rig.channels:
        raise InputError("no channel columns besides time", source=path)
    return rig


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _data_row(lines, start, i) -> int:
    """1-based line number of data row i (comments and blank lines skipped as loadtxt does)."""
    k = -1
    for n in range(start + 1, len(lines)):
        s = lines[n].strip()
        if s and not s.startswith("#"):
            k += 1
            if k == i:
                return n + 1
    return len(lines)


def _find_bad_row(lines, start, names, path):
    for n in range(start + 1, len(lines)):
        s = lines[n].strip()
        if not s or s.startswith("#"):
            continue
        cells = next(csv.reader([s]))
        if len(cells) != len(names):
            raise InputError(f"row {n + 1}: {len(cells)} fields; the header has {len(names)}", source=path)
        for c, name in zip(cells, names):
            try:
                float(c)
            except ValueError:
                raise InputError(f"row {n + 1}, column {name!r}: {c.strip()!r} is not a number", source=path) from None


#: Dropped samples (whole rows missing: the time column jumps by a whole number of steps) are filled when they
#: are at most this share of the samples and no gap is longer than :data:`MAX_DROPPED_RUN` samples; more is refused.
MAX_DROPPED_SHARE = 0.02
MAX_DROPPED_RUN = 8


def _time_rate(t, unit, name, lines, start, path):
    """``(fs_hz, gaps)``: the rate of an evenly spaced time column, and its dropped samples as ``[(i, missing,
    line)]`` — after data row ``i`` the column jumps by ``missing + 1`` steps (``line`` its line in the file)."""
    scale = _TIME_UNITS.get((unit or "s").strip().lower())
    if scale is None:
        raise InputError(f"column {name!r}: time unit {unit!r}; expected s or ms", source=path)
    t = t * scale
    d = np.diff(t)
    step = float(np.median(d))
    if not step > 0:
        raise InputError(f"column {name!r}: time does not increase", source=path)
    k = np.rint(d / step)
    whole = (k >= 1) & (np.abs(d - k * step) <= TIME_TOL * k * step)
    gaps = np.flatnonzero(whole & (k >= 2))
    missing = int(np.sum(k[gaps] - 1))
    if whole.all() and missing <= MAX_DROPPED_SHARE * t.size and (k[gaps] - 1 <= MAX_DROPPED_RUN).all():
        return 1.0 / step, [(int(i), int(k[i] - 1), _data_row(lines, start, i + 1)) for i in gaps]
    i = int(np.argmax(~whole | (k - 1 > MAX_DROPPED_RUN))) + 1 if not whole.all() or gaps.size else 1
    if whole.all():
        raise InputError(f"column {name!r}: {missing} samples dropped in {gaps.size} gap(s) (the longest "
                         f"{int(k[gaps].max() - 1)} samples, first after row {_data_row(lines, start, int(gaps[0]))}); "
                         f"expected at most {100 * MAX_DROPPED_SHARE:g} % of the samples, {MAX_DROPPED_RUN} in a row",
                         source=path)
    raise InputError(f"row {_data_row(lines, start, i)}, column {name!r}: uneven time step {d[i - 1]:.6g} s "
                     f"(typical {step:.6g} s); expected evenly sampled records", source=path)


def write_csv_records(records: Records, path: str | os.PathLike, *, overwrite: bool = False) -> tuple[Path, ChannelMap]:
    """Write ``records`` as CSV (module docstring); returns the path and the channel map that reads it back."""
    path = check_output_path(path, overwrite=overwrite)
    cols, header, specs = [np.arange(records.n_samples) / records.fs_hz], ["time [s]"], {}
    for r in range(records.n_records):
        rec = f"r{r:03d}"
        angle = float(records.sensor_angle_deg[r])
        for a, axis in enumerate(records.axes):
            name = f"{rec}_{axis}"
            cols.append(records.acc[r, a])
            header.append(f"{name} [m/s^2]")
            specs[name] = ChannelSpec(name, "acc", axis=axis, angle_deg=angle, record=rec, unit="m/s^2")
        if records.force is not None:
            name = f"{rec}_force"
            cols.append(records.force[r])
            header.append(f"{name} [N]")
            specs[name] = ChannelSpec(name, "force", angle_deg=angle, record=rec, unit="N")
    table = np.column_stack(cols)

    def write(tmp: Path):
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(",".join(header) + "\n")
            np.savetxt(fh, table, delimiter=",", fmt="%.17g")

    atomic_write(path, write)
    return path, ChannelMap(channels=specs, top={"fs_hz": float(records.fs_hz)}, source=str(path))
