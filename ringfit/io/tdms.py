"""National Instruments TDMS files (LabVIEW benches), via ``npTDMS`` (docs/formats.md §17.1).

Read: every numeric channel of every group becomes a
:class:`~ringfit.io.rig.RawChannel` named ``"group/channel"``, with the NI
waveform properties (``wf_increment`` → sample rate) and ``unit_string``;
ringfit's own properties ``sensor_angle_deg`` (channel or group), ``axis``
and ``role`` (channel) are used when present. Channels that are not numbers
(timestamps, text) are skipped with a warning unless the channel map names
them. A group is one impact record.

``lazy=True`` (continuous recordings, :func:`ringfit.io.continuous.read_continuous`):
the file stays open and each channel is read on demand, chunk by chunk
(``TdmsChannel.read_data``), so a long recording is never held whole.

Write (:func:`write_tdms_records`): one group per record (``record 000`` …)
with properties ``sensor_angle_deg``, channels named by axis and ``force``,
each with ``wf_increment`` and ``unit_string`` — readable without a channel map.
"""

from __future__ import annotations

import logging
import os
import warnings
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.channel_map import SCALAR_KEYS
from ringfit.io.files import atomic_write, check_output_path, existing_file
from ringfit.io.record_types import Records
from ringfit.io.rig_types import LazyData, RawChannel, RigFile


def _nptdms():
    try:
        import nptdms
    except ImportError as exc:  # pragma: no cover - a core dependency
        raise ImportError("reading/writing TDMS files needs npTDMS: pip install npTDMS") from exc
    return nptdms


class _Capture(logging.Handler):
    """Collects npTDMS's log messages (its only word on a truncated file)."""

    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record):
        self.messages.append(record.getMessage())


def _float(value, where, source):
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{where} = {value!r}; expected a number", source=source) from None
    if not np.isfinite(x):
        raise InputError(f"{where} = {value!r}; expected a finite number", source=source)
    return x


class _Handle:
    """The open file behind lazy channels; closing any of its channels closes it (a record closes all at once)."""

    def __init__(self, f):
        self.f = f

    def close(self):
        if self.f is not None:
            self.f.close()
            self.f = None


class _TdmsData(LazyData):
    """One TDMS channel read on demand with ``TdmsChannel.read_data`` (scaled values)."""

    def __init__(self, handle: _Handle, channel, name: str, source):
        self.handle, self.channel, self.name, self.source = handle, channel, name, source
        self.size = len(channel)
        self.dtype = np.dtype(channel.dtype) if channel.dtype is not None else np.dtype(object)

    def read(self, start, stop):
        try:
            out, cut = _quiet_nptdms(lambda: np.asarray(self.channel.read_data(offset=start, length=stop - start),
                                                        dtype=np.float64))
        except Exception as exc:  # noqa: BLE001 - npTDMS raises assorted errors on bad data
            raise InputError(f"channel {self.name!r}: samples {start}…{stop - 1} unreadable "
                             f"({exc.__class__.__name__}); corrupted file?", source=self.source) from None
        if cut:
            raise InputError(f"channel {self.name!r}: the TDMS file is truncated ({cut[0].rstrip('.')}); refusing "
                             "to read up to the cut", source=self.source)
        return out

    def close(self):
        self.handle.close()


#: npTDMS's words for a file that ends early (its log lines; it reads up to the cut and says only this).
_CUT_WORDS = ("less data than expected", "not a multiple of the chunk", "metadata is incomplete")


def _quiet_nptdms(fn):
    """``fn()`` with npTDMS's log lines caught: InputError for a truncated file, not a partial read.

    npTDMS gives each of its module loggers (``nptdms.reader``, ``nptdms.tdms_segment``, …) its own stderr
    handler, so silencing the package logger is not enough: each one's handlers are swapped for the capture
    while ``fn`` runs, and put back after.
    """
    logged = _Capture()
    saved = []
    names = ["nptdms"] + [n for n in list(logging.root.manager.loggerDict) if n.startswith("nptdms.")]
    for name in names:
        logger = logging.getLogger(name)
        saved.append((logger, list(logger.handlers), logger.propagate))
        for h in list(logger.handlers):
            logger.removeHandler(h)
        logger.addHandler(logged)
        logger.propagate = False  # npTDMS's log lines would break the one-line error
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out = fn()
    finally:
        for logger, handlers, propagate in saved:
            logger.removeHandler(logged)
            for h in handlers:
                logger.addHandler(h)
            logger.propagate = propagate
    cut = [m for m in logged.messages if any(w in m for w in _CUT_WORDS)]
    return out, cut


def read_tdms_channels(path: str | os.PathLike, *, lazy: bool = False) -> RigFile:
    """The channels of a TDMS file (module docstring); InputError for an unreadable or truncated file.

    ``lazy``: open the file and read each channel on demand (:class:`_TdmsData`)
    instead of reading it whole; the caller closes it (:meth:`RigFile.close`).
    """
    nptdms = _nptdms()
    path = existing_file(Path(path), "a TDMS file")
    handle = None

    def load():
        if lazy:
            f = nptdms.TdmsFile.open(str(path))
            groups = [(g, list(g.channels())) for g in f.groups()]
            return f, groups, None
        f = nptdms.TdmsFile.read(str(path))
        groups = [(g, list(g.channels())) for g in f.groups()]
        return f, groups, {(g.name, c.name): c[:] for g, chans in groups for c in chans}

    try:
        (f, groups, data), cut = _quiet_nptdms(load)
    except Exception as exc:  # noqa: BLE001 - npTDMS raises assorted errors on bad files
        text = str(exc).splitlines()[0][:120] if str(exc) else ""
        raise InputError(f"not a readable TDMS file ({exc.__class__.__name__}: {text}); truncated or corrupted?",
                         source=path) from None
    if lazy:
        handle = _Handle(f)
    if not cut and path.stat().st_size < 28:  # a segment's lead-in alone is 28 bytes ("TDSm", flags, version, …)
        cut = [f"{path.stat().st_size} bytes, shorter than one segment's 28-byte lead-in"]
    if cut:  # npTDMS reads up to the cut; ringfit refuses it (as it refuses a truncated UFF file)
        if handle is not None:
            handle.close()
        raise InputError(f"the TDMS file is truncated ({cut[0].rstrip('.')}); refusing to read up to the cut",
                         source=path)
    try:
        return _channels(path, f, groups, data, handle)
    except BaseException:
        if handle is not None:
            handle.close()
        raise


def _channels(path, f, groups, data, handle) -> RigFile:
    rig = RigFile(source=str(path), format="tdms")
    for key, value in f.properties.items():
        if key in SCALAR_KEYS:
            rig.props[key] = _float(value, f"file property {key!r}", path)
    skipped = []
    for g, chans in groups:
        g_angle = g.properties.get("sensor_angle_deg")
        for c in chans:
            name = f"{g.name}/{c.name}"
            x = _TdmsData(handle, c, name, path) if handle is not None else np.asarray(data[(g.name, c.name)])
            if x.dtype.kind not in "fiub":
                skipped.append(name)  # timestamps, text: dropped below (a map naming one is refused)
            p = c.properties
            inc = p.get("wf_increment")
            fs = None
            if inc is not None:
                inc = _float(inc, f"channel {name!r} property 'wf_increment'", path)
                if inc <= 0:
                    raise InputError(f"channel {name!r}: wf_increment = {inc!r}; expected a time step > 0 s",
                                     source=path)
                fs = 1.0 / inc
            if "fs_hz" in p:  # ringfit writes the rate in full beside wf_increment
                fs = _float(p["fs_hz"], f"channel {name!r} property 'fs_hz'", path)
            angle = p.get("sensor_angle_deg", g_angle)
            rig.channels.append(RawChannel(
                name=name, short=c.name, group=g.name, data=x,
                unit=str(p["unit_string"]) if "unit_string" in p else None, fs_hz=fs,
                axis=str(p["axis"]) if "axis" in p else None,
                angle_deg=None if angle is None else _float(angle, f"channel {name!r} sensor_angle_deg", path),
                role=str(p["role"]) if "role" in p else None))
    if skipped:
        rig.channels = [c for c in rig.channels if c.name not in skipped]
        warnings.warn(f"{path}: {len(skipped)} channel(s) of non-numeric data skipped: {', '.join(skipped[:4])}",
                      stacklevel=2)
    if not rig.channels:
        raise InputError("no numeric channels in any group", source=path)
    return rig


def write_tdms_records(records: Records, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``records`` as TDMS: a group per record, channels per axis and ``force`` (SI units)."""
    nptdms = _nptdms()
    path = check_output_path(path, overwrite=overwrite)
    dt = 1.0 / records.fs_hz
    objects = [nptdms.RootObject(properties={"title": "ringfit records", "fs_hz": float(records.fs_hz)})]
    for r in range(records.n_records):
        group = f"record {r:03d}"
        objects.append(nptdms.GroupObject(group, properties={"sensor_angle_deg": float(records.sensor_angle_deg[r])}))
        common = {"wf_increment": dt, "wf_start_offset": 0.0, "fs_hz": float(records.fs_hz)}
        for a, axis in enumerate(records.axes):
            objects.append(nptdms.ChannelObject(group, axis, np.ascontiguousarray(records.acc[r, a]),
                                                properties={**common, "unit_string": "m/s^2"}))
        if records.force is not None:
            objects.append(nptdms.ChannelObject(group, "force", np.ascontiguousarray(records.force[r]),
                                                properties={**common, "unit_string": "N"}))

    def write(tmp: Path):
        with nptdms.TdmsWriter(str(tmp)) as w:
            w.write_segment(objects)

    atomic_write(path, write)
    return path
