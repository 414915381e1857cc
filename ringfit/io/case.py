"""The one reader of a case folder (docs/formats.md §6): one tyre and everything measured on it.

``ringfit diagnose`` (:func:`ringfit.gap.case.read_case`), ``ringfit identify``
(:func:`ringfit.fit.identify.read_identify_folder`) and ``ringfit campaign`` read a folder through
:func:`read_case_folder`, so one folder is accepted or refused by one set of rules with one set of
messages (each one line naming the file and, where there is one, the field):

- the folder exists and holds ``tyre.toml`` and ``free.modes.csv``; ``free.modes.csv`` is the static,
  free tyre (its sidecar's ``state`` is ``free``, no speed, no rotation);
- every other ``*.modes.csv`` is a test table and every ``*.profile.csv`` a rolling profile, each with
  its sidecar (``NAME.json``), counted once when given twice (:func:`ringfit.io.conditions.case_inputs`);
- a table's sidecar states a condition that can be modelled (:func:`ringfit.io.modes.check_test_condition`);
- a profile's sidecar states a positive ``load_n`` and ``speed_kmh`` (every command that reads a case folder
  models the profile at its load and speed);
- every stated condition is checked against the tyre file (:func:`ringfit.io.conditions.check_stated`:
  the pressure, a rotation against its speed); what a command does with a measurement at another pressure is
  its own (``other_pressure``, ``pressure_law``): the diagnosis uses it with a warning, identify carries the
  ring to it with the pressure law or refuses it.

What each command then uses is its own rule (identify: loaded tables need ``load_n``, rolling tables are
skipped, a free table of any length is used, a parameter it does not bound flagged at its plausible bound; the
diagnosis: every table is a test, and ``free.modes.csv`` needs four structural modes with an n, since the
diagnosis fits the ring to it alone). ``*.records.npz`` files are listed, not read.

Example::

    case = read_case_folder("tyres/A")
    case.free, case.tables, case.profiles
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from ringfit.errors import InputError
from ringfit.io.conditions import OtherPressure, case_inputs, check_stated
from ringfit.io.modes import ModeTable, check_test_condition, read_mode_table
from ringfit.io.tyre import Tyre, read_tyre

@dataclass
class CaseFolder:
    """What a case folder holds, read and checked (see the module docstring).

    - ``folder``; ``tyre``: :class:`~ringfit.io.tyre.Tyre`; ``free``: ``free.modes.csv``;
    - ``tables``: every other mode table, sorted by file name; ``profiles``: the rolling profiles
      (:class:`~ringfit.io.profiles.Profile`), sorted by load, then speed; ``records``: ``*.records.npz`` paths.
    """

    folder: Path
    tyre: Tyre
    free: ModeTable
    tables: list[ModeTable] = field(default_factory=list)
    profiles: list = field(default_factory=list)
    records: list[Path] = field(default_factory=list)

    @property
    def data_files(self) -> list[str]:
        """File names of the data: the free table, the other tables, the profiles."""
        return [Path(str(t.source)).name for t in [self.free, *self.tables]] + \
            [Path(str(p.source)).name for p in self.profiles]


def sidecar_number(cond: dict, key: str):
    """A sidecar value as a float; ``None`` when absent, NaN when not a number."""
    value = cond.get(key)
    if value is None:
        return None
    if isinstance(value, bool):
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def read_case_folder(folder: str | os.PathLike, *, other_pressure: OtherPressure = "warn", used_as: str = "",
                     pressure_law: bool = False) -> CaseFolder:
    """Read and check a case folder (module docstring); :class:`~ringfit.errors.InputError` names the bad file.

    ``other_pressure``, ``used_as``, ``pressure_law``: what the reading command does with a measurement at
    another pressure than the tyre file's (:func:`ringfit.io.conditions.check_stated`)."""
    from ringfit.io.profiles import read_profile

    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("is not a folder; expected a case folder with tyre.toml and free.modes.csv", source=folder)
    tyre_path = folder / "tyre.toml"
    if not tyre_path.exists():
        raise InputError("missing tyre.toml (docs/formats.md §1: [tyre] radius_m, width_m, pressure_bar)", source=folder)
    tyre = read_tyre(tyre_path)
    free_path = folder / "free.modes.csv"
    if not free_path.exists():
        raise InputError("missing free.modes.csv: the free, static tyre's modes the ring is fitted to "
                         "(docs/formats.md §6)", source=folder)
    free = read_mode_table(free_path)
    speed, rotation = sidecar_number(free.condition, "speed_kmh") or 0.0, sidecar_number(free.condition, "rotation_hz") or 0.0
    if free.state != "free" or speed > 0 or rotation > 0:
        raise InputError(f"free.modes.json says state {free.state!r}, speed {free.condition.get('speed_kmh', 0)}; "
                         "free.modes.csv must be the static, free tyre", source=free_path.with_suffix(".json"))

    def stated(item, sidecar):
        item, notes = check_stated(item, tyre.geometry, source=sidecar, other_pressure=other_pressure,
                                   used_as=used_as, pressure_law=pressure_law)
        for note in notes:
            warnings.warn(note, stacklevel=3)
        return item

    case = CaseFolder(folder, tyre, free, records=sorted(folder.glob("*.records.npz")))
    # the same table or profile given twice (a copy, a symlink) is counted once: the data are not twice as sure
    table_paths, profile_paths = case_inputs(folder)
    for p in table_paths:
        sidecar = p.with_suffix(".json")
        if not sidecar.exists():
            raise InputError(f"missing sidecar {sidecar.name}: a test mode table needs its condition (state, "
                             "load_n, speed_kmh/rotation_hz, frame; docs/formats.md §2)", source=p)
        table = read_mode_table(p)
        check_test_condition(table.condition, source=sidecar)
        case.tables.append(stated(table, sidecar))
    for p in profile_paths:
        sidecar = p.with_suffix(".json")
        if not sidecar.exists():
            raise InputError(f"missing sidecar {sidecar.name} (speed_kmh, load_n, ...; docs/formats.md §3)", source=p)
        prof = read_profile(p)
        for key in ("load_n", "speed_kmh"):
            v = sidecar_number(prof.condition, key)
            if v is None or not (math.isfinite(v) and v > 0):
                raise InputError(f"missing or non-positive '{key}' = {prof.condition.get(key)!r}: a profile in a "
                                 f"case folder is modelled at its {key} (docs/formats.md §6)", source=sidecar)
        torque = sidecar_number(prof.condition, "torque_nm")
        if torque is not None and torque != 0.0 and prof.rotation_hz is None:
            warnings.warn(f"{p.name}: a profile at a torque without rotation_hz: Ω = V/R_e of free rolling, off by "
                          "the slip (state the encoder's rotation_hz)", stacklevel=2)
        case.profiles.append(stated(prof, sidecar))
    case.profiles.sort(key=lambda pr: (float(pr.condition["load_n"]), float(pr.condition["speed_kmh"])))
    return case


__all__ = ["read_case_folder", "CaseFolder"]
