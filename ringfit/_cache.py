"""JAX's persistent compilation cache, so a second run skips XLA compilation.

Every ``ringfit`` command turns it on before it runs (:func:`ringfit.cli.main`), without
importing JAX: when JAX is not loaded yet the settings go into the environment, where JAX
reads them when it is first imported (as ``import ringfit`` does for 64-bit mode); the
environment also carries them to processes the command starts (batch workers).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: JAX's settings for the cache, beside the directory: cache every program, however quick to compile
#: (a cold diagnosis compiles a few large programs and a dozen tiny ones; each tiny one costs a
#: fresh process 5–100 ms).
_SETTINGS = {"jax_persistent_cache_min_compile_time_secs": 0.0, "jax_persistent_cache_min_entry_size_bytes": 0}


#: XLA options for programs a cold process compiles once and runs for milliseconds (the gap's damping
#: refits, the static contact solve): the CPU backend's optimisation off (LLVM -O0) about halves their
#: compile time; their run time, measured, is the same. Their answers agree with the optimised program's
#: to rounding (5e-14 relative for the contact solve), which a fit can carry into its end point within its
#: tolerances — so eq. 18's fit, whose weakly determined EI lands ~5e-8 apart, keeps the optimised program.
QUICK_COMPILE = {"xla_backend_optimization_level": 0}


def cache_directory(directory: str | os.PathLike | None = None) -> Path:
    """The cache's directory: ``directory``, else ``$RINGFIT_CACHE_DIR``, else ``~/.cache/ringfit/jax``."""
    return Path(directory or os.environ.get("RINGFIT_CACHE_DIR") or Path.home() / ".cache" / "ringfit" / "jax")


def enable_compilation_cache(directory: str | os.PathLike | None = None) -> Path:
    """Turn on JAX's persistent compilation cache (imports no JAX; see the module docstring).

    **Arguments:**

    - ``directory``: where compiled executables are kept. Default:
      ``$RINGFIT_CACHE_DIR`` or ``~/.cache/ringfit/jax``.

    **Returns:** the directory used (a directory that cannot be created leaves the cache off).

    Examples
    --------
    >>> import tempfile, jax
    >>> from ringfit._cache import enable_compilation_cache
    >>> before = jax.config.jax_compilation_cache_dir
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     used = enable_compilation_cache(tmp)
    ...     print(used == Path(tmp), jax.config.jax_compilation_cache_dir == tmp)
    ...     jax.config.update("jax_compilation_cache_dir", before)  # as it was
    True True
    """
    path = cache_directory(directory)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:  # read-only home: run without a cache
        return path
    settings = {"jax_compilation_cache_dir": str(path), **_SETTINGS}
    if "jax" in sys.modules:
        for key, value in settings.items():
            sys.modules["jax"].config.update(key, value)
    else:
        for key, value in settings.items():
            os.environ[key.upper()] = str(value)
    return path
