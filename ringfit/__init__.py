"""ringfit — tyre structural dynamics from one embedded accelerometer.

Gong's flexible ring in JAX, fitted to what one tri-axial sensor inside a
tyre records. The entry points, by task (each also a ``ringfit`` command;
equations in docs/physics.md, files in docs/formats.md):

**Free tyre** — ring parameters from a mode table (``ringfit fit``,
``sample``, ``report``, ``demo``):
    read_tyre, write_tyre, Tyre, table9, RingParams, TyreGeometry,
    read_mode_table, write_mode_table, ModeTable,
    natural_frequencies, extensible_natural_frequencies, rotating_natural_frequencies,
    fixed_frame_frequencies, rotating_from_static, cavity_frequency, critical_speed,
    ring_modal_mass, loaded_natural_frequencies,
    fit_natural_frequencies, source_study_fit, identifiability, Identifiability,
    sample_posterior, Posterior, load_posterior, write_report

**The fitting engine** under every fit (free tyre, rolling, gap refits):
    least_squares, Problem, Coordinate, GaussianPrior, FitResult, sample,
    log_probability_function

**Targets from recordings** — mode tables, profiles and cleat fields from
time records, NumPy only (``ringfit ssi``, ``frf``, ``profile``, ``cleat``):
    read_records, read_measurement, write_records, Records, MeasuredFRF,
    read_continuous, ContinuousRecord,
    ssi_modes, frf_modes, rolling_profile, angle_time_field, AngleTimeField,
    identify_rolling_modes

**Rolling tyre** — steady rolling contact and the sensor's reading
(``ringfit roll``, ``fit-rolling``):
    read_profile, write_profile, Profile,
    OperatingPoint, FlatRoad, Drum, ContactSolver, solve_rolling, RollingSolution,
    SensorModel, sensor_signals, ProfileModel, simulate_profile, fit_rolling

**Sim-to-real gap** — where the model is wrong and which effect explains it
(``ringfit diagnose``):
    read_case, Case, diagnose, Diagnosis, read_diagnosis

**State estimation** — load and contact patch from the sensor
(``ringfit estimate``): not yet in this package (issue 15).

**Batch** — many inputs as tasks on dask.distributed (``ringfit batch``,
``campaign``; ``pip install 'ringfit[batch]'``):
    Task, TaskResult, execute, run_tasks, open_client, local_cluster

**Everywhere:**
    InputError, enable_compilation_cache

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
import os
import sys


def _enable_x64() -> None:
    if "jax" in sys.modules:
        sys.modules["jax"].config.update("jax_enable_x64", True)
    else:
        os.environ["JAX_ENABLE_X64"] = "1"


_enable_x64()

__version__ = "0.1.0"

# public name -> the module that defines it, by task (in the order of the docstring)
_EXPORTS = {
    # free tyre
    "read_tyre": "ringfit.io.tyre",
    "write_tyre": "ringfit.io.tyre",
    "Tyre": "ringfit.io.tyre",
    "table9": "ringfit.params",
    "RingParams": "ringfit.params",
    "TyreGeometry": "ringfit.params",
    "read_mode_table": "ringfit.io.modes",
    "write_mode_table": "ringfit.io.modes",
    "ModeTable": "ringfit.io.modes",
    "natural_frequencies": "ringfit.physics.natural",
    "extensible_natural_frequencies": "ringfit.physics.natural",
    "rotating_natural_frequencies": "ringfit.physics.natural",
    "fixed_frame_frequencies": "ringfit.physics.natural",
    "rotating_from_static": "ringfit.physics.natural",
    "cavity_frequency": "ringfit.physics.natural",
    "critical_speed": "ringfit.physics.natural",
    "ring_modal_mass": "ringfit.physics.natural",
    "loaded_natural_frequencies": "ringfit.physics.loaded",
    "fit_natural_frequencies": "ringfit.fit.least_squares",
    "source_study_fit": "ringfit.fit.source_procedure",
    "identifiability": "ringfit.fit.identifiability",
    "Identifiability": "ringfit.fit.identifiability",
    "sample_posterior": "ringfit.fit.posterior",
    "Posterior": "ringfit.fit.posterior",
    "load_posterior": "ringfit.fit.posterior",
    "write_report": "ringfit.report.html",
    # the fitting engine
    "least_squares": "ringfit.fit.engine",
    "Problem": "ringfit.fit.engine",
    "Coordinate": "ringfit.fit.engine",
    "GaussianPrior": "ringfit.fit.engine",
    "FitResult": "ringfit.fit.result",
    "sample": "ringfit.fit.posterior",
    "log_probability_function": "ringfit.fit.posterior",
    # targets from recordings
    "read_records": "ringfit.io.records",
    "read_measurement": "ringfit.io.records",
    "write_records": "ringfit.io.records",
    "Records": "ringfit.io.record_types",
    "MeasuredFRF": "ringfit.io.record_types",
    "read_continuous": "ringfit.io.continuous",
    "ContinuousRecord": "ringfit.io.continuous",
    "ssi_modes": "ringfit.targets.identify",
    "frf_modes": "ringfit.targets.frf",
    "rolling_profile": "ringfit.targets.rolling_profile",
    "angle_time_field": "ringfit.targets.cleat",
    "AngleTimeField": "ringfit.targets.cleat",
    "identify_rolling_modes": "ringfit.targets.rolling_modes",
    # rolling tyre
    "read_profile": "ringfit.io.profiles",
    "write_profile": "ringfit.io.profiles",
    "Profile": "ringfit.io.profiles",
    "OperatingPoint": "ringfit.physics.operating",
    "FlatRoad": "ringfit.physics.operating",
    "Drum": "ringfit.physics.operating",
    "ContactSolver": "ringfit.physics.contact",
    "solve_rolling": "ringfit.physics.contact",
    "RollingSolution": "ringfit.physics.contact",
    "SensorModel": "ringfit.physics.sensor",
    "sensor_signals": "ringfit.physics.sensor",
    "ProfileModel": "ringfit.physics.profile",
    "simulate_profile": "ringfit.physics.profile",
    "fit_rolling": "ringfit.fit.rolling",
    # sim-to-real gap
    "read_case": "ringfit.gap.case",
    "Case": "ringfit.gap.case",
    "diagnose": "ringfit.gap.diagnosis",
    "Diagnosis": "ringfit.gap.diagnosis",
    "read_diagnosis": "ringfit.gap.diagnosis",
    # state estimation
    # TODO(issue 15): export estimate_load (and its result type) here and list it under
    # "State estimation" in the docstring once ringfit/fit/estimate.py is on main.
    # batch
    "Task": "ringfit.batch",
    "TaskResult": "ringfit.batch",
    "execute": "ringfit.batch",
    "run_tasks": "ringfit.batch",
    "open_client": "ringfit.batch",
    "local_cluster": "ringfit.batch",
    # everywhere
    "InputError": "ringfit.errors",
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
    return sorted(set(globals()) | set(__all__))
