"""JAX's persistent compilation cache, so a second run skips XLA compilation.

Every ``ringfit`` command turns it on before it runs (:func:`ringfit.cli.main`), without
importing JAX: when JAX is not loaded yet the settings go into the environment, where JAX
reads them when it is first imported (as ``import ringfit`` does for 64-bit mode); the
environment also carries them to processes the command starts (batch workers).
"""

from __future__ import annotations

import functools
import logging
import os
import sys
from pathlib import Path

#: JAX's settings for the cache, beside the directory: cache every program, however quick to compile
#: (a cold diagnosis compiles a few large programs and a dozen tiny ones; each tiny one costs a
#: fresh process 5–100 ms).
_SETTINGS = {"jax_persistent_cache_min_compile_time_secs": 0.0, "jax_persistent_cache_min_entry_size_bytes": 0}


#: XLA options of every program ringfit compiles itself (:func:`jit`, :class:`ExportedJit`): the CPU
#: backend's classic fusion emitters instead of its newer MLIR ones. ringfit's programs are many small
#: fusions (a solve's loop body, a model's Jacobian), which the newer emitters compile one LLVM module at a
#: time: measured on one core, eq. 18's solve compiles in 0.65–0.9 s instead of 1.9–2.2 s and runs in
#: 0.40 ms instead of 0.54 ms with an identical answer (every output bit equal); the diagnosis's frequency
#: problem compiles in 4.1 s instead of 6.5 s. Other backends ignore the option; a jaxlib that does not
#: know it refuses the first program, which is then compiled without it (:func:`_refuse_option`).
CPU_COMPILE = {"xla_cpu_use_fusion_emitters": False}

#: For programs a cold process compiles once and whose run time is small beside their compile time (eq. 18's
#: fit, the gap's mode-table refits, the static contact solve): also the CPU backend's optimisation off
#: (LLVM -O0), which cuts their compile time by 2–3× again; eq. 18's fit and the contact solve run as fast,
#: the mode-table refits ~1.6× slower (~0.4 s more in a diagnosis that compiles ~2.5 s less). Their
#: answers agree with the optimised program's to rounding (5e-14 relative for the contact solve), which a
#: fit carries into its end point within its tolerances (eq. 18's weakly determined EI lands ~5e-8 apart).
QUICK_COMPILE = {**CPU_COMPILE, "xla_backend_optimization_level": 0}


#: For programs whose run time matters as well as a cold process's compile time (the ensemble sampler's block,
#: :mod:`ringfit.fit.ensemble`): the CPU backend at optimisation level 1. Measured on one core (shared machine)
#: for the free table's block: compile 1.7–2.8 s and 30–54 µs per step against 1.0–1.3 s and 67–89 µs at
#: level 0 (:data:`QUICK_COMPILE`) and 4.3 s and 38 µs with the default level.
BALANCED_COMPILE = {**CPU_COMPILE, "xla_backend_optimization_level": 1}


#: Options this jaxlib refused (``No such compile option``): left out of every later program.
_REFUSED: set[str] = set()


def compiler_options(quick: bool | str = False) -> dict | None:
    """:data:`QUICK_COMPILE` (``quick=True``), :data:`BALANCED_COMPILE` (``quick="balanced"``) or
    :data:`CPU_COMPILE`, less any option this jaxlib refused; ``None`` where none is left."""
    wanted = QUICK_COMPILE if quick is True else BALANCED_COMPILE if quick == "balanced" else CPU_COMPILE
    return {k: v for k, v in wanted.items() if k not in _REFUSED} or None


def _refuse_option(exc: BaseException, quick: bool) -> bool:
    """Whether ``exc`` is this jaxlib refusing one of the options a program was compiled with (named in its
    message, e.g. ``No such compile option: 'xla_…'``); if so the option is left out from now on (a debug line
    on ``ringfit.cache``). Programs are compiled with the options first and only fall back when refused, so
    a jaxlib that knows them (the usual case) pays no probe."""
    text = str(exc)
    for name in compiler_options(quick) or {}:
        if name in text:
            _REFUSED.add(name)
            _log.debug("XLA option %s left out: this jaxlib refused it (%s)", name, text.splitlines()[0][:200])
            return True
    return False


class jit:  # noqa: N801 — used as jax.jit is
    """``jax.jit(fun, **kwargs)`` compiled with :func:`compiler_options` (``quick``: :data:`QUICK_COMPILE`).

    The jitted function is made at the first call (or the first use of an attribute such as ``lower``),
    so importing a module compiles nothing; a call that this jaxlib refuses for an unknown option is made
    again without it (:func:`_refuse_option`). Use as ``jax.jit``:
    ``functools.partial(jit, static_argnames=...)(fun)`` or ``@jit``.
    """

    def __init__(self, fun, *, quick: bool = False, **kwargs):
        functools.update_wrapper(self, fun)
        self._fun, self._quick, self._kwargs = fun, quick, kwargs
        self._jitted = None

    @property
    def jitted(self):
        """The ``jax.jit`` object (made on first use)."""
        if self._jitted is None:
            import jax

            self._jitted = jax.jit(self._fun, compiler_options=compiler_options(self._quick), **self._kwargs)
        return self._jitted

    def __call__(self, *args, **kwargs):
        try:
            return (self._jitted or self.jitted)(*args, **kwargs)
        except Exception as exc:
            if not _refuse_option(exc, self._quick):
                raise
            self._jitted = None  # made again without the refused option
            return self(*args, **kwargs)

    def __getattr__(self, name):  # lower, trace, _cache_size, … of the jitted function
        if name.startswith("__") or name in ("_fun", "_quick", "_kwargs", "_jitted"):
            raise AttributeError(name)
        return getattr(self.jitted, name)

    def __reduce__(self):  # pickled as what it wraps (a batch task's function); the receiver compiles its own
        return _rebuilt_jit, (self._fun, self._quick, self._kwargs)


def _rebuilt_jit(fun, quick, kwargs):
    return jit(fun, quick=quick, **kwargs)


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


# --------------------------------------------------------------------------- exported programs
#: Folder, inside the compilation cache's, of exported programs (``jax.export``, serialised StableHLO).
EXPORT_FOLDER = "exported"

_log = logging.getLogger("ringfit.cache")


class _Unstable(Exception):
    """A static argument with no description that is the same in every process (no exported program)."""


def _describe(obj, depth: int = 0) -> str:
    """A description of a static argument that is the same in every process, or :class:`_Unstable`.

    Plain values by ``repr``; tuples, lists, dicts and dataclasses (``eqx.Module`` included) field by
    field; NumPy arrays by dtype, shape and a hash of their bytes; functions and classes by module and
    qualified name (a closure or lambda is refused: what it captured is not described); tree structures
    by their text (refused where it shows an object's address); other objects by their class and
    attributes. Anything else raises :class:`_Unstable`, and the caller traces as usual.
    """
    import dataclasses
    import hashlib
    import types

    import numpy as np

    if depth > 40:
        raise _Unstable("nested too deep")
    if obj is None or isinstance(obj, (bool, int, float, complex, str, bytes)):
        return repr(obj)
    if isinstance(obj, (tuple, list)):
        return f"{type(obj).__name__}(" + ",".join(_describe(x, depth + 1) for x in obj) + ")"
    if isinstance(obj, dict):
        return "dict(" + ",".join(f"{_describe(k, depth + 1)}:{_describe(v, depth + 1)}"
                                  for k, v in sorted(obj.items(), key=lambda kv: repr(kv[0]))) + ")"
    if isinstance(obj, (np.ndarray, np.generic)):
        a = np.ascontiguousarray(obj)
        return f"array({a.dtype.str},{a.shape},{hashlib.sha256(a.tobytes()).hexdigest()[:24]})"
    if isinstance(obj, functools.partial):
        return (f"partial({_describe(obj.func, depth + 1)},{_describe(obj.args, depth + 1)},"
                f"{_describe(obj.keywords, depth + 1)})")
    if isinstance(obj, (types.FunctionType, type)):
        name = f"{obj.__module__}.{obj.__qualname__}"
        if "<lambda>" in name or "<locals>" in name:
            raise _Unstable(f"local function {name}")
        return name
    if type(obj).__name__ == "PyTreeDef":
        text = str(obj)
        if " at 0x" in text:
            raise _Unstable("a tree structure that shows an object's address")
        return text
    cls = type(obj)
    name = f"{cls.__module__}.{cls.__qualname__}"
    if "<locals>" in name:
        raise _Unstable(f"local class {name}")
    if dataclasses.is_dataclass(obj):
        fields = {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj)}
    elif hasattr(obj, "__dict__"):  # class attributes are source, which the key holds (:func:`_environment`)
        fields = dict(vars(obj))
    else:
        raise _Unstable(f"{name} has no stable description")
    return f"{name}(" + ",".join(f"{k}={_describe(v, depth + 1)}" for k, v in sorted(fields.items())) + ")"


@functools.cache
def _environment() -> str:
    """What else decides a program: the versions of JAX and the libraries traced into it, ringfit's own source
    (a hash of every ``.py`` file of the package: a changed line is a new program), the backend."""
    import hashlib
    import importlib.metadata as md

    import jax

    versions = []
    for dist in ("jax", "jaxlib", "equinox", "optimistix", "lineax"):
        try:
            versions.append(f"{dist}={md.version(dist)}")
        except md.PackageNotFoundError:
            versions.append(f"{dist}=none")
    h = hashlib.sha256()
    package = Path(__file__).resolve().parent
    for path in sorted(package.rglob("*.py")):
        h.update(str(path.relative_to(package)).encode())
        h.update(path.read_bytes())
    flags = (jax.config.jax_enable_x64, jax.config.jax_default_matmul_precision, jax.default_backend())
    return ";".join(versions) + f";ringfit-source={h.hexdigest()};flags={flags}"


def _signature(args) -> tuple:
    """Shapes, dtypes and the tree structure of a call's arguments (what an exported program is specialised to)."""
    import jax
    import numpy as np

    leaves, tree = jax.tree.flatten(args)
    return tree, tuple((np.shape(x), np.result_type(x).str, type(x) in (int, float, complex)) for x in leaves)


def _kept_folder() -> str | None:
    """The compilation cache's folder where it is on (exported programs are kept inside it), else ``None``."""
    jax = sys.modules.get("jax")
    return (jax.config.jax_compilation_cache_dir or None) if jax is not None else None


class ExportedJit:
    """A jitted function whose programs are kept as exported StableHLO beside the compilation cache.

    Called as the jitted function (``fn(*args, **static)``, ``static`` its static keyword arguments).
    Where JAX's persistent compilation cache is on (:func:`enable_compilation_cache`) and the static
    arguments have a description that is the same in every process (:func:`_describe`), the first call
    of each argument signature looks for the program in ``<cache>/exported/``: found, it is deserialised
    (``jax.export``) and run — no tracing or lowering, and XLA's executable comes from the compilation
    cache; not found, the function is exported (traced and lowered once, as the jit would), saved
    (atomically) and run the same way. The file's name is a hash of the function, its static arguments,
    the arguments' shapes and dtypes, the versions of JAX and the libraries, and ringfit's own source:
    any change makes a new program, never a stale one. An entry that cannot be read, does not
    deserialise or does not fit the arguments is ignored (a debug log line on ``ringfit.cache``) and
    written again. Without the cache, or where a static argument has no stable description, it is
    the plain jitted function.

    - ``fn``: the function (traced with ``static`` bound); ``jitted``: the jitted function (:class:`jit`,
      or ``jax.jit``) with the same static argument names, used when no exported program applies;
      ``quick``: the exported program is compiled with :func:`compiler_options` of ``quick``, as ``jitted``
      (a :class:`jit`) is.
    """

    def __init__(self, fn, jitted, quick: bool = False):
        self.fn, self.jitted, self.quick = fn, jitted, quick
        self._programs: dict = {}
        #: how each program of this process was obtained: "loaded", "exported" or "jit" (tests, benchmarks)
        self.sources: list[str] = []

    def __getattr__(self, name):  # lower, _cache_size, … of the jitted function
        return getattr(self.jitted, name)

    def __call__(self, *args, **static):
        folder = _kept_folder()
        if not folder:
            return self.jitted(*args, **static)
        key = (tuple(sorted(static.items())), _signature(args), folder)
        program = self._programs.get(key)
        if program is None:
            program = self._programs[key] = self._program(Path(folder), args, static)
        try:
            return program(*args)
        except Exception as exc:
            if not _refuse_option(exc, self.quick):
                raise
            del self._programs[key]  # made again without the refused option (its key names the options)
            return self(*args, **static)

    def _program(self, folder: Path, args, static):
        import hashlib

        import jax
        from jax import export

        try:
            static_text = _describe(static)
        except _Unstable as why:
            _log.debug("%s: no exported program (%s)", self.fn.__qualname__, why)
            self.sources.append("jit")
            return functools.partial(self.jitted, **static)
        tree, avals = _signature(args)
        text = "\n".join([f"{self.fn.__module__}.{self.fn.__qualname__}", static_text, str(tree), repr(avals),
                          repr(sorted((compiler_options(self.quick) or {}).items())), _environment()])
        path = folder / EXPORT_FOLDER / f"{self.fn.__name__}-{hashlib.sha256(text.encode()).hexdigest()[:40]}.bin"
        exported = None
        if path.exists():
            try:
                exported = export.deserialize(bytearray(path.read_bytes()))
                flat = jax.tree.leaves(args)
                if len(exported.in_avals) != len(flat) or any(
                        tuple(a.shape) != tuple(shape) or a.dtype.str != dtype
                        for a, (shape, dtype, _) in zip(exported.in_avals, avals)):
                    raise ValueError("its arguments are not this call's")
                self.sources.append("loaded")
            except Exception as exc:  # noqa: BLE001 — any unreadable entry is ignored, never trusted
                _log.debug("%s: ignoring the exported program %s (%s: %s)", self.fn.__qualname__, path,
                           type(exc).__name__, exc)
                exported = None
        if exported is None:
            try:
                exported = export.export(jax.jit(functools.partial(self.fn, **static)))(*args)
            except Exception as exc:  # noqa: BLE001 — e.g. a custom call jax.export does not keep: trace as usual
                _log.debug("%s: no exported program (%s: %s)", self.fn.__qualname__, type(exc).__name__, exc)
                self.sources.append("jit")
                return functools.partial(self.jitted, **static)
            self.sources.append("exported")
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
                tmp.write_bytes(exported.serialize())
                os.replace(tmp, path)
            except Exception as exc:  # noqa: BLE001 — a read-only cache, no flatbuffers: run without keeping it
                _log.debug("%s: could not keep the exported program %s (%s)", self.fn.__qualname__, path, exc)

        def run(*call_args):
            return exported.call(*call_args)

        # named as the function, so its XLA program (logs, cache entries) is named as the jit's
        run.__name__ = run.__qualname__ = self.fn.__name__
        return jax.jit(run, compiler_options=compiler_options(self.quick))
