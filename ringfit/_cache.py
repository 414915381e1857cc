"""JAX's persistent compilation cache, so a second run skips XLA compilation."""

from __future__ import annotations

import os
from pathlib import Path


def enable_compilation_cache(directory: str | os.PathLike | None = None) -> Path:
    """Turn on JAX's persistent compilation cache.

    **Arguments:**

    - ``directory``: where compiled executables are kept. Default:
      ``$RINGFIT_CACHE_DIR`` or ``~/.cache/ringfit/jax``.

    **Returns:** the directory used.

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
    import jax

    path = Path(directory or os.environ.get("RINGFIT_CACHE_DIR") or Path.home() / ".cache" / "ringfit" / "jax")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:  # read-only home: run without a cache
        return path
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path
