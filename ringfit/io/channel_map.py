"""Channel map — ``--channels MAP.toml`` (docs/formats.md §17): what each channel of a rig file is.

Rig files (TDMS, MATLAB .mat, CSV; :mod:`ringfit.io.rig`) often carry no
sensor angle, axis, unit or sensitivity. A channel map supplies them, one
table per channel, keyed by the channel's name in the file (TDMS
``"group/channel"`` or the channel name alone when unique, a MATLAB variable,
a CSV column header without its ``[unit]``)::

    fs_hz = 25600.0            # when the file gives no sample rate
    [channels."Impact 01/AccZ"]
    role = "acc"               # acc (default), force, encoder, pulses, trigger, ignore
    axis = "radial"
    angle_deg = 15.0
    unit = "g"
    sensitivity = 0.1         # file value per unit (e.g. V per g); value = file value / sensitivity

A map without ``[channels.*]`` tables only adds the top-level values and
``[condition]`` to a file whose channels are named as ringfit names them.
Parsing and checking only; :mod:`ringfit.io.rig` applies the map.
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ringfit.errors import InputError
from ringfit.io.files import existing_file
from ringfit.io.record_types import ANGLE_RANGE_DEG, AXES, CONDITION_KEYS, SIGNED_CONDITION_KEYS

#: What a channel can be. ``pulses``: incremental encoder (0/1 levels); ``trigger``: the hall / cleat trigger.
ROLES = ("acc", "force", "encoder", "pulses", "trigger", "ignore")
#: Keys of one channel's table.
CHANNEL_KEYS = ("role", "axis", "angle_deg", "record", "unit", "sensitivity")
#: Magnitudes of ``sensitivity`` accepted (file value per unit): beyond them a unit slip or a corrupted map.
SENSITIVITY_RANGE = (1e-9, 1e9)
#: Top-level scalar keys.
TOP_KEYS = ("fs_hz", "pulses_per_rev", "encoder_offset_deg", "hall_delay_s")
#: File-level numbers a rig file may carry (TDMS root properties, MATLAB scalars): the top-level keys and the
#: condition keys of docs/formats.md §9 (:data:`ringfit.io.record_types.CONDITION_KEYS`).
SCALAR_KEYS = TOP_KEYS + CONDITION_KEYS


@dataclass
class ChannelSpec:
    """One channel's entry: ``role``, ``axis``, ``angle_deg``, ``record``, ``unit``, ``sensitivity``."""

    name: str
    role: str = "acc"
    axis: str | None = None
    angle_deg: float | None = None
    record: str | None = None
    unit: str | None = None
    sensitivity: float = 1.0


@dataclass
class ChannelMap:
    """A parsed channel map (docs/formats.md §17)."""

    channels: dict[str, ChannelSpec]
    top: dict = field(default_factory=dict)
    condition: dict = field(default_factory=dict)
    source: str = "<channel map>"


def _number(value, where: str, source, *, positive=False, nonzero=False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{where} = {value!r}; expected a number", source=source)
    x = float(value)
    if not math.isfinite(x) or (positive and x <= 0) or (nonzero and x == 0):
        what = "a positive" if positive else ("a non-zero" if nonzero else "a finite")
        raise InputError(f"{where} = {value!r}; expected {what} number", source=source)
    return x


def read_channel_map(path: str | os.PathLike) -> ChannelMap:
    """Read and check a channel map TOML.

    **Raises** :class:`InputError` (one line naming the file and key) for a
    missing or unparsable file, an unknown key or role, an axis not in
    :data:`~ringfit.io.record_types.AXES`, an acceleration or force channel
    without ``unit``, a non-numeric or zero sensitivity, an acceleration
    channel without ``axis``.
    """
    path = existing_file(Path(path), "a channel map TOML")
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not a valid TOML channel map ({exc})", source=path) from None
    return parse_channel_map(data, source=str(path))


def parse_channel_map(data: dict, *, source: str = "<channel map>") -> ChannelMap:
    """Check a channel map already parsed from TOML (see :func:`read_channel_map`)."""
    unknown = [k for k in data if k not in TOP_KEYS + ("channels", "condition")]
    if unknown:
        raise InputError(f"unknown key {unknown[0]!r}; expected {', '.join(TOP_KEYS)}, [condition] or "
                         "[channels.NAME] tables", source=source)
    top = {}
    for key in TOP_KEYS:
        if key in data:
            top[key] = _number(data[key], key, source, positive=key in ("fs_hz", "pulses_per_rev"))
    if "pulses_per_rev" in top and top["pulses_per_rev"] != int(top["pulses_per_rev"]):
        raise InputError(f"pulses_per_rev = {top['pulses_per_rev']!r}; expected a whole number", source=source)
    condition = data.get("condition", {})
    if not isinstance(condition, dict):
        raise InputError("'condition' must be a table [condition]", source=source)
    condition = {k: (_number(v, f"condition.{k}", source) if k in CONDITION_KEYS else v) for k, v in condition.items()}
    for k in CONDITION_KEYS:
        if k in condition and condition[k] < 0 and k not in SIGNED_CONDITION_KEYS:
            raise InputError(f"condition.{k} = {condition[k]!r}; expected a value >= 0", source=source)
    table = data.get("channels", {})
    if not isinstance(table, dict) or not (table or top or condition):
        raise InputError("missing [channels.NAME] tables (one per channel of the file)", source=source)
    channels = {}
    for name, entry in table.items():
        where = f"channels.{name!r}"
        if not isinstance(entry, dict):
            raise InputError(f"{where} must be a table", source=source)
        bad = [k for k in entry if k not in CHANNEL_KEYS]
        if bad:
            raise InputError(f"{where}: unknown key {bad[0]!r}; expected {', '.join(CHANNEL_KEYS)}", source=source)
        role = entry.get("role", "acc")
        if role not in ROLES:
            raise InputError(f"{where}.role = {role!r}; expected one of {', '.join(ROLES)}", source=source)
        spec = ChannelSpec(name=str(name), role=role)
        if role == "acc":
            if "axis" not in entry:
                raise InputError(f"{where}: missing key 'axis' (one of {', '.join(AXES)})", source=source)
            if entry["axis"] not in AXES:
                raise InputError(f"{where}.axis = {entry['axis']!r}; expected one of {', '.join(AXES)}", source=source)
            spec.axis = entry["axis"]
        elif "axis" in entry:
            raise InputError(f"{where}: 'axis' applies to acc channels only (role is {role!r})", source=source)
        if role in ("acc", "force") and "unit" not in entry:
            raise InputError(f"{where}: missing key 'unit' (e.g. \"m/s^2\", \"g\", \"N\")", source=source)
        if "unit" in entry:
            if not isinstance(entry["unit"], str):
                raise InputError(f"{where}.unit = {entry['unit']!r}; expected a unit text", source=source)
            spec.unit = entry["unit"]
        if "angle_deg" in entry:
            spec.angle_deg = _number(entry["angle_deg"], f"{where}.angle_deg", source)
            lo, hi = ANGLE_RANGE_DEG
            if not lo <= spec.angle_deg <= hi:
                raise InputError(f"{where}.angle_deg = {entry['angle_deg']!r}; expected an angle in [{lo:g}, {hi:g}] "
                                 "degrees", source=source)
        if "record" in entry:
            if not isinstance(entry["record"], (str, int)) or isinstance(entry["record"], bool):
                raise InputError(f"{where}.record = {entry['record']!r}; expected a name or number", source=source)
            spec.record = str(entry["record"])
        if "sensitivity" in entry:
            spec.sensitivity = _number(entry["sensitivity"], f"{where}.sensitivity", source, nonzero=True)
            lo, hi = SENSITIVITY_RANGE
            if not lo <= abs(spec.sensitivity) <= hi:
                raise InputError(f"{where}.sensitivity = {entry['sensitivity']!r}; expected a magnitude in "
                                 f"[{lo:g}, {hi:g}] (file value per unit; negative flips the sign)", source=source)
        channels[str(name)] = spec
    return ChannelMap(channels=channels, top=top, condition=condition, source=source)


def write_channel_map(cmap: ChannelMap, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``cmap`` as TOML (atomically; refuses to overwrite unless ``overwrite``)."""
    import tomli_w

    from ringfit.io.files import atomic_write_text, check_output_path

    path = check_output_path(path, overwrite=overwrite)
    doc: dict = dict(cmap.top)
    if cmap.condition:
        doc["condition"] = dict(cmap.condition)
    doc["channels"] = {}
    for name, spec in cmap.channels.items():
        entry = {"role": spec.role}
        for key in ("axis", "angle_deg", "record", "unit"):
            if getattr(spec, key) is not None:
                entry[key] = getattr(spec, key)
        if spec.sensitivity != 1.0:
            entry["sensitivity"] = spec.sensitivity
        doc["channels"][name] = entry
    atomic_write_text(path, "# ringfit channel map (docs/formats.md §17)\n" + tomli_w.dumps(doc))
    return path
