"""Mode tables — ``*.modes.csv`` with an optional ``*.modes.json`` sidecar (docs/formats.md §2).

A :class:`ModeTable` holds one row per identified mode as NumPy columns.
Reading validates every cell and names file, row and column on error;
writing is atomic and round-trips exactly (floats are written with ``repr``).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from ringfit.errors import InputError
from ringfit.io.checks import check_condition_field, csv_columns, number_in_range, read_json_object, short_repr
from ringfit.io.files import atomic_write, check_output_path, read_text_file

KINDS = ("structural", "acoustic", "unclassified")
TAGS = ("", "extr", "0", "vert", "hort")
BRANCHES = ("", "backward", "forward")
STATES = ("free", "loaded", "rolling")
#: A table's frame, as a type (:data:`FRAMES`).
Frame = Literal["rotating", "fixed"]
FRAMES: tuple[str, ...] = get_args(Frame)
#: How the rim was held (sidecar ``fixture``, docs/formats.md §2): ``bolted`` = rim fixed (the default).
FIXTURES = ("bolted", "suspension")
#: The wheel body's sidecar keys (``fixture: suspension``) with their plausible ranges (stiffness, mass: lo excluded) ...
WHEEL_SCALARS = {
    "wheel_mass_kg": (0.0, 1.0e4),
    "wheel_inertia_kg_m2": (0.0, 1.0e3),
    "suspension_torsion_n_m_rad": (0.0, 1.0e12),
    "suspension_torsion_damping_n_m_s_rad": (0.0, 1.0e9),
}
#: ... and the keys that give [vertical, fore-aft] (a single number = both).
WHEEL_PAIRS = {"suspension_stiffness_n_m": (0.0, 1.0e12), "suspension_damping_n_s_m": (0.0, 1.0e9)}
#: Columns of docs/formats.md §2, in the order ringfit writes them.
COLUMNS = ("n", "a", "tag", "kind", "freq_hz", "freq_std_hz", "damping_pct", "branch")
#: Largest plausible natural frequency [Hz] in a mode table (a tyre's modes lie below a few kHz).
MAX_FREQ_HZ = 1.0e5
#: Largest circumferential / cross-sectional index accepted.
MAX_INDEX = 1000
#: Largest modal damping accepted [%] (100 % is critical damping: no longer a mode).
MAX_DAMPING_PCT = 100.0


@dataclass
class ModeTable:
    """Identified modes, one entry per row (docs/formats.md §2).

    **Fields** (arrays of shape ``(modes,)``):

    - ``n``: circumferential index, int; ``-1`` where not assigned.
    - ``a``: cross-sectional index, int.
    - ``tag``: loaded-tyre label (``""``, ``extr``, ``0``, ``vert``, ``hort``).
    - ``kind``: ``structural``, ``acoustic`` or ``unclassified`` (not ring-like, not shown to be the cavity).
    - ``freq_hz``: natural frequency [Hz].
    - ``freq_std_hz``: one standard deviation [Hz]; NaN where unknown.
    - ``damping_pct``: modal damping ratio [%]; NaN where unknown.
    - ``branch``: ``""``, ``backward`` or ``forward`` (rotating tyre).
    - ``extra``: other columns, name -> array of str, kept and written back.
    - ``condition``: the sidecar's content (``state``, ``speed_kmh``, ...), may be empty.
    - ``source``: the file it came from, for messages.
    """

    freq_hz: np.ndarray
    n: np.ndarray | None = None
    a: np.ndarray | None = None
    tag: np.ndarray | None = None
    kind: np.ndarray | None = None
    freq_std_hz: np.ndarray | None = None
    damping_pct: np.ndarray | None = None
    branch: np.ndarray | None = None
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    condition: dict = field(default_factory=dict)
    source: str = ""

    def __post_init__(self):
        f = np.atleast_1d(np.asarray(self.freq_hz, dtype=np.float64))
        m = f.shape[0]
        self.freq_hz = f

        def col(x, default, dtype):
            if x is None:
                return np.full(m, default, dtype=dtype)
            x = np.atleast_1d(np.asarray(x, dtype=dtype))
            if x.shape != (m,):
                raise ValueError(f"column has shape {x.shape}, expected ({m},)")
            return x

        self.n = col(self.n, -1, np.int64)
        self.a = col(self.a, 0, np.int64)
        self.tag = col(self.tag, "", object)
        self.kind = col(self.kind, "structural", object)
        self.freq_std_hz = col(self.freq_std_hz, np.nan, np.float64)
        self.damping_pct = col(self.damping_pct, np.nan, np.float64)
        self.branch = col(self.branch, "", object)
        self.extra = {k: col(v, "", object) for k, v in self.extra.items()}

    def __len__(self) -> int:
        return self.freq_hz.shape[0]

    @property
    def state(self) -> str:
        """``free`` (default when there is no sidecar), ``loaded`` or ``rolling``."""
        return self.condition.get("state", "free")

    def extra_floats(self, name: str) -> np.ndarray:
        """An optional numeric extra column (e.g. ``damping_std_pct`` of ``ringfit ssi``) as ``(m,)`` floats:
        NaN where it is absent, empty, unparsable, negative or not finite."""
        out = np.full(len(self), np.nan)
        for i, text in enumerate(self.extra.get(name, ())):
            try:
                x = float(text)
            except (TypeError, ValueError):
                continue
            if math.isfinite(x) and x >= 0:
                out[i] = x
        return out

    def select(self, mask) -> "ModeTable":
        """Rows where ``mask`` (bool array or index array) holds."""
        idx = np.asarray(mask)
        return replace(
            self,
            **{c: getattr(self, c)[idx] for c in COLUMNS},
            extra={k: v[idx] for k, v in self.extra.items()},
        )

    def structural_with_n(self) -> np.ndarray:
        """Bool mask of structural rows with an assigned n (what the ring fit uses by default)."""
        return (self.kind == "structural") & (self.n >= 0)

    def to_rows(self) -> list[dict]:
        """One dict per row, docs/formats.md column names, None for empty cells."""
        rows = []
        for i in range(len(self)):
            row = {
                "n": int(self.n[i]) if self.n[i] >= 0 else None,
                "a": int(self.a[i]),
                "tag": self.tag[i],
                "kind": self.kind[i],
                "freq_hz": float(self.freq_hz[i]),
                "freq_std_hz": _none_if_nan(self.freq_std_hz[i]),
                "damping_pct": _none_if_nan(self.damping_pct[i]),
                "branch": self.branch[i],
            }
            row.update({k: v[i] for k, v in self.extra.items()})
            rows.append(row)
        return rows


def _none_if_nan(x):
    return None if not math.isfinite(x) else float(x)


def sidecar_path(path: str | os.PathLike) -> Path:
    """``x.modes.csv`` -> ``x.modes.json`` (also ``x.csv`` -> ``x.json``)."""
    return Path(path).with_suffix(".json")


def read_mode_table(path: str | os.PathLike, *, sidecar: bool = True) -> ModeTable:
    """Read and validate a mode table and its sidecar, if present (docs/formats.md §2).

    **Raises** :class:`~ringfit.errors.InputError` naming file, row and
    column for: unreadable file, missing ``freq_hz`` column, non-numeric,
    NaN, non-positive or negative values, unknown ``kind``/``tag``/``branch``,
    a bad sidecar.

    Examples
    --------
    >>> from ringfit.data import path
    >>> from ringfit.io.modes import read_mode_table
    >>> table = read_mode_table(path("free-ssi.modes.csv"))
    >>> table.n.tolist()  # n = -1: the acoustic cavity mode
    [1, 2, 3, 4, 5, 6, 7, 8, 9, -1]
    >>> table.freq_hz[:3].tolist(), table.condition["state"]
    ([107.0, 116.3, 140.0], 'free')
    """
    path = Path(path)
    text = read_text_file(path)
    table = parse_mode_table(text, source=str(path))
    if sidecar:
        side = sidecar_path(path)
        if side.exists():
            table.condition = read_condition(side)
    return table


def parse_mode_table(text: str, *, source: str = "<text>") -> ModeTable:
    """Parse the CSV text of a mode table (see :func:`read_mode_table`)."""
    header, cols, _ = csv_columns(text, ("freq_hz",), source=source, empty="with at least freq_hz")
    m = len(cols["freq_hz"])
    if m == 0:
        raise InputError("no data rows", source=source)

    def where(i, c):
        return f"{source}: row {i + 2}, column '{c}'"

    def floats(c, *, required, positive=False, nonneg=False, hi=MAX_FREQ_HZ, unit="Hz"):
        out = np.full(m, np.nan)
        for i, s in enumerate(cols.get(c, [""] * m)):
            if s == "":
                if required:
                    raise InputError(f"{where(i, c)}: empty; expected a number")
                continue
            try:
                x = float(s)
            except ValueError:
                raise InputError(f"{where(i, c)}: {short_repr(s)} is not a number") from None
            if not math.isfinite(x):
                raise InputError(f"{where(i, c)}: {short_repr(s)}; expected a finite number")
            if positive and x <= 0:
                raise InputError(f"{where(i, c)}: {s}; expected a positive value")
            if nonneg and x < 0:
                raise InputError(f"{where(i, c)}: {s}; expected a value >= 0")
            if x > hi:
                raise InputError(f"{where(i, c)}: {x:g}; outside the plausible range "
                                 f"[0, {hi:g}] {unit} (docs/formats.md §2)")
            out[i] = x
        return out

    def ints(c, default):
        out = np.full(m, default, dtype=np.int64)
        for i, s in enumerate(cols.get(c, [""] * m)):
            if s == "":
                continue
            try:
                x = float(s)
            except (ValueError, OverflowError):
                raise InputError(f"{where(i, c)}: {short_repr(s)} is not an integer") from None
            if not math.isfinite(x) or x != int(x) or not 0 <= x <= MAX_INDEX:
                raise InputError(f"{where(i, c)}: {short_repr(s)}; expected an integer 0..{MAX_INDEX} or empty")
            out[i] = int(x)
        return out

    def choices(c, allowed, default):
        out = np.empty(m, dtype=object)
        for i, s in enumerate(cols.get(c, [""] * m)):
            s = s if s != "" else default
            if s not in allowed:
                raise InputError(f"{where(i, c)}: {short_repr(s)}; expected one of {list(allowed)}")
            out[i] = s
        return out

    table = ModeTable(
        freq_hz=floats("freq_hz", required=True, positive=True),
        n=ints("n", -1),
        a=ints("a", 0),
        tag=choices("tag", TAGS, ""),
        kind=choices("kind", KINDS, "structural"),
        freq_std_hz=floats("freq_std_hz", required=False, nonneg=True),
        damping_pct=floats("damping_pct", required=False, nonneg=True, hi=MAX_DAMPING_PCT, unit="%"),
        branch=choices("branch", BRANCHES, ""),
        extra={h: np.array(cols[h], dtype=object) for h in header if h not in COLUMNS},
        source=source,
    )
    return table


def read_condition(path: str | os.PathLike) -> dict:
    """Read and validate a ``*.modes.json`` sidecar (docs/formats.md §2)."""
    path = Path(path)
    return validate_condition(read_json_object(path), source=str(path))


def validate_condition(cond: dict, *, source: str = "<condition>") -> dict:
    """Check the sidecar fields that ringfit uses; unknown fields pass through."""
    if not isinstance(cond, dict):
        raise InputError("expected a JSON object", source=source)
    if "state" in cond and cond["state"] not in STATES:
        raise InputError(f"field 'state' = {short_repr(cond['state'])}; expected one of {list(STATES)}", source=source)
    if "frame" in cond and cond["frame"] not in FRAMES:
        raise InputError(f"field 'frame' = {short_repr(cond['frame'])}; expected one of {list(FRAMES)}", source=source)
    for key in ("load_n", "speed_kmh", "rotation_hz", "pressure_bar"):
        if key not in cond or cond[key] is None:
            continue
        check_condition_field(cond, key, source=source)
    wheel_of(cond, source=source)
    return dict(cond)


#: Drum diameters [m] a rolling model takes (test rigs' drums are 0.5–3 m; a larger drum is a flat road for the
#: contact patch, a smaller one leaves the contact solve's window). ``--drum`` of the CLI uses the same range.
DRUM_DIAMETER_RANGE_M = (0.5, 100.0)


def check_test_condition(cond: dict, *, source) -> None:
    """A test table's sidecar says a condition that can be modelled, or :class:`InputError` naming the key.

    Refused (docs/formats.md §2, "test tables"): no ``state`` while the sidecar gives a load, speed or
    rotation (the default ``free`` would silently drop the ground contact); ``state: free`` with a load
    (free means no ground contact; a spinning free tyre has a speed and no load); ``loaded`` or
    ``rolling`` with ``load_n: 0``; a ``drum_diameter_m`` outside :data:`DRUM_DIAMETER_RANGE_M`.
    ``source``: the sidecar, named in the message.
    """
    def positive(key):
        v = cond.get(key)
        return v is not None and float(v) > 0

    drum = cond.get("drum_diameter_m")
    if drum is not None:
        lo, hi = DRUM_DIAMETER_RANGE_M
        ok = isinstance(drum, (int, float)) and not isinstance(drum, bool) and lo <= float(drum) <= hi
        if not ok:
            raise InputError(f"'drum_diameter_m' = {short_repr(drum)}; expected a drum diameter in [{lo:g}, {hi:g}] m "
                             "(no drum_diameter_m for a flat road)", source=source)
    running = [k for k in ("load_n", "speed_kmh", "rotation_hz") if positive(k)]
    state = cond.get("state")
    if state is None:
        if running:
            raise InputError(f"no 'state' while {running[0]} = {cond[running[0]]!r}; expected 'state': 'rolling' "
                             "(on the ground, moving), 'loaded' (on the ground, standing) or 'free' (no ground "
                             "contact)", source=source)
        return
    if state == "free" and positive("load_n"):
        moving = [k for k in ("speed_kmh", "rotation_hz") if positive(k)]
        what = "rolling" if moving else "loaded"
        raise InputError(f"'state': 'free' with load_n = {cond['load_n']!r} (free means no ground contact); "
                         f"expected 'state': '{what}', or no load_n for a free tyre", source=source)
    if state in ("loaded", "rolling") and "load_n" in cond and cond["load_n"] is not None \
            and not positive("load_n"):
        raise InputError(f"'load_n' = {cond['load_n']!r} for a {state} table; expected the vertical load in N "
                         "(> 0)", source=source)


#: Defaults of the wheel body when a sidecar says ``fixture: suspension`` but leaves a value out
#: (docs/formats.md §2): a passenger-car wheel with hub on a test-bench suspension. Defined here, at the
#: format's edge (io/ is NumPy only); :mod:`ringfit.physics.wheel` takes them from here.
DEFAULT_WHEEL_MASS_KG = 20.0
DEFAULT_WHEEL_INERTIA_KG_M2 = 0.6
DEFAULT_STIFFNESS_N_M = (2.0e5, 1.0e6)  # vertical, fore-aft
DEFAULT_TORSION_N_M_RAD = 1.0e5


def wheel_of(cond: dict, *, source: str = "<condition>") -> dict | None:
    """The wheel body a sidecar states (docs/formats.md §2 ``fixture``; docs/physics.md §6 ``wheel_suspension``).

    **Returns:** ``None`` for a bolted rim (``fixture`` absent or ``bolted``: the rim-fixed model);
    for ``fixture: suspension`` a dict in SI: ``mass`` [kg], ``inertia`` [kg m²], ``k_vertical``,
    ``k_fore_aft`` [N/m], ``k_torsion`` [N m/rad], ``c_vertical``, ``c_fore_aft`` [N s/m],
    ``c_torsion`` [N m s/rad], and ``defaults``: the keys the sidecar left out (their values are
    those of :mod:`ringfit.physics.wheel`'s defaults; the diagnosis says so). InputError naming
    the field for a bad value, or for a wheel key without ``fixture: suspension``.
    """
    fixture = cond.get("fixture", "bolted")
    if fixture not in FIXTURES:
        raise InputError(f"field 'fixture' = {short_repr(fixture)}; expected one of {list(FIXTURES)}", source=source)
    keys = [k for k in (*WHEEL_SCALARS, *WHEEL_PAIRS) if k in cond]
    if fixture != "suspension":
        if keys:
            raise InputError(f"field {keys[0]!r} needs 'fixture': 'suspension' (the rim is bolted here); "
                             "drop it or say how the wheel was held", source=source)
        return None
    out = dict(mass=DEFAULT_WHEEL_MASS_KG, inertia=DEFAULT_WHEEL_INERTIA_KG_M2, k_vertical=DEFAULT_STIFFNESS_N_M[0],
               k_fore_aft=DEFAULT_STIFFNESS_N_M[1], k_torsion=DEFAULT_TORSION_N_M_RAD,
               c_vertical=0.0, c_fore_aft=0.0, c_torsion=0.0)
    defaults = []
    for key, (lo, hi) in WHEEL_SCALARS.items():
        target = {"wheel_mass_kg": "mass", "wheel_inertia_kg_m2": "inertia", "suspension_torsion_n_m_rad": "k_torsion",
                  "suspension_torsion_damping_n_m_s_rad": "c_torsion"}[key]
        if key in cond:
            damp = "damping" in key
            out[target] = number_in_range(cond[key], key, lo, hi, lo_open=not damp, source=source)
        elif "damping" not in key:
            defaults.append(key)
    for key, (lo, hi) in WHEEL_PAIRS.items():
        damp = "damping" in key
        names = ("c_vertical", "c_fore_aft") if damp else ("k_vertical", "k_fore_aft")
        if key not in cond:
            if not damp:
                defaults.append(key)
            continue
        v = cond[key]
        vals = v if isinstance(v, list) else [v]
        if len(vals) not in (1, 2):
            raise InputError(f"field {key!r} = {short_repr(v)}: expected a number or [vertical, fore-aft]",
                             source=source)
        nums = [number_in_range(x, key, lo, hi, lo_open=not damp, source=source) for x in vals]
        out[names[0]], out[names[1]] = nums[0], nums[-1]
    out["defaults"] = defaults
    return out


def format_mode_table(table: ModeTable) -> str:
    """CSV text of a mode table (floats via ``repr``, so reading it back is exact)."""
    header = list(COLUMNS) + list(table.extra)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for row in table.to_rows():
        w.writerow(["" if row[h] is None else (repr(row[h]) if isinstance(row[h], float) else row[h]) for h in header])
    return buf.getvalue()


def write_mode_table(
    table: ModeTable, path: str | os.PathLike, *, overwrite: bool = False, sidecar: bool = True
) -> Path:
    """Write ``table`` as CSV (and its ``condition`` as the JSON sidecar when non-empty).

    Refuses to overwrite existing files unless ``overwrite``; writes atomically.
    """
    path = check_output_path(path, overwrite=overwrite)
    side = sidecar_path(path)
    write_side = sidecar and bool(table.condition)
    if write_side:
        check_output_path(side, overwrite=overwrite)
        validate_condition(table.condition, source=str(side))
    text = format_mode_table(table)
    atomic_write(path, lambda tmp: tmp.write_text(text))
    if write_side:
        payload = json.dumps(table.condition, indent=1, default=_json_default)
        atomic_write(side, lambda tmp: tmp.write_text(payload + "\n"))
    return path


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"cannot write {type(x).__name__} to JSON")
