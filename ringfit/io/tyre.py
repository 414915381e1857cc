"""Tyre description files — ``*.toml`` (DATA.md §1).

``[tyre]`` holds geometry and pressure (required); ``[ring]`` holds ring
parameters, fitted or starting guesses (optional, any subset). Unknown keys
are kept in :attr:`Tyre.extra` and written back, so a file round-trips.
"""

from __future__ import annotations

import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ringfit.errors import InputError
from ringfit.io.files import atomic_write_text, check_output_path
from ringfit.params import BAR, RING_PARAMETERS, RingParams, TyreGeometry

_TYRE_KEYS = {"radius_m": "radius", "width_m": "width", "tread_thickness_m": "tread_thickness"}
#: A [tyre] pressure_bar above this is almost surely a value in Pa or kPa.
MAX_PRESSURE_BAR = 20.0

#: Defaults used when [ring] lacks a value that a model needs (Table 9 of the seed).
RING_DEFAULTS = dict(rho_a=2.715, ei=0.9426, kw=1.294e6, kv=1.161e6, damping_ratio=0.025, k_tread=19.0e6)


@dataclass
class Tyre:
    """A parsed tyre file.

    - ``geometry``: :class:`~ringfit.params.TyreGeometry` (SI).
    - ``ring_values``: the ``[ring]`` values present in the file, by short name
      (``rho_a``, ``ei``, ``kw``, ``kv``, ``damping_ratio``, ``k_tread``, ``ea``, ``chi``), SI.
    - ``extra``: every other table/key of the file, kept for writing back.
    """

    geometry: TyreGeometry
    ring_values: dict[str, float] = field(default_factory=dict)
    extra: dict = field(default_factory=dict)
    source: str = ""

    @property
    def ring(self) -> RingParams:
        """Ring parameters: the file's values, Table 9 defaults for the rest."""
        values = {**RING_DEFAULTS, **self.ring_values}
        return RingParams(**values)

    def with_ring(self, ring: RingParams, names=None) -> "Tyre":
        """A copy whose ``[ring]`` holds ``ring``'s values for ``names`` (default: all finite ones)."""
        d = ring.as_dict()
        names = names or [k for k, v in d.items() if math.isfinite(v)]
        values = dict(self.ring_values)
        values.update({k: d[k] for k in names})
        return Tyre(self.geometry, values, dict(self.extra), self.source)


def _number(table: dict, key: str, where: str, *, positive=True) -> float:
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"[{where}] {key} = {value!r}: expected a number")
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"[{where}] {key} = {value}: expected a finite number")
    if positive and value <= 0:
        raise InputError(f"[{where}] {key} = {value}: expected a positive number")
    return value


def read_tyre(path: str | os.PathLike) -> Tyre:
    """Read and validate a tyre TOML file (DATA.md §1).

    Raises :class:`~ringfit.errors.InputError` with one line naming the file
    and field for anything missing, non-numeric, non-positive or implausible
    (a ``pressure_bar`` that looks like Pa).
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except FileNotFoundError:
        raise InputError("file not found", source=path) from None
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not a readable TOML file ({exc})", source=path) from None
    try:
        return _parse(doc, str(path))
    except InputError as exc:
        raise InputError(str(exc), source=path) from None


def _parse(doc: dict, source: str) -> Tyre:
    doc = dict(doc)
    tyre = doc.pop("tyre", None)
    if not isinstance(tyre, dict):
        raise InputError("missing [tyre] table (radius_m, width_m, pressure_bar)")
    tyre = dict(tyre)
    for key in ("radius_m", "width_m", "pressure_bar"):
        if key not in tyre:
            raise InputError(f"[tyre] lacks {key}")
    kw = {attr: _number(tyre, key, "tyre") for key, attr in _TYRE_KEYS.items() if key in tyre}
    pressure_bar = _number(tyre, "pressure_bar", "tyre")
    if pressure_bar > MAX_PRESSURE_BAR:
        raise InputError(
            f"[tyre] pressure_bar = {pressure_bar:g} looks like Pa or kPa, not bar "
            f"(expected 0 < pressure_bar <= {MAX_PRESSURE_BAR:g}; 2.2 bar = 2.2e5 Pa)"
        )
    if kw["radius"] > 5.0:
        raise InputError(f"[tyre] radius_m = {kw['radius']:g} looks like mm, expected metres")
    name = str(tyre.get("name", ""))
    geometry = TyreGeometry(pressure=pressure_bar * BAR, name=name, **kw)
    known_tyre = set(_TYRE_KEYS) | {"pressure_bar", "name"}
    extra = {"tyre": {k: v for k, v in tyre.items() if k not in known_tyre}}

    ring_table = dict(doc.pop("ring", {}) or {})
    by_key = {toml_key: short for short, (_, toml_key) in RING_PARAMETERS.items()}
    ring_values = {}
    for key in list(ring_table):
        if key in by_key:
            short = by_key[key]
            ring_values[short] = _number(ring_table, key, "ring", positive=short not in ("chi",))
            ring_table.pop(key)
    extra["ring"] = ring_table
    extra.update(doc)
    return Tyre(geometry, ring_values, extra, source)


def write_tyre(tyre: Tyre, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write a tyre TOML file (DATA.md §1). Refuses to overwrite unless asked."""
    import tomli_w

    path = check_output_path(path, overwrite=overwrite)
    g = tyre.geometry
    tyre_table = {}
    if g.name:
        tyre_table["name"] = g.name
    tyre_table.update(
        radius_m=float(g.radius), width_m=float(g.width), pressure_bar=float(g.pressure) / BAR,
        tread_thickness_m=float(g.tread_thickness),
    )
    tyre_table.update(tyre.extra.get("tyre", {}))
    ring_table = {RING_PARAMETERS[k][1]: float(v) for k, v in tyre.ring_values.items() if math.isfinite(v)}
    ring_table.update(tyre.extra.get("ring", {}))
    doc = {"tyre": tyre_table, "ring": ring_table}
    doc.update({k: v for k, v in tyre.extra.items() if k not in ("tyre", "ring")})
    text = tomli_w.dumps(doc)
    atomic_write_text(path, text)
    return path
