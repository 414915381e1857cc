"""Continuous recordings — ``*.records.npz`` with ``kind = "continuous"`` (docs/formats.md §4, extended).

A long recording of a rolling tyre: the co-rotating accelerometer's channels,
the rim encoder (absolute angle or incremental pulses) and, for cleat tests,
the hall sensor that marks each cleat arrival. The file is a §4 records file
with one record (``acc`` has shape ``(1, axes, samples)``) plus optional keys;
a §4 reader that ignores unknown keys still reads it. The extension is
documented in ``docs/records-continuous.md``.

Recordings are long (30 min at 25.6 kHz is 46 M samples a channel), so
:func:`read_continuous` never loads the big channels: members stored without
compression (what :func:`write_continuous` and :class:`ContinuousWriter`
write) are read in place by offset, compressed members are decompressed as a stream.
:meth:`ContinuousRecord.chunks` walks the recording in bounded pieces and
turns the encoder into the unwrapped sensor angle φ (degrees from the centre
of the contact patch, docs/physics.md §0) on the way.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.files import atomic_write, check_output_path, existing_file
from ringfit.io.record_types import AXES, CONDITION_KEYS, SIGNED_CONDITION_KEYS

KIND = "continuous"
#: Samples per chunk when walking a recording (8 MB per float64 channel).
DEFAULT_CHUNK = 1 << 20


# --------------------------------------------------------------------------- channel access


class _Channel:
    """One 1-D channel of a recording: ``read(start, stop)`` returns float64 samples."""

    def __init__(self, length: int):
        self.length = int(length)

    def read(self, start: int, stop: int) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def close(self) -> None:
        pass


class _ArrayChannel(_Channel):
    """A channel held by an in-memory array."""

    def __init__(self, array):
        super().__init__(array.shape[-1])
        self.array = array

    def read(self, start, stop):
        return np.asarray(self.array[start:stop], dtype=np.float64)


class _FileChannel(_Channel):
    """A row of an uncompressed npz member, read with plain file reads.

    (Not a memory map: mapped pages would count toward the process's resident
    memory; file reads keep only the chunk in memory and leave caching to the OS.)
    """

    def __init__(self, path, dtype, start_byte, length):
        super().__init__(length)
        self.fh = open(path, "rb")
        self.dtype = dtype
        self.start_byte = start_byte

    def read(self, start, stop):
        n = max(0, min(stop, self.length) - start)
        self.fh.seek(self.start_byte + start * self.dtype.itemsize)
        return np.fromfile(self.fh, dtype=self.dtype, count=n).astype(np.float64)

    def close(self):
        self.fh.close()


class _ZipStreamChannel(_Channel):
    """A row of a compressed npz member, decompressed as a forward-only stream."""

    def __init__(self, path, member, dtype, data_offset, row_offset, length):
        super().__init__(length)
        self.zf = zipfile.ZipFile(path)
        self.fh = self.zf.open(member)
        self.dtype = dtype
        self.start_byte = data_offset + row_offset * dtype.itemsize
        self.pos = 0  # next sample index the stream is positioned at
        self._skip(self.start_byte)

    def _skip(self, nbytes):
        while nbytes > 0:
            got = len(self.fh.read(min(nbytes, 1 << 24)))
            if got == 0:
                raise EOFError("truncated member")
            nbytes -= got

    def read(self, start, stop):
        if start < self.pos:  # rewind: reopen (rare; chunked walks go forward)
            self.fh.close()
            self.fh = self.zf.open(self.fh.name)
            self._skip(self.start_byte)
            self.pos = 0
        self._skip((start - self.pos) * self.dtype.itemsize)
        n = stop - start
        buf = self.fh.read(n * self.dtype.itemsize)
        self.pos = stop
        return np.frombuffer(buf, dtype=self.dtype, count=n).astype(np.float64)

    def close(self):
        self.fh.close()
        self.zf.close()


def _member_layout(path: Path, zf: zipfile.ZipFile, name: str):
    """(info, dtype, shape, fortran, data offset inside the member) of ``name.npy``."""
    info = zf.getinfo(name + ".npy")
    with zf.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        read_header = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        shape, fortran, dtype = read_header(fh)
        offset = fh.tell()
    return info, np.dtype(dtype), tuple(shape), fortran, offset


def _stored_data_start(path: Path, info: zipfile.ZipInfo) -> int:
    """Byte offset in the file where a stored (uncompressed) member's data begin (after its local header)."""
    with open(path, "rb") as f:
        f.seek(info.header_offset)
        local = f.read(30)
    if local[:4] != b"PK\x03\x04":
        raise InputError(f"member {info.filename!r}: bad zip local header (corrupted file)", source=path)
    return info.header_offset + 30 + int.from_bytes(local[26:28], "little") + int.from_bytes(local[28:30], "little")


def _open_rows(path: Path, zf: zipfile.ZipFile, name: str, rows: int, length: int) -> list[_Channel]:
    """Channels for each row of a C-ordered member of shape (..., length) with ``rows`` rows."""
    info, dtype, shape, fortran, offset = _member_layout(path, zf, name)
    if fortran and rows > 1:
        raise InputError(f"key '{name}' is stored in Fortran order; expected C order", source=path)
    if dtype.hasobject or dtype.kind not in "fiub":
        raise InputError(f"key '{name}' has dtype {dtype}; expected numbers", source=path)
    if info.compress_type == zipfile.ZIP_STORED:
        start = _stored_data_start(path, info) + offset
        return [_FileChannel(path, dtype, start + r * length * dtype.itemsize, length) for r in range(rows)]
    return [_ZipStreamChannel(path, info.filename, dtype, offset, r * length, length) for r in range(rows)]


# --------------------------------------------------------------------------- the record


@dataclass
class ContinuousChunk:
    """A piece of a recording, samples ``start … stop − 1`` (n = stop − start).

    - ``acc``: (axes, n) acceleration [m/s²], float64; None when the walk
      skipped it (``chunks(acc=False)``).
    - ``angle_deg``: (n,) unwrapped sensor angle φ [deg] (φ mod 360 from the
      patch centre, docs/physics.md §0), or None without an encoder.
    - ``hall``: (n,) hall sensor level (any unit), or None.
    """

    start: int
    stop: int
    acc: np.ndarray | None
    angle_deg: np.ndarray | None
    hall: np.ndarray | None

    def __len__(self):
        return self.stop - self.start


@dataclass
class ContinuousRecord:
    """A continuous recording of a co-rotating sensor (docs/records-continuous.md).

    **Fields:**

    - ``acc``: (axes, samples) acceleration [m/s²]; an array (in memory) or a
      channel reader (from a file; use :meth:`read` / :meth:`chunks`).
    - ``axes``: tuple of axis names (``radial``, ``tangential``, ``lateral``).
    - ``fs_hz``: sample rate [Hz].
    - ``encoder_angle_deg``: (samples,) absolute encoder angle [deg] or None.
    - ``encoder_pulses``: (samples,) incremental encoder level (0/1) or None.
    - ``pulses_per_rev``: pulses per revolution of ``encoder_pulses``.
    - ``encoder_offset_deg``: φ = encoder angle + offset (with pulses:
      φ = 360·rising edges/pulses_per_rev + offset).
    - ``hall``: (samples,) hall sensor level or None (no cleat).
    - ``hall_delay_s``: time from a hall edge to the cleat's arrival at the tyre [s].
    - ``condition``: ``speed_kmh``, ``load_n``, ``pressure_bar``, ``drum_diameter_m``, ``rotation_hz``.
    """

    acc: object
    axes: tuple
    fs_hz: float
    encoder_angle_deg: object = None
    encoder_pulses: object = None
    pulses_per_rev: int | None = None
    encoder_offset_deg: float = 0.0
    hall: object = None
    hall_delay_s: float = 0.0
    condition: dict = field(default_factory=dict)
    source: str = "<record>"
    _channels: dict = field(default=None, repr=False)

    def __post_init__(self):
        self.axes = tuple(str(a) for a in self.axes)
        if self._channels is None:  # built in memory: wrap the arrays
            acc = np.asarray(self.acc, dtype=np.float64)
            if acc.ndim == 1:
                acc = acc[None, :]
            self.acc = acc
            ch = {f"acc:{a}": _ArrayChannel(acc[i]) for i, a in enumerate(self.axes)}
            for key in ("encoder_angle_deg", "encoder_pulses", "hall"):
                value = getattr(self, key)
                if value is not None:
                    value = np.asarray(value)
                    setattr(self, key, value)
                    ch[key] = _ArrayChannel(value)
            self._channels = ch
        _validate(self)

    @property
    def samples(self) -> int:
        """Number of samples per channel."""
        return self._channels[f"acc:{self.axes[0]}"].length

    @property
    def duration_s(self) -> float:
        """Length of the recording [s]."""
        return self.samples / self.fs_hz

    @property
    def has_encoder(self) -> bool:
        return "encoder_angle_deg" in self._channels or "encoder_pulses" in self._channels

    @property
    def has_hall(self) -> bool:
        return "hall" in self._channels

    def axis_index(self, axis: str) -> int:
        """Position of ``axis`` in :attr:`axes`; InputError naming the file if absent."""
        if axis not in self.axes:
            raise InputError(f"no '{axis}' axis (have: {', '.join(self.axes)})", source=self.source)
        return self.axes.index(axis)

    def read(self, key: str, start: int = 0, stop: int | None = None) -> np.ndarray:
        """Samples ``start:stop`` of one channel (``acc:radial``, ``hall``, ...) as float64."""
        if key not in self._channels:
            raise InputError(f"no channel {key!r} (have: {', '.join(self._channels)})", source=self.source)
        stop = self.samples if stop is None else min(stop, self.samples)
        return self._channels[key].read(start, stop)

    def chunks(self, chunk: int = DEFAULT_CHUNK, *, start: int = 0, stop: int | None = None,
               acc: bool = True) -> Iterator[ContinuousChunk]:
        """Walk the recording in pieces of ``chunk`` samples (bounded memory).

        The encoder is decoded into the unwrapped sensor angle on the way; a
        non-finite sample raises :class:`InputError` naming the sample index.
        ``acc=False`` skips the acceleration channels (e.g. for the hall pass).
        Each chunk's arrays are fresh: keep a *copy* of any slice held beyond
        the chunk, or the whole chunk stays alive.
        """
        stop = self.samples if stop is None else min(stop, self.samples)
        tracker = SensorAngleTracker(self) if self.has_encoder else None
        if tracker is not None and start > 0:
            tracker.advance(0, start, chunk)
        for i0 in range(start, stop, chunk):
            i1 = min(i0 + chunk, stop)
            x = None
            if acc:
                x = np.empty((len(self.axes), i1 - i0))
                for k, a in enumerate(self.axes):
                    x[k] = self._channels[f"acc:{a}"].read(i0, i1)
                if not np.isfinite(x).all():
                    bad = i0 + int(np.argwhere(~np.isfinite(x))[0, 1])
                    raise InputError(f"key 'acc': non-finite value at sample {bad}", source=self.source)
            angle = tracker.angles(i0, i1) if tracker is not None else None
            hall = self._channels["hall"].read(i0, i1) if self.has_hall else None
            yield ContinuousChunk(i0, i1, x, angle, hall)

    def close(self) -> None:
        """Close the open files and streams."""
        for ch in self._channels.values():
            ch.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


class SensorAngleTracker:
    """Decodes the encoder of a record into the unwrapped sensor angle φ [deg], chunk by chunk.

    Absolute encoder: successive differences wrapped to (−180, 180] and summed
    (the wheel must turn less than half a revolution per sample).
    Incremental encoder: φ = 360·(rising edges + fraction of the current
    pulse)/pulses_per_rev + offset, the fraction taken from the previous
    pulse's length (causal, so chunks need no look-ahead).
    """

    def __init__(self, record: ContinuousRecord):
        self.record = record
        self.absolute = "encoder_angle_deg" in record._channels
        self.offset = float(record.encoder_offset_deg)
        self.ppr = record.pulses_per_rev
        self.last = None  # absolute: last unwrapped angle [deg]
        self.edges = 0  # pulses: rising edges so far
        self.last_edge = np.nan  # sample index of the last rising edge
        self.period = np.nan  # samples between the last two rising edges
        self.prev_level = None
        self.next_start = 0

    def advance(self, start, stop, chunk):
        """Feed samples ``start:stop`` without keeping the angles (to start mid-record)."""
        for i0 in range(start, stop, chunk):
            self.angles(i0, min(i0 + chunk, stop))

    def angles(self, i0: int, i1: int) -> np.ndarray:
        """Unwrapped φ [deg] of samples ``i0:i1``; chunks must come in order."""
        if i0 != self.next_start:
            raise RuntimeError("SensorAngleTracker must be fed consecutive chunks")
        self.next_start = i1
        rec = self.record
        if self.absolute:
            raw = rec._channels["encoder_angle_deg"].read(i0, i1)
            if not np.isfinite(raw).all():
                bad = i0 + int(np.argmax(~np.isfinite(raw)))
                raise InputError(f"key 'encoder_angle_deg': non-finite value at sample {bad}", source=rec.source)
            raw = raw + self.offset
            prev = raw[0] if self.last is None else self.last
            steps = np.diff(raw, prepend=prev)
            steps = (steps + 180.0) % 360.0 - 180.0
            out = prev + np.cumsum(steps)
            self.last = float(out[-1])
            return out
        level = rec._channels["encoder_pulses"].read(i0, i1) > 0.5
        prev = level[0] if self.prev_level is None else self.prev_level
        rising = (np.flatnonzero(level & ~np.concatenate([[prev], level[:-1]])) + i0).astype(np.float64)
        self.prev_level = bool(level[-1])
        idx = np.arange(i0, i1, dtype=np.float64)
        k = np.searchsorted(rising, idx, side="right")
        edge_at = np.concatenate([[self.last_edge], rising])[k]
        lengths = np.diff(np.concatenate([[self.last_edge], rising]))
        period = np.concatenate([[self.period], lengths])[k]
        if lengths.size and np.nanmin(lengths) < 3:
            at = int(rising[int(np.nanargmin(lengths))])
            raise InputError(f"key 'encoder_pulses': rising edges {int(np.nanmin(lengths))} samples apart at sample "
                             f"{at}; the pulse rate must stay below fs_hz/3 (aliased pulses)", source=rec.source)
        known = np.isfinite(edge_at) & np.isfinite(period)
        frac = np.zeros_like(idx)
        frac[known] = np.clip((idx[known] - edge_at[known]) / period[known], 0.0, 1.0)
        count = self.edges + k
        if rising.size:
            self.edges += rising.size
            self.last_edge = rising[-1]
            if np.isfinite(lengths[-1]):
                self.period = lengths[-1]
        return 360.0 * (count + frac) / self.ppr + self.offset


# --------------------------------------------------------------------------- validation


def _scalar(value, key, source, *, positive=False, integer=False):
    try:
        x = float(np.asarray(value).reshape(()))
    except (TypeError, ValueError):
        raise InputError(f"key '{key}' must be a number (got {np.asarray(value).shape} array)", source=source) from None
    if not math.isfinite(x) or (positive and x <= 0):
        raise InputError(f"key '{key}' = {x!r}; expected a finite{' positive' if positive else ''} number", source=source)
    if integer and x != int(x):
        raise InputError(f"key '{key}' = {x!r}; expected an integer", source=source)
    return int(x) if integer else x


def _validate(rec: ContinuousRecord) -> None:
    src = rec.source
    rec.fs_hz = _scalar(rec.fs_hz, "fs_hz", src, positive=True)
    if len(rec.axes) == 0:
        raise InputError("key 'axes' is empty; expected names from radial, tangential, lateral", source=src)
    for a in rec.axes:
        if a not in AXES:
            raise InputError(f"key 'axes': unknown axis {a!r}; expected one of {list(AXES)}", source=src)
    if len(set(rec.axes)) != len(rec.axes):
        raise InputError(f"key 'axes' repeats a name: {list(rec.axes)}", source=src)
    n = rec._channels[f"acc:{rec.axes[0]}"].length
    if n < 2:
        raise InputError(f"key 'acc' has {n} samples; expected a recording", source=src)
    has_angle = "encoder_angle_deg" in rec._channels
    has_pulses = "encoder_pulses" in rec._channels
    if has_angle and has_pulses:
        raise InputError("has both 'encoder_angle_deg' and 'encoder_pulses'; expected one encoder", source=src)
    if has_pulses:
        if rec.pulses_per_rev is None:
            raise InputError("key 'encoder_pulses' needs key 'pulses_per_rev'", source=src)
        rec.pulses_per_rev = _scalar(rec.pulses_per_rev, "pulses_per_rev", src, positive=True, integer=True)
    for key, ch in rec._channels.items():
        if ch.length != n:
            raise InputError(f"key '{key.split(':')[0]}' has {ch.length} samples; 'acc' has {n}", source=src)
    rec.encoder_offset_deg = _scalar(rec.encoder_offset_deg, "encoder_offset_deg", src)
    rec.hall_delay_s = _scalar(rec.hall_delay_s, "hall_delay_s", src)
    cond = {}
    for k, v in (rec.condition or {}).items():
        if k in CONDITION_KEYS:
            v = _scalar(v, k, src)
            if v < 0 and k not in SIGNED_CONDITION_KEYS:
                raise InputError(f"key '{k}' = {v!r}; expected a value >= 0", source=src)
        cond[k] = v
    rec.condition = cond


# --------------------------------------------------------------------------- reading


def verify_members(path: Path, zf: zipfile.ZipFile) -> None:
    """Check every member against its zip CRC-32 (one streaming pass; ~2 GB/s for stored members).

    The channels are read in place by offset, which bypasses the zip's own
    check: without this pass a corrupted (bit-flipped) recording would be
    read as plausible numbers.
    """
    import zlib

    for info in zf.infolist():
        if info.compress_type == zipfile.ZIP_STORED:
            with open(path, "rb") as f:
                f.seek(_stored_data_start(path, info))
                crc, left = 0, info.file_size
                while left > 0:
                    block = f.read(min(left, 1 << 24))
                    if not block:
                        raise InputError(f"member {info.filename!r} is cut short (truncated file)", source=path)
                    crc = zlib.crc32(block, crc)
                    left -= len(block)
            if crc != info.CRC:
                raise InputError(f"member {info.filename!r} fails its CRC check (corrupted file)", source=path)
        else:
            with zf.open(info) as fh:  # ZipExtFile checks the CRC at the end of the stream
                while fh.read(1 << 24):
                    pass


def read_continuous(path: str | os.PathLike, *, verify: bool = True,
                    channels: str | os.PathLike | None = None) -> ContinuousRecord:
    """Open a continuous ``*.records.npz`` without loading its big channels, or read a rig file.

    A ``.tdms``, ``.mat`` or ``.csv`` file (docs/formats.md §17) is read into
    memory by :mod:`ringfit.io.rig`, ``channels`` naming
    its channel map when the file lacks channel metadata.

    ``verify`` (default) checks every member against its CRC first
    (:func:`verify_members`), so a corrupted file is refused rather than read.

    **Raises** :class:`InputError` (one line naming the file and key) for a
    missing, truncated or corrupted file, a §4 file that is not continuous,
    missing or misshapen keys, an unknown axis, two encoders, channels of
    unequal length.
    """
    from ringfit.io.rig import continuous_fields, load_channel_map, read_rig, rig_format

    if rig_format(path) is not None:
        cmap = load_channel_map(channels)  # the map's own errors before the (possibly long) read
        rig = read_rig(path, lazy=True)  # TDMS: channels read chunk by chunk; .mat and CSV whole
        try:
            return ContinuousRecord(**continuous_fields(rig, cmap))
        except BaseException:
            rig.close()
            raise
    if channels is not None:
        raise InputError("--channels applies to TDMS, .mat and CSV files; an .npz names its own channels", source=path)
    path = existing_file(path, "a continuous .npz record")
    try:
        zf = zipfile.ZipFile(path)
        if verify:
            verify_members(path, zf)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, NotImplementedError) as exc:
        raise InputError(f"not a readable .npz file ({exc.__class__.__name__}: {exc}); truncated or corrupted?",
                         source=path) from None
    with zf:
        try:
            return _open_record(path, zf)
        except InputError:
            raise
        except (ValueError, KeyError, EOFError, OSError, zipfile.BadZipFile) as exc:
            raise InputError(f"not a readable continuous record ({exc.__class__.__name__}: {exc})", source=path) from None


def _open_record(path: Path, zf: zipfile.ZipFile) -> ContinuousRecord:
    names = {n[:-4] for n in zf.namelist() if n.endswith(".npy")}
    small = _SmallKeys(path, zf)
    kind = small.get("kind")
    if kind is None or str(kind) != KIND:
        raise InputError(
            f"not a continuous record (key 'kind' is {None if kind is None else str(kind)!r}, "
            f"expected '{KIND}'); per-record files load with the §4 reader",
            source=path,
        )
    for key in ("acc", "axes", "fs_hz"):
        if key not in names:
            raise InputError(f"missing key '{key}'", source=path)
    axes = tuple(str(a) for a in np.atleast_1d(small.get("axes")))
    _, _, shape, _, _ = _member_layout(path, zf, "acc")
    if len(shape) != 3 or shape[0] != 1 or shape[1] != len(axes):
        raise InputError(
            f"key 'acc' has shape {shape}; expected (1, {len(axes)}, samples) for a continuous record", source=path
        )
    samples = shape[2]
    channels = {}
    for i, (a, ch) in enumerate(zip(axes, _open_rows(path, zf, "acc", len(axes), samples))):
        channels[f"acc:{a}"] = ch
    for key in ("encoder_angle_deg", "encoder_pulses", "hall"):
        if key in names:
            _, _, kshape, _, _ = _member_layout(path, zf, key)
            if len(kshape) != 1:
                raise InputError(f"key '{key}' has shape {kshape}; expected (samples,)", source=path)
            channels[key] = _open_rows(path, zf, key, 1, kshape[0])[0]
    condition = {k: small.get(k) for k in CONDITION_KEYS if k in names}
    extra = small.get("condition_json")
    if extra is not None:
        try:
            condition.update({k: v for k, v in json.loads(str(extra)).items() if k not in condition})
        except json.JSONDecodeError:
            raise InputError("key 'condition_json' is not valid JSON", source=path) from None
    return ContinuousRecord(
        acc=channels[f"acc:{axes[0]}"],
        axes=axes,
        fs_hz=small.get("fs_hz"),
        encoder_angle_deg=channels.get("encoder_angle_deg"),
        encoder_pulses=channels.get("encoder_pulses"),
        pulses_per_rev=small.get("pulses_per_rev"),
        encoder_offset_deg=small.get("encoder_offset_deg", 0.0),
        hall=channels.get("hall"),
        hall_delay_s=small.get("hall_delay_s", 0.0),
        condition=condition,
        source=str(path),
        _channels=channels,
    )


class _SmallKeys:
    """Reads small (scalar / short) members of an npz without pickles."""

    def __init__(self, path, zf):
        self.path, self.zf = path, zf
        self.names = {n[:-4] for n in zf.namelist() if n.endswith(".npy")}

    def get(self, key, default=None):
        if key not in self.names:
            return default
        with self.zf.open(key + ".npy") as fh:
            try:
                return np.lib.format.read_array(fh, allow_pickle=False)
            except ValueError as exc:
                raise InputError(f"key '{key}' cannot be read ({exc})", source=self.path) from None


# --------------------------------------------------------------------------- writing


def _small_members(record: ContinuousRecord, first_angle: float) -> dict:
    out = {
        "kind": np.array(KIND),
        "axes": np.array(record.axes),
        "fs_hz": np.float64(record.fs_hz),
        "sensor_angle_deg": np.array([(first_angle + 180.0) % 360.0 - 180.0]),
        "encoder_offset_deg": np.float64(record.encoder_offset_deg),
        "hall_delay_s": np.float64(record.hall_delay_s),
    }
    if record.pulses_per_rev is not None:
        out["pulses_per_rev"] = np.int64(record.pulses_per_rev)
    other = {}
    for k, v in record.condition.items():
        if k in CONDITION_KEYS:
            out[k] = np.float64(v)
        else:
            other[k] = v
    if other:
        out["condition_json"] = np.array(json.dumps(other, default=_json_default))
    return out


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"cannot write {type(x).__name__} to JSON")


def write_continuous(record: ContinuousRecord, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write a (short, in-memory) record as an uncompressed npz, atomically.

    Long recordings: use :class:`ContinuousWriter`, which streams chunks.
    """
    path = check_output_path(path, overwrite=overwrite)
    with ContinuousWriter(
        path,
        axes=record.axes,
        fs_hz=record.fs_hz,
        samples=record.samples,
        encoder="pulses" if "encoder_pulses" in record._channels else ("angle" if record.has_encoder else None),
        hall=record.has_hall,
        pulses_per_rev=record.pulses_per_rev,
        encoder_offset_deg=record.encoder_offset_deg,
        hall_delay_s=record.hall_delay_s,
        condition=record.condition,
        overwrite=True,
    ) as w:
        for i0 in range(0, record.samples, DEFAULT_CHUNK):
            i1 = min(i0 + DEFAULT_CHUNK, record.samples)
            acc = np.stack([record.read(f"acc:{a}", i0, i1) for a in record.axes])
            enc = None
            if "encoder_angle_deg" in record._channels:
                enc = record.read("encoder_angle_deg", i0, i1)
            elif "encoder_pulses" in record._channels:
                enc = record.read("encoder_pulses", i0, i1)
            hall = record.read("hall", i0, i1) if record.has_hall else None
            w.write(acc, encoder=enc, hall=hall)
    return path


class ContinuousWriter:
    """Stream a long continuous record to ``path`` chunk by chunk (bounded memory).

    Each channel (each axis of ``acc``) is appended to its own temporary raw
    file next to ``path`` with plain writes — no memory maps, whose dirty
    pages would count toward the process's resident memory and grow with the
    recording. Closing streams them, 1 MB at a time, into an uncompressed npz
    (so that :func:`read_continuous` can read it in place) and renames it into
    place. Nothing is left behind if an exception interrupts the writing.

    **Arguments:** ``axes``, ``fs_hz``, ``samples`` (total per channel);
    ``encoder`` — ``"angle"`` (absolute, degrees), ``"pulses"`` (0/1 levels,
    needs ``pulses_per_rev``) or None; ``hall`` — whether a hall channel is
    written; ``acc_dtype`` (float64 default; float32 halves the file);
    ``encoder_offset_deg``, ``hall_delay_s``, ``condition`` as in
    :class:`ContinuousRecord`.
    """

    def __init__(
        self,
        path,
        *,
        axes,
        fs_hz,
        samples,
        encoder="angle",
        hall=True,
        pulses_per_rev=None,
        encoder_offset_deg=0.0,
        hall_delay_s=0.0,
        condition=None,
        acc_dtype=np.float64,
        overwrite=False,
    ):
        self.path = check_output_path(path, overwrite=overwrite)
        if encoder not in ("angle", "pulses", None):
            raise ValueError(f"encoder={encoder!r}; expected 'angle', 'pulses' or None")
        self.meta = ContinuousRecord(
            acc=np.zeros((len(axes), 2)),
            axes=tuple(axes),
            fs_hz=fs_hz,
            encoder_pulses=np.zeros(2) if encoder == "pulses" else None,
            encoder_angle_deg=np.zeros(2) if encoder == "angle" else None,
            pulses_per_rev=pulses_per_rev,
            encoder_offset_deg=encoder_offset_deg,
            hall=np.zeros(2) if hall else None,
            hall_delay_s=hall_delay_s,
            condition=dict(condition or {}),
        )
        self.samples = int(samples)
        self.encoder = encoder
        self.tmpdir = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", dir=self.path.parent))
        # member name -> (dtype, shape, [temporary raw file per row, in C order])
        self.members = {"acc": (np.dtype(acc_dtype), (1, len(axes), self.samples), [])}
        self.files = []
        try:
            for k in range(len(axes)):
                self.members["acc"][2].append(self._open(f"acc_{k}"))
            if encoder is not None:
                name = "encoder_angle_deg" if encoder == "angle" else "encoder_pulses"
                dtype = np.dtype(np.float64 if encoder == "angle" else np.uint8)
                self.members[name] = (dtype, (self.samples,), [self._open(name)])
            if hall:
                self.members["hall"] = (np.dtype(np.float32), (self.samples,), [self._open("hall")])
        except BaseException:
            self._cleanup()
            raise
        self.pos = 0
        self.first_angle = 0.0

    def _open(self, name):
        fh = open(self.tmpdir / f"{name}.raw", "wb")
        self.files.append(fh)
        return fh

    def write(self, acc, *, encoder=None, hall=None) -> None:
        """Append a chunk: ``acc`` (axes, n), ``encoder`` (n,), ``hall`` (n,)."""
        acc = np.asarray(acc)
        if acc.ndim == 1:
            acc = acc[None, :]
        n = acc.shape[-1]
        if acc.shape != (len(self.meta.axes), n):
            raise ValueError(f"acc chunk has shape {acc.shape}; expected ({len(self.meta.axes)}, n)")
        if self.pos + n > self.samples:
            raise ValueError(f"writing past the declared {self.samples} samples")
        given = {"encoder_angle_deg": encoder, "encoder_pulses": encoder, "hall": hall}
        for name, (dtype, _, files) in self.members.items():
            if name == "acc":
                for k, fh in enumerate(files):
                    np.ascontiguousarray(acc[k], dtype=dtype).tofile(fh)
                continue
            x = given[name]
            if x is None:
                raise ValueError(f"this writer expects a{'n encoder' if name != 'hall' else ' hall'} chunk")
            x = np.asarray(x)
            if x.shape != (n,):
                raise ValueError(f"{name} chunk has shape {x.shape}; expected ({n},)")
            np.ascontiguousarray(x, dtype=dtype).tofile(files[0])
        if self.pos == 0 and self.encoder == "angle" and n:
            self.first_angle = float(encoder[0]) + self.meta.encoder_offset_deg
        self.pos += n

    def close(self) -> Path:
        """Pack the npz and move it into place."""
        if self.pos != self.samples:
            self._cleanup()
            raise ValueError(f"wrote {self.pos} of {self.samples} declared samples")
        small = _small_members(self.meta, self.first_angle)
        for fh in self.files:
            fh.close()
        fmt = np.lib.format

        def write(tmp):
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
                for name, (dtype, shape, files) in self.members.items():
                    with zf.open(name + ".npy", "w", force_zip64=True) as dst:
                        fmt.write_array_header_1_0(
                            dst, {"descr": fmt.dtype_to_descr(dtype), "fortran_order": False, "shape": shape})
                        for fh in files:
                            with open(fh.name, "rb") as src:
                                shutil.copyfileobj(src, dst, 1 << 20)
                for key, value in small.items():
                    with zf.open(key + ".npy", "w", force_zip64=True) as fh:
                        fmt.write_array(fh, np.asarray(value), allow_pickle=False)

        try:
            atomic_write(self.path, write)
        finally:
            self._cleanup()
        return self.path

    def _cleanup(self):
        for fh in self.files:
            fh.close()
        shutil.rmtree(self.tmpdir, ignore_errors=True)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self._cleanup()
