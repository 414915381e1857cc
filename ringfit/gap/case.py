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

from ringfit.errors import InputError
from ringfit.io.case import CaseFolder, read_case_folder


#: The parsed contents of a case folder: the one reader's :class:`ringfit.io.case.CaseFolder` (``free``; ``tables``,
#: the test data; ``profiles``; ``records``), which the diagnosis uses as it is.
Case = CaseFolder


def read_case(folder: str | os.PathLike) -> Case:
    """Read and check a case folder (docs/formats.md §6) with the one case-folder reader
    (:func:`ringfit.io.case.read_case_folder`: its rules and messages); raises :class:`InputError` for an incomplete
    one. The diagnosis's own rules: ``free.modes.csv`` holds at least :data:`MIN_FREE_MODES` structural modes with
an n; a measurement at another pressure than the tyre file's is used at the tyre file's, with a warning."""
    c = read_case_folder(folder, other_pressure="warn", used_as=USED_AS)
    if int(((c.free.kind == "structural") & (c.free.n >= 0)).sum()) < MIN_FREE_MODES:
        raise InputError(f"needs at least {MIN_FREE_MODES} structural modes with an assigned n to fit the ring "
                         "(rho_a, EI, kw, kv)", source=c.free.source)
    return c


#: Structural modes with an n the diagnosis needs in free.modes.csv: it fits the ring's four eq. 18 parameters to it.
MIN_FREE_MODES = 4
#: How the diagnosis uses a measurement at another pressure than the tyre file's (its warning says so).
USED_AS = "the diagnosis uses it as if measured"
