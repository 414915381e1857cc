"""The library of candidate effects, and the registry a user adds to.

Built-in effects (docs/physics.md §6, docs/formats.md §5 names): one module each,
imported on first use. A user effect is one module that subclasses
:class:`~ringfit.gap.effects.base.Effect` and calls :func:`register`; load it
with :func:`load_effect_module` (the CLI's ``--effect-module``), see
``docs/adding-an-effect.md``.
"""

from __future__ import annotations

import importlib

from ringfit.gap.effects.base import Effect, Parameter

#: Built-in effect modules, in the order of docs/formats.md §5.
BUILTIN = (
    "sensor_tilt", "gravity", "iepe_highpass", "wave_damping", "tread_shear",
    "ground_contact", "rotation", "cavity_mode", "sensor_mass", "ring_extensibility", "wheel_suspension",
    "damping_growth", "viscous_damping",
)

_REGISTRY: dict[str, Effect] = {}
_LOADED = False


def register(effect: Effect) -> Effect:
    """Add ``effect`` to the library (replacing one of the same name); returns it."""
    if not isinstance(effect, Effect) or not effect.name:
        raise TypeError("register() takes an Effect instance with a non-empty name")
    _REGISTRY[effect.name] = effect
    return effect


def _load_builtin() -> None:
    global _LOADED
    if not _LOADED:
        _LOADED = True
        for name in BUILTIN:
            importlib.import_module(f"ringfit.gap.effects.{name}")


def load_effect_module(module: str) -> None:
    """Import a user module that registers one or more effects (``package.module`` or a ``.py`` path)."""
    from pathlib import Path

    if module.endswith(".py"):
        import importlib.util

        spec = importlib.util.spec_from_file_location(Path(module).stem, module)
        if spec is None or spec.loader is None:
            raise ImportError(f"cannot load effect module {module}")
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    else:
        importlib.import_module(module)


def available() -> tuple[str, ...]:
    """Names of every registered effect (built-ins first)."""
    _load_builtin()
    return tuple(_REGISTRY)


def get(name: str) -> Effect:
    """The registered effect called ``name``; ``KeyError`` listing the known names otherwise."""
    _load_builtin()
    try:
        return _REGISTRY[name]
    except KeyError:
        raise KeyError(f"unknown effect {name!r}; known: {', '.join(_REGISTRY)}") from None


__all__ = ["Effect", "Parameter", "register", "get", "available", "load_effect_module", "BUILTIN"]
