"""Test configuration: float64 everywhere, strict promotion, headless plots; parallel runs.

The default run is parallel (``-n auto --maxprocesses 4`` in pyproject's addopts; pytest-xdist,
in the ``test`` extra) with ``--dist loadfile``: each file's tests stay together on one worker, so a
module-scoped fixture is computed once. (``--dist loadgroup`` with an ``xdist_group`` mark per file did
not group anything under pytest 9.2: xdist 3.8 renames ``item._nodeid``, which pytest 9.2 no longer
reads, so the long module fixtures were computed once per worker.) Each worker gets its own JAX compilation cache folder (JAX
writes cache entries in place, so two processes must not share one). ``-n 0`` runs serially.
"""

import os

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

_WORKER = os.environ.get("PYTEST_XDIST_WORKER")
if _WORKER:  # before anything imports ringfit's cache helper; subprocesses inherit it
    _base = os.environ.get("RINGFIT_CACHE_DIR") or os.path.join(os.path.expanduser("~"), ".cache", "ringfit", "jax")
    os.environ["RINGFIT_CACHE_DIR"] = os.path.join(_base, f"xdist-{_WORKER}")

import jax  # noqa: E402

import ringfit  # noqa: E402,F401  (enables jax_enable_x64)

jax.config.update("jax_numpy_dtype_promotion", "standard")
assert jax.config.jax_enable_x64, "importing ringfit must enable float64"


@pytest.fixture(autouse=True, scope="session")
def _no_kept_programs():
    """In-process tests run the jitted programs themselves, not exported ones kept beside the compilation cache
    (a test that calls ``ringfit.cli.main`` turns the cache on for its whole worker; the compile counts and
    retrace checks of later tests are about the jits). Session-scoped, so that module fixtures — set up before
    any function fixture — see it too (a module's fit made by a kept program and its refit by the jit would
    count a trace). tests/test_exported_programs.py turns them on where it tests them; commands run as
    subprocesses keep them as users do."""
    from ringfit import _cache

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_cache, "_kept_folder", lambda: None)
        yield
