"""ringfit — tyre structural dynamics from one embedded accelerometer.

Importing ``ringfit`` enables JAX's 64-bit mode (``jax_enable_x64``) for the
whole process: ring stiffnesses span 1e-1 … 1e7 and float32 silently ruins
fits. It does so without importing JAX (``JAX_ENABLE_X64=1`` in the
environment, read when JAX is first imported; or ``jax.config`` when JAX is
already loaded), so ``import ringfit`` and ``ringfit --help`` stay fast.
Public names are re-exported here one by one and imported lazily.
"""

from __future__ import annotations

import importlib
import os
import sys


def _enable_x64() -> None:
    if "jax" in sys.modules:
        sys.modules["jax"].config.update("jax_enable_x64", True)
    else:
        os.environ["JAX_ENABLE_X64"] = "1"


_enable_x64()

__version__ = "0.1.0"

# public name -> module that defines it
_EXPORTS = {
    "TyreGeometry": "ringfit.params",
    "RingParams": "ringfit.params",
    "table9": "ringfit.params",
    "Tyre": "ringfit.io.tyre",
    "read_tyre": "ringfit.io.tyre",
    "write_tyre": "ringfit.io.tyre",
    "ModeTable": "ringfit.io.modes",
    "read_mode_table": "ringfit.io.modes",
    "write_mode_table": "ringfit.io.modes",
    "natural_frequencies": "ringfit.physics.natural",
    "extensible_natural_frequencies": "ringfit.physics.natural",
    "rotating_natural_frequencies": "ringfit.physics.natural",
    "fixed_frame_frequencies": "ringfit.physics.natural",
    "cavity_frequency": "ringfit.physics.natural",
    "critical_speed": "ringfit.physics.natural",
    "rotating_from_static": "ringfit.physics.natural",
    "loaded_natural_frequencies": "ringfit.physics.loaded",
    "diagnose": "ringfit.gap.diagnosis",
    "read_case": "ringfit.gap.case",
    "fit_natural_frequencies": "ringfit.fit.least_squares",
    "FitResult": "ringfit.fit.result",
    "source_study_fit": "ringfit.fit.source_procedure",
    "identifiability": "ringfit.fit.identifiability",
    "sample_posterior": "ringfit.fit.posterior",
    "Posterior": "ringfit.fit.posterior",
    "load_posterior": "ringfit.fit.posterior",
    "write_report": "ringfit.report.html",
    "enable_compilation_cache": "ringfit._cache",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'ringfit' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(list(globals()) + __all__)
