"""Safe output files: never overwrite an input, never leave a partial file.

Every writer in ``ringfit.io`` goes through :func:`check_output_path` and an
``atomic_write_*`` function: the content is written to a temporary file in the
same folder and renamed into place only when complete. Inside
:func:`outputs_committed_together` (the CLI wraps each command in it) the
renames wait for the end of the block: all outputs of a command appear
together, or none does (a failing plot leaves no mode table behind).

A folder that cannot take a file (read-only, not a folder, no permission)
is found by :func:`check_output_path` before any work, and a write that
fails half-way (disk full) ends in one :class:`InputError` naming the file,
with nothing left behind.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import os
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path

from ringfit.errors import InputError


def sidecar_of(path: str | os.PathLike) -> Path:
    """The JSON sidecar a reader looks for next to ``path``: ``x.modes.csv`` -> ``x.modes.json`` (docs/formats.md §2, §3)."""
    return Path(path).with_suffix(".json")


def protected_inputs(inputs: Iterable[str | os.PathLike]) -> list[Path]:
    """``inputs`` plus the sidecar of each one that has a sidecar on disk: every file a command reads."""
    out = []
    for item in inputs:
        item = Path(item)
        out.append(item)
        if item.suffix.lower() != ".json":
            side = sidecar_of(item)
            if side != item and side.exists():
                out.append(side)
    return out


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists() and os.path.samefile(a, b):
            return True
    except OSError:
        pass
    return a.resolve() == b.resolve()


def check_output_path(
    path: str | os.PathLike, *, overwrite: bool = False, inputs: Iterable[str | os.PathLike] = ()
) -> Path:
    """Validate an output path before any work is written.

    Raises :class:`InputError` (one line naming ``path``) if ``path`` is one of
    ``inputs`` or the JSON sidecar of one of them (a file a command reads is
    never written), is a directory, exists (a dangling symbolic link counts)
    and ``overwrite`` is false, or its folder does not exist.
    """
    path = Path(path)
    try:
        for item in protected_inputs(inputs):
            if _same_file(item, path):
                raise InputError("is an input file; refusing to overwrite it", source=path)
        if path.is_dir():
            raise InputError("is a directory; expected a file name", source=path)
        if os.path.lexists(path) and not overwrite:
            what = "is a dangling symbolic link" if path.is_symlink() and not path.exists() else "exists"
            raise InputError(f"{what}; refusing to overwrite it (pass --force to replace it)", source=path)
        if not path.parent.is_dir():
            raise InputError(f"folder {path.parent} does not exist", source=path)
        _probe_folder(path)
    except OSError as exc:  # a name too long, a loop of links, no permission to look
        raise InputError(f"cannot be used as an output ({exc.strerror or exc.__class__.__name__})", source=path) from None
    return path


def _probe_folder(path: Path) -> None:
    """Create and remove a temporary file beside ``path``: a read-only or unwritable folder refused up front.

    (A permission check alone would not do: root passes ``os.access`` on a read-only mount.)
    """
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:64]}.", suffix=".probe", dir=path.parent)
    except OSError as exc:
        raise InputError(f"cannot be written: folder {path.parent} does not take new files "
                         f"({exc.strerror or exc.__class__.__name__})", source=path) from None
    os.close(fd)
    os.unlink(tmp)


def write_failed(path: str | os.PathLike, exc: OSError) -> InputError:
    """The one-line :class:`InputError` for a write of ``path`` that failed with ``exc`` (disk full, read-only ...)."""
    if exc.errno == errno.ENOSPC:
        why = "no space left on the device"
    elif exc.errno:
        why = exc.strerror or os.strerror(exc.errno)
    else:
        why = " ".join(str(exc).split()) or exc.__class__.__name__
    return InputError(f"could not be written ({why}); nothing was written", source=path)


#: Set by the command line's SIGINT handler (:func:`mark_interrupted`) for the length of a command: a Ctrl-C whose
#: KeyboardInterrupt was swallowed on its way up (raised inside a garbage-collector callback — JAX's
#: ``_xla_gc_callback`` — Python prints "Exception ignored" and goes on) still stops every commit.
_INTERRUPTED = False


def mark_interrupted() -> None:
    """Record a Ctrl-C: from now on no output is committed (:func:`check_not_interrupted`)."""
    global _INTERRUPTED
    _INTERRUPTED = True


def clear_interrupted() -> None:
    """Forget a recorded Ctrl-C (an outermost command starts or ends: its exit status has said it)."""
    global _INTERRUPTED
    _INTERRUPTED = False


def check_not_interrupted() -> None:
    """Raise KeyboardInterrupt when a Ctrl-C was received, even one swallowed since: called before any output is
    renamed into place, so that an interrupted command never replaces its outputs."""
    if _INTERRUPTED:
        raise KeyboardInterrupt


#: Temporary files of :func:`atomic_write`: ``.NAME.rf<pid>.<random>.tmp`` beside the output (hidden, the writing
#: process's id in the name so that a later run can tell its own stale ones from a live writer's).
_TMP_TAG = "rf"
#: A temporary file of the older naming (``.NAME.<random>.tmp``, no process id) older than this [s] is stale.
LEGACY_TMP_AGE_S = 600.0


def clean_stale_temps(path: str | os.PathLike) -> list[Path]:
    """Remove the temporary files :func:`atomic_write` left beside ``path`` in an earlier run that was killed
    (SIGKILL, power loss) between writing and renaming: those whose writing process is gone (or of the older
    naming, older than :data:`LEGACY_TMP_AGE_S`). Only files of our own naming for this output's name are
    touched. Returns those removed."""
    import re
    import time

    path = Path(path)
    stem = re.escape(path.name[:64])
    ours = re.compile(rf"^\.{stem}\.{_TMP_TAG}(\d+)\.[A-Za-z0-9_]{{8}}\.tmp$")
    legacy = re.compile(rf"^\.{stem}\.[A-Za-z0-9_]{{8}}\.tmp$")
    removed = []
    try:
        entries = list(os.scandir(path.parent))
    except OSError:
        return removed
    now = time.time()
    for e in entries:
        m = ours.match(e.name)
        stale = False
        if m is not None:
            pid = int(m.group(1))
            stale = pid != os.getpid() and not _alive(pid)
        elif legacy.match(e.name):
            with contextlib.suppress(OSError):
                stale = now - e.stat(follow_symlinks=False).st_mtime > LEGACY_TMP_AGE_S
        if stale and e.is_file(follow_symlinks=False):
            with contextlib.suppress(OSError):
                os.unlink(e.path)
                removed.append(Path(e.path))
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True  # someone else's live process
    return True


#: Files staged by :func:`atomic_write` inside :func:`outputs_committed_together`: [(tmp, destination)].
_STAGED: contextvars.ContextVar[list | None] = contextvars.ContextVar("ringfit_staged_outputs", default=None)


@contextlib.contextmanager
def outputs_committed_together():
    """Every :func:`atomic_write` inside the block is renamed into place when the block ends without an
    exception; on an exception (or Ctrl-C) none is, and the temporary files are removed.

    Nested blocks join the outermost one. Code inside must not read back what it wrote (the files appear
    only at the end).
    """
    if _STAGED.get() is not None:
        yield
        return
    staged: list[tuple[Path, Path]] = []
    token = _STAGED.set(staged)
    try:
        yield
    except BaseException:
        _discard(staged)
        raise
    finally:
        _STAGED.reset(token)
    _commit(staged)


def _discard(staged) -> None:
    for tmp, _ in staged:
        with contextlib.suppress(OSError):
            tmp.unlink()


def _commit(staged) -> None:
    try:
        check_not_interrupted()
    except KeyboardInterrupt:
        _discard(staged)
        raise
    with _sigint_held():  # a Ctrl-C during the renames waits for their end: all of them, or (before) none
        for i, (tmp, dest) in enumerate(staged):
            try:
                os.replace(tmp, dest)
            except OSError as exc:
                _discard(staged[i:])
                raise write_failed(dest, exc) from None


@contextlib.contextmanager
def _sigint_held():
    """SIGINT blocked for this thread inside the block (delivered when it ends), where the platform allows."""
    import signal

    mask = getattr(signal, "pthread_sigmask", None)
    if mask is None:
        yield
        return
    try:
        old = mask(signal.SIG_BLOCK, {signal.SIGINT})
    except (OSError, ValueError):
        yield
        return
    try:
        yield
    finally:
        mask(signal.SIG_SETMASK, old)


def check_output_paths(
    paths: Iterable[str | os.PathLike | None], *, overwrite: bool = False, inputs: Iterable[str | os.PathLike] = ()
) -> list[Path]:
    """:func:`check_output_path` for each of ``paths`` (``None`` skipped), and no two outputs the same file."""
    inputs = list(inputs)
    seen: list[Path] = []
    for p in paths:
        if p is None:
            continue
        p = check_output_path(p, overwrite=overwrite, inputs=inputs)
        if any(_same_file(p, q) for q in seen):
            raise InputError("is named for two outputs; give each output its own file", source=p)
        seen.append(p)
    return seen


def atomic_write(path: str | os.PathLike, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp_path)`` then rename ``tmp_path`` onto ``path``; clean up on failure."""
    path = Path(path)
    check_not_interrupted()
    clean_stale_temps(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name[:64]}.{_TMP_TAG}{os.getpid()}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise write_failed(path, exc) from None
    os.close(fd)
    tmp = Path(tmp)
    staged = _STAGED.get()
    keep = False
    try:
        try:
            write(tmp)
            os.chmod(tmp, 0o666 & ~_umask())
            if staged is None:
                check_not_interrupted()
                os.replace(tmp, path)
            else:
                for k, (old_tmp, dest) in enumerate(staged):  # a second write of the same output replaces the first
                    if dest == path:
                        with contextlib.suppress(OSError):
                            old_tmp.unlink()
                        del staged[k]
                        break
                staged.append((tmp, path))
                keep = True
        except OSError as exc:
            raise write_failed(path, exc) from None
    finally:
        if not keep and tmp.exists():
            tmp.unlink()
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically."""
    return atomic_write(path, lambda tmp: tmp.write_text(text))


def existing_file(path: str | os.PathLike, expected: str) -> Path:
    """``path`` as a :class:`~pathlib.Path` to a file that exists; :class:`InputError` naming it otherwise.

    **Arguments:** ``expected`` — what the file should be, for the message
    (``"an .npz file"``): a directory in its place is refused with it.
    """
    path = Path(path)
    if not path.exists():
        raise InputError("file not found", source=path)
    if path.is_dir():
        raise InputError(f"is a directory; expected {expected}", source=path)
    return path


def read_text_file(path: str | os.PathLike) -> str:
    """Text of ``path`` (UTF-8, BOM tolerated); :class:`InputError` naming the file if missing or unreadable."""
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError("file not found", source=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"not a readable text file ({exc.__class__.__name__})", source=path) from None


def load_npz(path: str | os.PathLike) -> dict:
    """Every array of an ``.npz`` as a dict, read without pickles.

    **Raises** :class:`InputError` naming the file when it is missing, empty,
    truncated, corrupted (zip CRC), holds object arrays (which would need
    unpickling) or anything else NumPy cannot read.
    """
    import zipfile

    import numpy as np

    path = existing_file(path, "an .npz file")
    try:
        with open(path, "rb") as fh:
            magic = fh.read(4)
    except OSError as exc:
        raise InputError(f"not readable ({exc.strerror or exc.__class__.__name__})", source=path) from None
    if magic[:2] != b"PK":
        why = "empty file" if not magic else "no zip signature"
        raise InputError(f"not a readable .npz file ({why}); truncated, or not an .npz?", source=path)
    try:
        with np.load(path, allow_pickle=False) as data:
            if not isinstance(data, np.lib.npyio.NpzFile):
                raise InputError("is a single .npy array; expected an .npz archive of named arrays", source=path)
            return {key: data[key] for key in data.files}
    except InputError:
        raise
    except ValueError as exc:
        if "allow_pickle" in str(exc):
            raise InputError("holds object arrays, which ringfit does not unpickle; expected numeric and "
                             "string arrays", source=path) from None
        raise InputError(f"not a readable .npz file ({exc.__class__.__name__}: {exc})", source=path) from None
    except (OSError, EOFError, zipfile.BadZipFile, zipfile.LargeZipFile, KeyError, NotImplementedError,
            RuntimeError, MemoryError, UnicodeDecodeError) as exc:
        text = str(exc).splitlines()[0] if str(exc) else ""
        why = "empty file" if path.stat().st_size == 0 else f"{exc.__class__.__name__}: {text}"
        raise InputError(f"not a readable .npz file ({why}); truncated or corrupted?", source=path) from None


def csv_cell(x) -> str:
    """One CSV cell as ringfit writes tables: empty for None or a non-finite number, ``true``/``false``,
    floats to 10 significant digits, anything else ``str``."""
    import math

    import numpy as np

    if x is None:
        return ""
    if isinstance(x, (bool, np.bool_)):
        return "true" if x else "false"
    if isinstance(x, (float, np.floating)):
        return format(float(x), ".10g") if math.isfinite(x) else ""
    return str(x)


def csv_text(header, rows) -> str:
    """CSV text (``\n`` line ends) of ``header`` and ``rows`` (iterables of cells, :func:`csv_cell`)."""
    import csv
    import io

    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    for row in rows:
        writer.writerow([csv_cell(x) for x in row])
    return buf.getvalue()

