"""Rig files — NI TDMS, MATLAB .mat (v5, v7.3) and CSV — turned into ringfit's records (docs/formats.md §17).

The three readers (:mod:`ringfit.io.tdms`, :mod:`ringfit.io.matlab`,
:mod:`ringfit.io.csv_records`) each return a :class:`RigFile`: named 1-D
channels with whatever metadata the file carries (unit, sample rate, axis,
sensor angle, record). This module applies the channel map
(:mod:`ringfit.io.channel_map`) on top and builds the same objects the npz
and UFF readers return:

- :func:`records_from_rig` → :class:`~ringfit.io.record_types.Records`
  (impact records: ``ssi``, ``frf``);
- :func:`continuous_fields` → the fields of a
  :class:`~ringfit.io.continuous.ContinuousRecord`, which
  :func:`ringfit.io.continuous.read_continuous` builds (drum and cleat
  recordings: ``profile``, ``cleat``, ``estimate``; this module does not
  import that one, so the two never import each other).

A file may instead hold ringfit's own key layout (the keys of docs/formats.md
§4 / §9 as arrays, as a MATLAB user saves them); the readers return that as
``RigFile.arrays`` and it is used as an npz would be.

Units are converted with the UFF reader's unit table (:func:`ringfit.io.uff.unit_scale`).
Nothing is guessed silently: a channel whose role, axis, angle or unit is
unknown is refused with a one-line hint to ``--channels MAP.toml``.
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.channel_map import CONDITION_KEYS, ChannelMap, ChannelSpec, read_channel_map
from ringfit.io.record_types import ANGLE_RANGE_DEG, AXES, Records
from ringfit.io.rig_types import LazyData, RawChannel, RigFile, ScaledChannel
from ringfit.io.uff import unit_scale

__all__ = ["RawChannel", "RigFile", "RIG_SUFFIXES", "rig_format", "read_rig", "records_from_rig",
           "continuous_fields", "read_rig_records", "load_channel_map"]

#: Suffixes of the rig formats, and the reader module of each.
RIG_SUFFIXES = {".tdms": "tdms", ".mat": "matlab", ".csv": "csv"}
#: Channel names understood without a channel map (besides the axis names), and their roles.
NAMED_ROLES = {"force": "force", "encoder_angle_deg": "encoder", "encoder": "encoder",
               "encoder_pulses": "pulses", "hall": "trigger", "trigger": "trigger"}
#: Angle units of an absolute encoder channel.
ANGLE_UNITS = {"deg": 1.0, "degree": 1.0, "degrees": 1.0, "°": 1.0, "rad": 180.0 / math.pi, "radian": 180.0 / math.pi}


def rig_format(path: str | os.PathLike) -> str | None:
    """``"tdms"``, ``"matlab"``, ``"csv"`` for a rig file's suffix, else None."""
    return RIG_SUFFIXES.get(Path(path).suffix.lower())


def read_rig(path: str | os.PathLike, *, lazy: bool = False) -> RigFile:
    """Read a rig file with the reader its suffix names (no channel map applied yet).

    ``lazy``: TDMS channels are read on demand (:class:`~ringfit.io.rig_types.LazyData`;
    a long recording is walked chunk by chunk, never held whole); close them
    with :meth:`RigFile.close`. The other formats are read whole.
    """
    fmt = rig_format(path)
    if fmt == "tdms":
        from ringfit.io.tdms import read_tdms_channels

        return read_tdms_channels(path, lazy=lazy)
    if fmt == "matlab":
        from ringfit.io.matlab import read_mat_channels

        return read_mat_channels(path)
    if fmt == "csv":
        from ringfit.io.csv_records import read_csv_channels

        return read_csv_channels(path)
    raise InputError(f"not a rig file; expected one of {', '.join(RIG_SUFFIXES)}", source=path)


def load_channel_map(channels) -> ChannelMap | None:
    """A :class:`ChannelMap` from a path (read and checked), or ``channels`` itself (None or a map)."""
    if channels is None or isinstance(channels, ChannelMap):
        return channels
    return read_channel_map(channels)


# --------------------------------------------------------------------------- applying the map


@dataclass
class _Channel:
    """A channel with its meaning settled: role, axis, angle, record, SI data."""

    raw: RawChannel
    role: str
    axis: str | None
    angle_deg: float | None
    record: str | None
    data: np.ndarray


def _spec_for(raw: RawChannel, cmap: ChannelMap, rig: RigFile) -> ChannelSpec | None:
    if raw.name in cmap.channels:
        return cmap.channels[raw.name]
    if raw.short and raw.short in cmap.channels:
        same = [c for c in rig.channels if c.short == raw.short]
        if len(same) > 1:
            raise InputError(f"channels.{raw.short!r} matches {len(same)} channels of {rig.source} "
                             f"({', '.join(c.name for c in same[:3])}); key it as \"GROUP/CHANNEL\"",
                             source=cmap.source)
        return cmap.channels[raw.short]
    return None


def _factor(raw: RawChannel, role: str, unit: str | None, sensitivity: float, rig: RigFile, hint: str) -> float:
    """SI value per file value (acc m/s², force N, encoder deg): unit scale / sensitivity; ``unit`` from the map
    or the file."""
    where = f"channel {raw.name!r}"
    data = raw.data
    if np.dtype(data.dtype).kind not in "fiub" or data.ndim != 1:
        raise InputError(f"{where}: {data.dtype} data of {data.ndim} dimensions; expected a 1-D numeric channel",
                         source=rig.source)
    if role in ("pulses", "trigger"):
        return 1.0 / sensitivity
    if role == "encoder":
        text = (unit or "deg").strip().lower().strip("[]()")
        if text not in ANGLE_UNITS:
            raise InputError(f"{where}: encoder unit {unit!r}; expected deg or rad{hint}", source=rig.source)
        return ANGLE_UNITS[text] / sensitivity
    if unit is None or not unit.strip():
        raise InputError(f"{where}: no unit in the file; give it{hint or ' in --channels MAP.toml'} "
                         f"(e.g. unit = \"{'m/s^2' if role == 'acc' else 'N'}\")", source=rig.source)
    parsed = unit_scale(unit)
    want = "acc" if role == "acc" else "force"
    if parsed is None or parsed[0] != want:
        what = "an acceleration (m/s^2, mm/s^2, g)" if want == "acc" else "a force (N, kN, lbf)"
        raise InputError(f"{where}: unit {unit!r} is not {what}{hint}", source=rig.source)
    return parsed[1] / sensitivity


def _scaled(raw: RawChannel, factor: float):
    """The channel in SI: an array, or for a lazy channel a :class:`ScaledChannel` read on demand."""
    if isinstance(raw.data, LazyData):
        return ScaledChannel(raw.data, factor)
    data = np.asarray(raw.data).astype(np.float64)
    return data * factor if factor != 1.0 else data


def _settle(rig: RigFile, cmap: ChannelMap | None) -> list[_Channel]:
    """Each channel's role, axis, angle, record and SI data, from the map or the file's own metadata."""
    out = []
    if cmap is not None and not cmap.channels:  # the map adds values only; channels named as ringfit names them
        cmap = None
    if cmap is not None:
        names = {c.name for c in rig.channels} | {c.short for c in rig.channels if c.short}
        missing = [k for k in cmap.channels if k not in names]
        if missing:
            have = ", ".join(sorted(c.name for c in rig.channels)[:6])
            raise InputError(f"channels.{missing[0]!r} is not a channel of {rig.source} (have: {have}"
                             f"{', …' if len(rig.channels) > 6 else ''})", source=cmap.source)
    unused = []
    for raw in rig.channels:
        spec = _spec_for(raw, cmap, rig) if cmap is not None else None
        if cmap is not None and spec is None:
            unused.append(raw.name)
            continue
        if spec is not None:
            hint = f" (channels.{spec.name!r} in {cmap.source})"
            role, axis, angle, record = spec.role, spec.axis, spec.angle_deg, spec.record
            unit = spec.unit if spec.unit is not None else raw.unit
            sens = spec.sensitivity
            if record is None and angle is None:  # the map places it by angle, else the file's group does
                record = raw.group
            if angle is None:
                angle = raw.angle_deg
        else:
            hint = ""
            role = raw.role or NAMED_ROLES.get(raw.short.lower(), "acc" if raw.short.lower() in AXES else None)
            axis = raw.axis or (raw.short.lower() if raw.short.lower() in AXES else None)
            if role is None or (role == "acc" and axis is None):
                raise InputError(f"channel {raw.name!r}: unknown channel (not named {', '.join(AXES)}, force, "
                                 "encoder_angle_deg, encoder_pulses or hall, no axis in the file); describe it in "
                                 "--channels MAP.toml (docs/formats.md §17)", source=rig.source)
            angle, record, unit, sens = raw.angle_deg, raw.group, raw.unit, 1.0
        if role == "ignore":
            continue
        out.append(_Channel(raw, role, axis, angle, record, _scaled(raw, _factor(raw, role, unit, sens, rig, hint))))
    if unused:
        warnings.warn(f"{rig.source}: {len(unused)} channel(s) not in the channel map, not used: "
                      f"{', '.join(unused[:5])}{', …' if len(unused) > 5 else ''}", stacklevel=3)
    if not out:
        raise InputError("no channels to read (every channel ignored)", source=rig.source)
    return out


def _sample_rate(rig: RigFile, cmap: ChannelMap | None, chans: list[_Channel]) -> float:
    if cmap is not None and "fs_hz" in cmap.top:
        fs = float(cmap.top["fs_hz"])
        told = [rig.props.get("fs_hz")] + [ch.raw.fs_hz for ch in chans]
        off = [f for f in told if f is not None and not math.isclose(f, fs, rel_tol=1e-6)]
        if off:
            warnings.warn(f"{rig.source}: the channel map's fs_hz = {fs:.9g} Hz overrides the file's {off[0]:.9g} Hz",
                          stacklevel=4)
        return fs
    fs = rig.props.get("fs_hz")
    for ch in chans:
        f = ch.raw.fs_hz
        if f is None:
            continue
        if fs is None:
            fs = f
        elif not math.isclose(f, fs, rel_tol=1e-6):
            raise InputError(f"channel {ch.raw.name!r}: sample rate {f:.9g} Hz differs from {fs:.9g} Hz",
                             source=rig.source)
    if fs is None:
        raise InputError("no sample rate in the file (TDMS wf_increment, a CSV time column, a MATLAB fs_hz "
                         "variable); give fs_hz in --channels MAP.toml", source=rig.source)
    return float(fs)


def _same_length(rig: RigFile, chans: list[_Channel]) -> int:
    n = chans[0].raw.data.size
    for ch in chans[1:]:
        if ch.raw.data.size != n:
            raise InputError(f"channel {ch.raw.name!r} has {ch.raw.data.size} samples; {chans[0].raw.name!r} has {n}",
                             source=rig.source)
    return n


def _fill_gaps(rig: RigFile, chans) -> None:
    """Put the samples a reader found dropped (``rig.gaps``) back on the even time grid, in place: straight
    lines for measured values, the encoder's angle unwrapped first, pulses and the trigger held (0/1 levels)."""
    if not rig.gaps:
        return
    n = chans[0].data.size
    idx = np.arange(n)
    where = idx.copy()  # each kept sample's place on the full grid
    for i, m in rig.gaps:
        where[i + 1:] += m
    grid = np.arange(int(where[-1]) + 1)
    for ch in chans:
        x = np.asarray(ch.data, dtype=np.float64)
        if ch.role in ("pulses", "trigger"):
            ch.data = x[np.searchsorted(where, grid, side="right") - 1]
        elif ch.role == "encoder":
            y = np.rad2deg(np.interp(grid, where, np.unwrap(np.deg2rad(x))))
            ch.data = y % 360.0 if x.min() >= 0 and x.max() < 360.0 else y  # wrapped stays wrapped
        else:
            ch.data = np.interp(grid, where, x)


def records_from_rig(rig: RigFile, channels=None) -> Records:
    """Impact :class:`Records` from a rig file (and a channel map path or :class:`ChannelMap`).

    Channels are grouped into records by the map's ``record``, else by the
    map's ``angle_deg``, else by the TDMS group, else by the file's sensor angle; each record has one channel per axis (every
    record the same axes) and at most one force (every record or none).
    """
    cmap = load_channel_map(channels)
    if rig.arrays is not None:
        if cmap is not None:
            raise InputError("holds ringfit's own keys (acc, axes, sensor_angle_deg, fs_hz); --channels applies to "
                             "files of named channels", source=rig.source)
        a = rig.arrays
        for key in ("acc", "axes", "sensor_angle_deg", "fs_hz"):
            if key not in a:
                raise InputError(f"missing key {key!r} (have: {', '.join(sorted(a)) or 'none'})", source=rig.source)
        return Records(acc=a["acc"], axes=a["axes"], sensor_angle_deg=a["sensor_angle_deg"], fs_hz=a["fs_hz"],
                       force=a.get("force"), source=rig.source)
    chans = _settle(rig, cmap)
    fs = _sample_rate(rig, cmap, chans)
    _same_length(rig, chans)
    _fill_gaps(rig, chans)
    order: list[str] = []
    acc: dict[str, dict[str, _Channel]] = {}
    force: dict[str, _Channel] = {}
    for ch in chans:
        if ch.role not in ("acc", "force"):
            raise InputError(f"channel {ch.raw.name!r} is a {ch.role} channel; impact records hold acceleration "
                             "and force (mark it role = \"ignore\" in the channel map)", source=rig.source)
        if ch.role == "acc" and ch.angle_deg is None:
            raise InputError(f"channel {ch.raw.name!r} has no sensor angle; give angle_deg in --channels MAP.toml (or "
                             "a sensor_angle_deg property)", source=rig.source)
        lo, hi = ANGLE_RANGE_DEG
        if ch.angle_deg is not None and not lo <= ch.angle_deg <= hi:
            raise InputError(f"channel {ch.raw.name!r}: sensor angle {ch.angle_deg:g}°; expected an angle in "
                             f"[{lo:g}, {hi:g}] degrees", source=rig.source)
        key = ch.record if ch.record is not None else (None if ch.angle_deg is None else f"{ch.angle_deg:.12g} deg")
        if key is None:
            raise InputError(f"channel {ch.raw.name!r}: no record and no sensor angle; give angle_deg (and record "
                             "for repeated impacts) in --channels MAP.toml", source=rig.source)
        if key not in acc:
            acc[key] = {}
            order.append(key)
        if ch.role == "force":
            if key in force:
                raise InputError(f"record {key!r} has two force channels ({force[key].raw.name!r}, "
                                 f"{ch.raw.name!r})", source=rig.source)
            force[key] = ch
        else:
            if ch.axis in acc[key]:
                raise InputError(f"record {key!r} has two {ch.axis} channels ({acc[key][ch.axis].raw.name!r}, "
                                 f"{ch.raw.name!r})", source=rig.source)
            acc[key][ch.axis] = ch
    used = [a for a in AXES if any(a in acc[k] for k in order)]
    if not used:
        raise InputError("no acceleration channels", source=rig.source)
    angles = []
    for k in order:
        missing = [a for a in used if a not in acc[k]]
        if missing:
            raise InputError(f"record {k!r}: no {missing[0]} channel while other records have one", source=rig.source)
        got = {acc[k][a].angle_deg for a in used}
        if len(got) > 1:
            raise InputError(f"record {k!r}: its channels give different sensor angles {sorted(got)}",
                             source=rig.source)
        angles.append(got.pop())
    if force and len(force) != len(order):
        k = next(k for k in order if k not in force)
        raise InputError(f"record {k!r} has no force channel while others have one; every record or none",
                         source=rig.source)
    return Records(
        acc=np.stack([np.stack([acc[k][a].data for a in used]) for k in order]),
        axes=tuple(used),
        sensor_angle_deg=np.array(angles, dtype=np.float64),
        fs_hz=fs,
        force=np.stack([force[k].data for k in order]) if force else None,
        source=rig.source,
        notes=list(rig.notes),
    )


def continuous_fields(rig: RigFile, channels=None) -> dict:
    """The keyword arguments of a :class:`~ringfit.io.continuous.ContinuousRecord` (in memory) from a rig file
    and an optional channel map.

    One acceleration channel per axis, at most one encoder (``encoder`` in
    degrees, or ``pulses`` with ``pulses_per_rev``), at most one ``trigger``
    (the hall sensor); condition keys from the file and the map's
    ``[condition]`` (the map wins).
    """
    cmap = load_channel_map(channels)
    props = dict(rig.props)
    if rig.arrays is not None:
        if cmap is not None:
            raise InputError("holds ringfit's own keys; --channels applies to files of named channels",
                             source=rig.source)
        a = rig.arrays
        for key in ("acc", "axes", "fs_hz"):
            if key not in a:
                raise InputError(f"missing key {key!r} (have: {', '.join(sorted(a)) or 'none'})", source=rig.source)
        acc = np.asarray(a["acc"])
        if acc.ndim != 3 or acc.shape[0] != 1:
            raise InputError(f"key 'acc' has shape {acc.shape}; expected (1, axes, samples) for a continuous record",
                             source=rig.source)
        extra = {k: a[k] for k in ("encoder_angle_deg", "encoder_pulses", "hall") if k in a}
        for k, v in extra.items():
            if np.asarray(v).ndim != 1:
                raise InputError(f"key {k!r} has shape {np.asarray(v).shape}; expected (samples,)", source=rig.source)
        return dict(
            acc=acc[0], axes=tuple(a["axes"]), fs_hz=a["fs_hz"], pulses_per_rev=a.get("pulses_per_rev"),
            encoder_offset_deg=a.get("encoder_offset_deg", 0.0), hall_delay_s=a.get("hall_delay_s", 0.0),
            condition={k: a[k] for k in CONDITION_KEYS if k in a}, source=rig.source, **extra)
    chans = _settle(rig, cmap)
    fs = _sample_rate(rig, cmap, chans)
    _same_length(rig, chans)
    _fill_gaps(rig, chans)
    for note in rig.notes:  # a continuous recording has no mode table to carry them: said at once
        warnings.warn(f"{rig.source}: {note}", RuntimeWarning, stacklevel=2)
    acc: dict[str, _Channel] = {}
    one: dict[str, _Channel] = {}
    for ch in chans:
        if ch.role == "force":
            raise InputError(f"channel {ch.raw.name!r} is a force channel; a continuous recording holds "
                             "acceleration, encoder and trigger (mark it role = \"ignore\")", source=rig.source)
        if ch.role == "acc":
            if ch.axis in acc:
                raise InputError(f"two {ch.axis} channels ({acc[ch.axis].raw.name!r}, {ch.raw.name!r}); a "
                                 "continuous recording has one per axis", source=rig.source)
            acc[ch.axis] = ch
            continue
        slot = "encoder" if ch.role in ("encoder", "pulses") else ch.role
        if slot in one:
            raise InputError(f"two {slot} channels ({one[slot].raw.name!r}, {ch.raw.name!r})", source=rig.source)
        one[slot] = ch
    if not acc:
        raise InputError("no acceleration channels", source=rig.source)
    axes = tuple(a for a in AXES if a in acc)
    top = dict(props)
    if cmap is not None:
        top.update(cmap.top)
    enc = one.get("encoder")
    condition = {k: props[k] for k in CONDITION_KEYS if k in props}
    if cmap is not None:
        condition.update(cmap.condition)
    fields = dict(
        encoder_angle_deg=enc.data if enc is not None and enc.role == "encoder" else None,
        encoder_pulses=enc.data if enc is not None and enc.role == "pulses" else None,
        hall=one["trigger"].data if "trigger" in one else None)
    common = dict(axes=axes, fs_hz=fs, pulses_per_rev=top.get("pulses_per_rev"),
                  encoder_offset_deg=top.get("encoder_offset_deg", 0.0), hall_delay_s=top.get("hall_delay_s", 0.0),
                  condition=condition, source=rig.source)
    if any(isinstance(ch.data, ScaledChannel) for ch in chans):  # read on demand, chunk by chunk
        channels = {f"acc:{a}": acc[a].data for a in axes}
        channels.update({k: v for k, v in fields.items() if v is not None})
        return dict(acc=channels[f"acc:{axes[0]}"], _channels=channels, **fields, **common)
    return dict(acc=np.stack([acc[a].data for a in axes]), **fields, **common)


def read_rig_records(path: str | os.PathLike, channels=None) -> Records:
    """Impact records from a TDMS, .mat or CSV file (``channels``: a channel map path, or None)."""
    cmap = load_channel_map(channels)  # the map's own errors before the (possibly long) read
    return records_from_rig(read_rig(path), cmap)
