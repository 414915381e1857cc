"""ringfit — tyre structural dynamics from one embedded accelerometer.

Gong's flexible ring in JAX, fitted to what one tri-axial sensor inside a
tyre records. The names users call, by task (each also a ``ringfit`` command;
equations in docs/physics.md, files in docs/formats.md):

**Free tyre** — ring parameters from a mode table (``ringfit fit``,
``sample``, ``report``):
    read_tyre, read_mode_table, natural_frequencies, fit_natural_frequencies,
    identifiability, sample_posterior, load_posterior, write_report

**Targets from recordings** — mode tables from time records, NumPy only
(``ringfit ssi``, ``frf``):
    read_records, ssi_modes, frf_modes

**Rolling tyre** — the rolling, loaded ring read by the sensor (``ringfit roll``,
``fit-rolling``):
    simulate_profile, read_profile, fit_rolling

**Sim-to-real gap** — where the model is wrong and which effect explains it
(``ringfit diagnose``):
    read_case, diagnose

**Identify once** — one ring from everything measured of a tyre, a case folder
(``ringfit identify``):
    read_identify_folder, identify

**State estimation** — load and contact patch from the sensor
(``ringfit estimate``):
    estimate_load

**Everywhere:**
    RingParams, TyreGeometry, InputError, enable_compilation_cache

Everything else stays importable from the module that defines it, e.g. the
fitting engine under every fit (``ringfit.fit.engine``: ``least_squares``,
``Problem``, ``Coordinate``; ``ringfit.fit.posterior``: ``sample``,
``Posterior``), the source study's tyre (``ringfit.params.table9``), readers and writers (``ringfit.io``), the rolling model
(``ringfit.physics``), the gap diagnosis (``ringfit.gap``) and the Dask batch
machinery (``ringfit.batch``); the documentation site's API reference lists
every module.

Importing ``ringfit`` enables JAX's 64-bit mode (``jax_enable_x64``) for the
whole process: ring stiffnesses span 1e-1 … 1e7 and float32 silently ruins
fits. It does so without importing JAX (``JAX_ENABLE_X64=1`` in the
environment, read when JAX is first imported; or ``jax.config`` when JAX is
already loaded), so ``import ringfit`` and ``ringfit --help`` stay fast.
Public names are re-exported here one by one and imported lazily: the
module that defines each one is imported on first use.
"""

from __future__ import annotations

import importlib
import sys


from ringfit._precision import enable_x64 as _enable_x64

_enable_x64()

__version__ = "0.1.0"

# public name -> the module that defines it, by task (in the order of the docstring)
_EXPORTS = {
    # free tyre
    "read_tyre": "ringfit.io.tyre",
    "read_mode_table": "ringfit.io.modes",
    "natural_frequencies": "ringfit.physics.natural",
    "fit_natural_frequencies": "ringfit.fit.least_squares",
    "identifiability": "ringfit.fit.identifiability",
    "sample_posterior": "ringfit.fit.posterior",
    "load_posterior": "ringfit.fit.posterior",
    "write_report": "ringfit.report.html",
    # targets from recordings
    "read_records": "ringfit.io.records",
    "ssi_modes": "ringfit.targets.identify",
    "frf_modes": "ringfit.targets.frf",
    # rolling tyre
    "simulate_profile": "ringfit.physics.profile",
    "read_profile": "ringfit.io.profiles",
    "fit_rolling": "ringfit.fit.rolling",
    # sim-to-real gap
    "read_case": "ringfit.gap.case",
    "diagnose": "ringfit.gap.diagnosis",
    # identify once
    "read_identify_folder": "ringfit.fit.identify",
    "identify": "ringfit.fit.identify",
    # state estimation
    "estimate_load": "ringfit.fit.estimate.load",
    # everywhere
    "RingParams": "ringfit.params",
    "TyreGeometry": "ringfit.params",
    "InputError": "ringfit.errors",
    "enable_compilation_cache": "ringfit._cache",
}

#: Names ringfit exported before issue 24 trimmed its namespace: where they live now (an
#: ``AttributeError`` says so instead of a bare 'no attribute').
_ELSEWHERE = {
    "Task": "ringfit.batch",
    "TaskResult": "ringfit.batch",
    "execute": "ringfit.batch",
    "local_cluster": "ringfit.batch",
    "open_client": "ringfit.batch",
    "run_tasks": "ringfit.batch",
    "Coordinate": "ringfit.fit.engine",
    "GaussianPrior": "ringfit.fit.engine",
    "Problem": "ringfit.fit.engine",
    "least_squares": "ringfit.fit.engine",
    "EstimateSettings": "ringfit.fit.estimate.problem",
    "LoadEstimate": "ringfit.fit.estimate.load",
    "RevolutionEstimates": "ringfit.fit.estimate.revolutions",
    "estimate_recording": "ringfit.fit.estimate.revolutions",
    "Identifiability": "ringfit.fit.identifiability",
    "Posterior": "ringfit.fit.posterior",
    "log_probability_function": "ringfit.fit.posterior",
    "sample": "ringfit.fit.posterior",
    "FitResult": "ringfit.fit.result",
    "source_study_fit": "ringfit.fit.source_procedure",
    "CaseFolder": "ringfit.io.case",
    "Diagnosis": "ringfit.gap.diagnosis",
    "read_diagnosis": "ringfit.gap.diagnosis",
    "ContinuousRecord": "ringfit.io.continuous",
    "read_continuous": "ringfit.io.continuous",
    "ModeTable": "ringfit.io.modes",
    "write_mode_table": "ringfit.io.modes",
    "Profile": "ringfit.io.profiles",
    "write_profile": "ringfit.io.profiles",
    "MeasuredFRF": "ringfit.io.record_types",
    "Records": "ringfit.io.record_types",
    "read_measurement": "ringfit.io.records",
    "write_records": "ringfit.io.records",
    "Tyre": "ringfit.io.tyre",
    "write_tyre": "ringfit.io.tyre",
    "table9": "ringfit.params",
    "ContactSolver": "ringfit.physics.contact",
    "RollingSolution": "ringfit.physics.contact",
    "solve_rolling": "ringfit.physics.contact",
    "loaded_natural_frequencies": "ringfit.physics.loaded",
    "cavity_frequency": "ringfit.physics.natural",
    "critical_speed": "ringfit.physics.natural",
    "extensible_natural_frequencies": "ringfit.physics.natural",
    "fixed_frame_frequencies": "ringfit.physics.natural",
    "ring_modal_mass": "ringfit.physics.natural",
    "rotating_from_static": "ringfit.physics.natural",
    "rotating_natural_frequencies": "ringfit.physics.natural",
    "Drum": "ringfit.physics.operating",
    "FlatRoad": "ringfit.physics.operating",
    "OperatingPoint": "ringfit.physics.operating",
    "ProfileModel": "ringfit.physics.profile",
    "SensorModel": "ringfit.physics.sensor",
    "sensor_signals": "ringfit.physics.sensor",
    "AngleTimeField": "ringfit.targets.cleat",
    "angle_time_field": "ringfit.targets.cleat",
    "identify_rolling_modes": "ringfit.targets.rolling_modes",
    "rolling_profile": "ringfit.targets.rolling_profile",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        if name in _ELSEWHERE:
            raise AttributeError(f"module 'ringfit' has no attribute {name!r}: import it from its module, "
                                 f"`from {_ELSEWHERE[name]} import {name}`")
        raise AttributeError(f"module 'ringfit' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
