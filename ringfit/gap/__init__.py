"""Sim-to-real gap diagnosis: where model and measurement disagree, which missing effect explains it, how far it shrinks.

Public entry points: :func:`diagnose` (a case folder → :class:`Diagnosis`,
JSON of docs/formats.md §5), :func:`read_case` (docs/formats.md §6), the effect registry
:mod:`ringfit.gap.effects`.
"""

from ringfit._precision import enable_x64

enable_x64()  # float64 even when ``ringfit`` itself is shadowed (ringfit._precision)

from ringfit.gap.case import Case, read_case
from ringfit.gap.diagnosis import Diagnosis, diagnose, read_diagnosis

__all__ = ["diagnose", "Diagnosis", "read_case", "Case", "read_diagnosis"]
