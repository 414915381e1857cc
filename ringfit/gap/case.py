"""A case folder (docs/formats.md §6): one tyre and everything measured on it.

``tyre.toml`` and ``free.modes.csv`` are fixed names; every other
``*.modes.csv`` is test data (its sidecar says its state), every
``*.profile.csv`` a rolling profile (its sidecar is required), every
``*.records.npz`` optional raw records (listed, not used by the diagnosis).
Errors are :class:`~ringfit.errors.InputError` with one line naming the
missing or bad file. Stated conditions are checked on reading (:mod:`ringfit.io.conditions`,
docs/formats.md §6): a duplicate table or profile is counted once, a table whose ``rotation_hz`` and
``speed_kmh`` contradict is refused, a profile's contradiction is settled by its contact patch or refused,
and a measurement at another pressure than the tyre file's is a warning.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

from ringfit.errors import InputError
from ringfit.io.conditions import case_inputs, check_stated
from ringfit.io.modes import ModeTable, check_test_condition, read_mode_table
from ringfit.io.tyre import Tyre, read_tyre


@dataclass
class Case:
    """The parsed contents of a case folder.

    - ``folder``: the path; ``tyre``: :class:`~ringfit.io.tyre.Tyre`.
    - ``free``: the free-tyre table the ring is fitted to.
    - ``tests``: other mode tables (test data), sorted by file name.
    - ``profiles``: rolling profiles (objects of :mod:`ringfit.io.profiles`), sorted by speed.
    - ``records``: paths of ``*.records.npz`` files (not used by the diagnosis).
    """

    folder: Path
    tyre: Tyre
    free: ModeTable
    tests: list[ModeTable] = field(default_factory=list)
    profiles: list = field(default_factory=list)
    records: list[Path] = field(default_factory=list)

    @property
    def data_files(self) -> list[str]:
        names = [Path(t.source).name for t in [self.free, *self.tests]]
        names += [Path(str(getattr(p, "source", ""))).name for p in self.profiles]
        return names


def read_case(folder: str | os.PathLike) -> Case:
    """Read and check a case folder (docs/formats.md §6); raises :class:`InputError` for an incomplete one."""
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
    if free.state != "free" or float(free.condition.get("speed_kmh") or 0) > 0 or \
            float(free.condition.get("rotation_hz") or 0) > 0:
        raise InputError(f"free.modes.json says state {free.state!r}, speed {free.condition.get('speed_kmh', 0)}; "
                         "free.modes.csv must be the static, free tyre", source=folder / "free.modes.json")
    if int(((free.kind == "structural") & (free.n >= 0)).sum()) < 4:
        raise InputError("needs at least 4 structural modes with an assigned n to fit the ring "
                         "(rho_a, EI, kw, kv)", source=free_path)
    tests = []
    # the same table or profile given twice (a copy, a symlink) is counted once (docs/formats.md §6)
    table_paths, profile_paths = case_inputs(folder)
    for p in table_paths:
        if not p.with_suffix(".json").exists():
            raise InputError(f"missing sidecar {p.with_suffix('.json').name}: a test mode table needs its "
                             "condition (state, load_n, speed_kmh/rotation_hz, frame; docs/formats.md §2)", source=p)
        table = read_mode_table(p)
        check_test_condition(table.condition, source=p.with_suffix(".json"))
        table, notes = check_stated(table, tyre.geometry, source=p.with_suffix(".json"), other_pressure="warn",
                                    used_as=USED_AS)
        for note in notes:
            warnings.warn(note, stacklevel=2)
        tests.append(table)
    profiles = []
    if profile_paths:
        try:
            from ringfit.io.profiles import read_profile
        except ImportError as exc:  # pragma: no cover - profiles module ships with ringfit
            raise InputError(f"cannot read profiles: {exc}", source=folder) from None
        for p in profile_paths:
            if not p.with_suffix(".json").exists():
                raise InputError(f"missing sidecar {p.with_suffix('.json').name} (speed_kmh, load_n, ...; "
                                 "docs/formats.md §3)", source=p)
            prof = read_profile(p)
            prof, notes = check_stated(prof, tyre.geometry, source=p.with_suffix(".json"), other_pressure="warn",
                                       used_as=USED_AS)
            for note in notes:
                warnings.warn(note, stacklevel=2)
            profiles.append(prof)
        profiles.sort(key=lambda pr: float(_condition(pr).get("speed_kmh", 0.0)))
    records = sorted(folder.glob("*.records.npz"))
    return Case(folder=folder, tyre=tyre, free=free, tests=tests, profiles=profiles, records=records)


#: How the diagnosis uses a measurement at another pressure than the tyre file's (its warning says so).
USED_AS = "the diagnosis uses it as if measured"


def _condition(profile) -> dict:
    for name in ("condition", "meta", "sidecar"):
        c = getattr(profile, name, None)
        if isinstance(c, dict):
            return c
    return {}
