"""Safe output files: never overwrite an input, never leave a partial file.

Every writer in ``ringfit.io`` goes through :func:`check_output_path` and an
``atomic_write_*`` function: the content is written to a temporary file in the
same folder and renamed into place only when complete.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path

from ringfit.errors import InputError


def check_output_path(
    path: str | os.PathLike, *, overwrite: bool = False, inputs: Iterable[str | os.PathLike] = ()
) -> Path:
    """Validate an output path before any work is written.

    Raises :class:`InputError` if ``path`` is one of ``inputs`` (never
    overwrite an input), exists and ``overwrite`` is false, or its folder
    does not exist.
    """
    path = Path(path)
    for item in inputs:
        try:
            if Path(item).exists() and path.exists() and os.path.samefile(item, path):
                raise InputError("is an input file; refusing to overwrite it", source=path)
        except OSError:
            pass
        if Path(item).resolve() == path.resolve():
            raise InputError("is an input file; refusing to overwrite it", source=path)
    if path.exists() and not overwrite:
        raise InputError("exists; refusing to overwrite it (pass --force to replace it)", source=path)
    if not path.parent.exists():
        raise InputError(f"folder {path.parent} does not exist", source=path)
    return path


def atomic_write(path: str | os.PathLike, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp_path)`` then rename ``tmp_path`` onto ``path``; clean up on failure."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` to ``path`` atomically."""
    return atomic_write(path, lambda tmp: tmp.write_text(text))


def read_text_file(path: str | os.PathLike) -> str:
    """Text of ``path`` (UTF-8, BOM tolerated); :class:`InputError` naming the file if missing or unreadable."""
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError("file not found", source=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"not a readable text file ({exc.__class__.__name__})", source=path) from None


def load_npz(path: str | os.PathLike):
    """``np.load`` of an ``.npz`` without pickles; :class:`InputError` naming the file if missing or unreadable."""
    import numpy as np

    path = Path(path)
    if not path.exists():
        raise InputError("file not found", source=path)
    try:
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise InputError(f"not a readable .npz file ({exc.__class__.__name__}: {exc})", source=path) from None
