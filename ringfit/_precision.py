"""float64 everywhere: switch JAX's 64-bit mode on, and refuse to compute without it.

Ring stiffnesses span 1e-1 … 1e7 and float32 silently ruins fits (docs/physics.md §1, numerics).
``import ringfit`` turns 64-bit mode on, but a folder named ``ringfit`` on the import path (the
clone's parent, say) makes ``ringfit`` a namespace package whose ``__init__`` never runs; the
submodules still import from the installed package. So every package that computes with JAX
(``ringfit.physics``, ``ringfit.fit``, ``ringfit.gap``, ``ringfit.synth``, ``ringfit.params``) calls
:func:`enable_x64` when it is imported, and every fit and command calls :func:`require_x64` before it
computes: if 64-bit mode was switched off afterwards (``jax.config.update("jax_enable_x64", False)``),
it refuses with one line instead of running in float32.

Neither function imports JAX when it is not loaded yet (``ringfit --help`` stays fast).
"""

from __future__ import annotations

import os
import sys


class PrecisionError(RuntimeError):
    """JAX's 64-bit mode is off: ringfit refuses to compute in float32."""


def enable_x64() -> None:
    """Switch JAX's 64-bit mode on for the process (``JAX_ENABLE_X64=1`` before JAX loads, else its config)."""
    if "jax" in sys.modules:
        sys.modules["jax"].config.update("jax_enable_x64", True)
    else:
        os.environ["JAX_ENABLE_X64"] = "1"


def x64_enabled() -> bool:
    """Whether JAX computes in float64 (JAX's config once it is loaded, else the environment it will read)."""
    jax = sys.modules.get("jax")
    if jax is not None:
        return bool(jax.config.jax_enable_x64)
    return os.environ.get("JAX_ENABLE_X64", "").strip().lower() in {"1", "true", "yes", "on"}


def require_x64(where: str = "ringfit") -> None:
    """Raise :class:`PrecisionError` (one line) unless JAX's 64-bit mode is on."""
    if not x64_enabled():
        raise PrecisionError(
            f"{where}: JAX's 64-bit mode is off (jax_enable_x64 is False), and ringfit does not compute in "
            "float32; remove the jax.config.update('jax_enable_x64', False) or the JAX_ENABLE_X64=0 that "
            "turned it off, or import ringfit before changing it")
