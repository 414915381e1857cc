"""Checks shared by the readers: JSON sidecars, numbers in plausible ranges.

Every reader of ``ringfit.io`` ends either in a valid object or in an
:class:`~ringfit.errors.InputError` of one line naming the file and field;
these helpers hold the parts they share, so that a sidecar field means the
same thing (and has the same plausible range) in every file that carries it
(docs/formats.md §2, §3, §4).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path

from ringfit.errors import InputError

#: Largest plausible inflation pressure [bar] in any file (a tyre file's ``pressure_bar``, a
#: sidecar's, a record's condition): above it the value is almost surely in Pa or kPa.
MAX_PRESSURE_BAR = 20.0

#: Plausible range [lo, hi] of the condition fields of sidecars and continuous
#: records (docs/formats.md §2–§4). Generous on purpose: a value outside is a
#: unit slip (a pressure in Pa, a speed in m/h) or a corrupted file, not a test.
CONDITION_RANGES: dict[str, tuple[float, float]] = {
    "speed_kmh": (0.0, 1000.0),
    "load_n": (0.0, 1.0e6),
    "pressure_bar": (0.0, MAX_PRESSURE_BAR),
    "rotation_hz": (0.0, 1000.0),
    "drum_diameter_m": (0.0, 100.0),
    "revolutions": (1.0, 1.0e9),
    "sample_rate_hz": (0.0, 1.0e8),
    "torque_nm": (-1.0e5, 1.0e5),
    "tread_depth_mm": (0.0, 50.0),
}

#: What a value outside CONDITION_RANGES probably is, for the message.
_HINTS = {"pressure_bar": " (looks like Pa or kPa, not bar; 2.2 bar = 2.2e5 Pa)"}


def read_json_object(path: str | os.PathLike) -> dict:
    """A JSON file that must hold one object; InputError naming the file otherwise.

    Survives what the standard parser does not: nesting deep enough to
    overflow the recursion limit, integers of thousands of digits, bytes
    that are not UTF-8, a directory in place of the file.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError("file not found", source=path) from None
    except IsADirectoryError:
        raise InputError("is a directory; expected a JSON file", source=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"not a readable JSON file ({exc.__class__.__name__})", source=path) from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"not readable JSON ({exc.msg} at line {exc.lineno}, column {exc.colno})",
                         source=path) from None
    except (ValueError, RecursionError, MemoryError) as exc:  # int digit limit, nesting
        why = "nested too deeply" if isinstance(exc, RecursionError) else str(exc).split(";")[0]
        raise InputError(f"not readable JSON ({why})", source=path) from None
    if not isinstance(doc, dict):
        raise InputError(f"expected a JSON object {{...}}, found a {type(doc).__name__}", source=path)
    return doc


def short_repr(value, limit: int = 40) -> str:
    """``repr`` cut to ``limit`` characters (a 400-digit number or a long string stays readable)."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def number_in_range(value, name: str, lo: float | None = None, hi: float | None = None, *,
                    lo_open: bool = False, source=None, what: str = "field") -> float:
    """``value`` as a finite float in [lo, hi] (``lo_open``: lo excluded); InputError naming ``name`` otherwise."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{what} {name!r} = {short_repr(value)}: expected a number", source=source)
    try:
        x = float(value)
    except OverflowError:
        x = math.inf
    if not math.isfinite(x):
        raise InputError(f"{what} {name!r} = {short_repr(value)}: expected a finite number", source=source)
    below = lo is not None and (x <= lo if lo_open else x < lo)
    above = hi is not None and x > hi
    if below or above:
        span = f"{'(' if lo_open else '['}{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]"
        raise InputError(f"{what} {name!r} = {x:g}: outside the plausible range {span}{_HINTS.get(name, '')}",
                         source=source)
    return x


def check_condition_field(doc: dict, key: str, *, source=None, what: str = "field") -> float:
    """Validate ``doc[key]`` against :data:`CONDITION_RANGES`; returns it as a float."""
    lo, hi = CONDITION_RANGES[key]
    value = number_in_range(doc[key], key, lo, hi, source=source, what=what)
    if key == "revolutions" and not value.is_integer():
        raise InputError(f"{what} 'revolutions' = {value:g}: expected a whole number >= 1", source=source)
    return value


def csv_columns(text: str, required: tuple[str, ...], *, source: str,
                empty: str) -> tuple[list[str], dict[str, list[str]], list[int]]:
    """The columns of a CSV file's text as stripped strings (docs/formats.md §0).

    One header row (names stripped of spaces; a duplicate name is an error),
    any column order, blank rows skipped, a missing trailing cell empty, a row
    with more cells than the header an error.

    **Arguments:** ``required`` — columns that must be present; ``source`` —
    the file, for messages; ``empty`` — what the header should hold, for the
    message about an empty file.

    **Returns:** ``(header, columns, lines)``: the names in file order, each
    column's cells, and the file line number of each kept row.
    """
    try:
        reader = csv.DictReader(io.StringIO(text))
        header = [h.strip() for h in (reader.fieldnames or [])]
        if not header:
            raise InputError(f"empty file; expected a header row {empty}", source=source)
        reader.fieldnames = header
        missing = [c for c in required if c not in header]
        if missing:
            listed = ", ".join(repr(c) for c in missing)
            raise InputError(f"missing column{'s' if len(missing) > 1 else ''} {listed} "
                             f"(have: {', '.join(header)}; expected {', '.join(required)})", source=source)
        if len(set(header)) != len(header):
            raise InputError(f"duplicate column names in header {header}", source=source)
        cols: dict[str, list[str]] = {h: [] for h in header}
        lines: list[int] = []
        for line_no, row in enumerate(reader, start=2):
            if None in row:
                raise InputError(f"row {line_no}: more cells than header columns", source=source)
            if all((v or "").strip() == "" for v in row.values()):
                continue
            lines.append(line_no)
            for h in header:
                cols[h].append((row.get(h) or "").strip())
    except csv.Error as exc:  # a cell over the field size limit, a NUL byte
        raise InputError(f"not a readable CSV file ({exc})", source=source) from None
    return header, cols, lines
