"""A case folder (docs/formats.md §6) as the diagnosis uses it: one tyre and everything measured on it.

Read by the one case-folder reader :func:`ringfit.io.case.read_case_folder` (its rules and messages, the same
for ``identify`` and ``campaign``): ``tyre.toml`` and ``free.modes.csv`` are fixed names; every other
``*.modes.csv`` is test data (its sidecar says its state), every ``*.profile.csv`` a rolling profile (its
sidecar is required), every ``*.records.npz`` optional raw records (listed, not used by the diagnosis). The
diagnosis's own rule: a measurement at another pressure than the tyre file's is used at the tyre file's, with
a warning.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

from ringfit.errors import InputError
from ringfit.io.case import read_case_folder
from ringfit.io.modes import ModeTable
from ringfit.io.tyre import Tyre


@dataclass
class Case:
    """The parsed contents of a case folder.

    - ``folder``: the path; ``tyre``: :class:`~ringfit.io.tyre.Tyre`.
    - ``free``: the free-tyre table the ring is fitted to.
    - ``tests``: other mode tables (test data), sorted by file name.
    - ``profiles``: rolling profiles (objects of :mod:`ringfit.io.profiles`), sorted by load, then speed.
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
    """Read and check a case folder (docs/formats.md §6) with the one case-folder reader
    (:func:`ringfit.io.case.read_case_folder`: its rules and messages); raises :class:`InputError` for an incomplete
    one. The diagnosis's own rules: ``free.modes.csv`` holds at least :data:`MIN_FREE_MODES` structural modes with
an n; a measurement at another pressure than the tyre file's is used at the tyre file's, with a warning."""
    c = read_case_folder(folder, other_pressure="warn", used_as=USED_AS)
    if int(((c.free.kind == "structural") & (c.free.n >= 0)).sum()) < MIN_FREE_MODES:
        raise InputError(f"needs at least {MIN_FREE_MODES} structural modes with an assigned n to fit the ring "
                         "(rho_a, EI, kw, kv)", source=c.free.source)
    return Case(folder=c.folder, tyre=c.tyre, free=c.free, tests=c.tables, profiles=c.profiles, records=c.records)


#: Structural modes with an n the diagnosis needs in free.modes.csv: it fits the ring's four eq. 18 parameters to it.
MIN_FREE_MODES = 4
#: How the diagnosis uses a measurement at another pressure than the tyre file's (its warning says so).
USED_AS = "the diagnosis uses it as if measured"
