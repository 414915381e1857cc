"""Tyre description files — ``*.toml`` (docs/formats.md §1).

``[tyre]`` holds geometry and pressure (required); ``[ring]`` holds ring
parameters, fitted or starting guesses (optional, any subset); ``[meta]``
(optional) is free-form and kept in :attr:`Tyre.extra`, so a file
round-trips. Any other key or table is refused with the nearest valid name
(a typo such as ``ei_nm2`` would otherwise be silently ignored), and every
value must lie in the plausible range of :data:`RANGES` (docs/formats.md §1).
"""

from __future__ import annotations

import difflib
import math
import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.checks import MAX_PRESSURE_BAR
from ringfit.io.files import atomic_write_text, check_output_path
from ringfit.params import BAR, DEFAULT_K_TREAD, RING_PARAMETERS, RingParams, TyreGeometry, TyreLaws

_TYRE_KEYS = {"radius_m": "radius", "width_m": "width", "tread_thickness_m": "tread_thickness",
              "tread_rib_width_m": "tread_rib_width"}
#: Keys of the [tyre] table.
TYRE_KEYS = ("name", "radius_m", "width_m", "pressure_bar", "tread_thickness_m", "tread_rib_width_m",
             "tread_depth_mm", "tread_depth_new_mm", "tread_density_kg_m3", "tread_land_ratio")
#: The state laws' keys (docs/formats.md §1, docs/physics.md §13): in [tyre], in [ring] and in [ring.pressure].
STATE_TYRE_KEYS = ("tread_depth_mm", "tread_depth_new_mm", "tread_density_kg_m3", "tread_land_ratio")
STATE_RING_KEYS = ("kx_n_per_m2", "friction", "friction_sd")
PRESSURE_KEYS = ("kw_share", "kv_share", "k_tread_share")
#: Top-level tables of a tyre file; ``meta`` is free-form (notes, provenance).
TABLES = ("tyre", "ring", "meta")

#: Plausible range (lo, hi], SI, of every number in a tyre file. Far wider than a
#: passenger-car tyre (the fit's own bounds are in ringfit/fit/priors.py): a value
#: outside is a unit slip or a typo, and would only send a solver astray.
RANGES: dict[str, tuple[float, float]] = {
    "radius_m": (0.05, 5.0),
    "width_m": (0.005, 2.0),
    "pressure_bar": (0.0, MAX_PRESSURE_BAR),
    "tread_thickness_m": (0.0, 0.2),
    "tread_rib_width_m": (0.0, 2.0),
    "rho_a_kg_per_m": (1e-3, 1e3),
    "ei_n_m2": (1e-6, 1e6),
    "kw_n_per_m2": (1.0, 1e11),
    "kv_n_per_m2": (1.0, 1e11),
    "damping_ratio": (0.0, 1.0),
    "k_tread_n_per_m2": (1.0, 1e12),
    "ea_n": (1.0, 1e13),
    "chi": (-1.0, 2.0),
    "tread_depth_mm": (0.0, 50.0),
    "tread_depth_new_mm": (0.0, 50.0),
    "tread_density_kg_m3": (100.0, 5000.0),
    "tread_land_ratio": (0.0, 1.0),
    "kx_n_per_m2": (1.0, 1e12),
    "friction": (0.0, 10.0),
    "friction_sd": (0.0, 10.0),
    "kw_share": (0.0, 1.0),
    "kv_share": (0.0, 1.0),
    "k_tread_share": (0.0, 1.0),
}
#: Keys whose range includes its lower end: a pressure share of ``[ring.pressure]`` may be 0 (docs/formats.md §1).
CLOSED_RANGE = ("kw_share", "kv_share", "k_tread_share")

#: Defaults used when [ring] lacks a value that a model needs (Table 9 of the seed).
RING_DEFAULTS = dict(rho_a=2.715, ei=0.9426, kw=1.294e6, kv=1.161e6, damping_ratio=0.025, k_tread=DEFAULT_K_TREAD)


@dataclass
class Tyre:
    """A parsed tyre file.

    - ``geometry``: :class:`~ringfit.params.TyreGeometry` (SI).
    - ``ring_values``: the ``[ring]`` values present in the file, by short name
      (``rho_a``, ``ei``, ``kw``, ``kv``, ``damping_ratio``, ``k_tread``, ``ea``, ``chi``), SI.
    - ``extra``: every other table/key of the file, kept for writing back.
    - ``covariance``: the ``[ring.covariance]`` (:class:`RingCovariance`) when the file has one.
    - ``state_values``: the state laws' keys present in the file (docs/physics.md §13), by TOML key
      (:data:`STATE_TYRE_KEYS`, :data:`STATE_RING_KEYS`, :data:`PRESSURE_KEYS`), as written (mm, bar …).
    """

    geometry: TyreGeometry
    ring_values: dict[str, float] = field(default_factory=dict)
    extra: dict = field(default_factory=dict)
    source: str = ""
    covariance: "RingCovariance | None" = None
    state_values: dict[str, float] = field(default_factory=dict)

    @property
    def laws(self) -> TyreLaws:
        """The state laws (:class:`~ringfit.params.TyreLaws`, SI) of the file's keys; defaults for the rest."""
        v = self.state_values
        kw = {}
        if "tread_depth_mm" in v:
            kw.update(tread_depth_ref=v["tread_depth_mm"] * 1e-3, has_tread_depth=True)
        if "tread_depth_new_mm" in v:
            kw.update(tread_depth_new=v["tread_depth_new_mm"] * 1e-3)
        if "kx_n_per_m2" in v:
            kw.update(k_x=v["kx_n_per_m2"], has_brush=True)
        for key, attr in (("tread_density_kg_m3", "tread_density"), ("tread_land_ratio", "land_ratio"),
                          ("friction", "friction"), ("kw_share", "kw_share"), ("kv_share", "kv_share"),
                          ("k_tread_share", "k_tread_share")):
            if key in v:
                kw[attr] = v[key]
        return TyreLaws(**kw)

    def with_state_values(self, **values) -> "Tyre":
        """A copy with state-law keys (TOML names, e.g. ``kx_n_per_m2=15e6``, ``kw_share=0.5``) set."""
        unknown = set(values) - set(STATE_TYRE_KEYS + STATE_RING_KEYS + PRESSURE_KEYS)
        if unknown:
            raise KeyError(f"unknown state key(s) {sorted(unknown)}")
        return Tyre(self.geometry, dict(self.ring_values), dict(self.extra), self.source, self.covariance,
                    {**self.state_values, **{k: float(x) for k, x in values.items()}})

    @property
    def ring(self) -> RingParams:
        """Ring parameters: the file's values, Table 9 defaults for the rest."""
        values = {**RING_DEFAULTS, **self.ring_values}
        return RingParams(**values)

    def with_ring(self, ring: RingParams, names=None, covariance: "RingCovariance | None" = None) -> "Tyre":
        """A copy whose ``[ring]`` holds ``ring``'s values for ``names`` (default: all finite ones).

        The copy carries ``covariance`` (default none: the file's old ``[ring.covariance]`` described
        other values)."""
        d = ring.as_dict()
        names = names or [k for k, v in d.items() if math.isfinite(v)]
        values = dict(self.ring_values)
        values.update({k: d[k] for k in names})
        # a covariance belongs to the values it was identified with: new values drop it unless given
        return Tyre(self.geometry, values, dict(self.extra), self.source, covariance, dict(self.state_values))


def require_ring(tyre: Tyre, needs: str) -> Tyre:
    """``tyre`` when its file has a ``[ring]``; else InputError naming the file: a command that simulates or
    fits from the ring never falls back silently to the source study's Table 9 values. ``needs``: what the
    command needs the ring for ("the load estimate needs the tyre's identified ring")."""
    if not tyre.ring_values:
        raise InputError(f"has no [ring]: {needs} (ringfit identify, or ringfit fit and fit-rolling); it does not "
                         "fall back to the Table 9 values", source=tyre.source or None)
    return tyre


def _number(table: dict, key: str, where: str) -> float:
    """``table[key]`` as a float inside :data:`RANGES` [key]; InputError naming ``[where] key`` otherwise."""
    value = table[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"[{where}] {key} = {_show(value)}: expected a number")
    try:
        x = float(value)
    except OverflowError:
        x = math.inf
    if not math.isfinite(x):
        raise InputError(f"[{where}] {key} = {_show(value)}: expected a finite number")
    lo, hi = RANGES[key]
    closed = key in CLOSED_RANGE
    if not (lo <= x if closed else lo < x) or x > hi:
        raise InputError(f"[{where}] {key} = {x:g}: outside the plausible range {'[' if closed else '('}{lo:g}, "
                         f"{hi:g}] (docs/formats.md §1; a unit slip?)")
    return x


def _show(value) -> str:
    """A short repr for messages (a 400-digit number or a long string is cut)."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _unknown(key: str, known, where: str) -> InputError:
    close = difflib.get_close_matches(key, list(known), n=1, cutoff=0.6)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return InputError(f"unknown {where} {_show(key)}: {hint}expected one of {', '.join(known)}")


def read_tyre(path: str | os.PathLike) -> Tyre:
    """Read and validate a tyre TOML file (docs/formats.md §1).

    Raises :class:`~ringfit.errors.InputError` with one line naming the file
    and field for anything missing, non-numeric, non-positive, outside its
    plausible range (:data:`RANGES`; a ``pressure_bar`` that looks like Pa),
    or an unknown key or table (with the nearest valid name).

    Examples
    --------
    The source study's tyre, bundled with ringfit:

    >>> from ringfit.data import path
    >>> from ringfit.io.tyre import read_tyre
    >>> tyre = read_tyre(path("table9.tyre.toml"))
    >>> tyre.geometry.name, round(float(tyre.geometry.radius), 3), round(float(tyre.ring.kw))
    ('205/55R16 94H XL', 0.296, 1294000)
    """
    path = Path(path)
    try:
        with open(path, "rb") as fh:
            doc = tomllib.load(fh)
    except FileNotFoundError:
        raise InputError("file not found", source=path) from None
    except IsADirectoryError:
        raise InputError("is a directory; expected a tyre TOML file", source=path) from None
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not a readable TOML file ({exc})", source=path) from None
    except (RecursionError, MemoryError):
        raise InputError("not a readable TOML file (nested too deeply)", source=path) from None
    try:
        return _parse(doc, str(path))
    except InputError as exc:
        raise InputError(str(exc), source=path) from None


def _parse(doc: dict, source: str) -> Tyre:
    doc = dict(doc)
    for key, value in doc.items():
        if key not in TABLES:
            raise _unknown(key, TABLES, "table" if isinstance(value, dict) else "top-level key")
        if not isinstance(value, dict):
            raise InputError(f"{key} = {_show(value)}: expected a [{key}] table")
    tyre = doc.pop("tyre", None)
    if tyre is None:
        raise InputError("missing [tyre] table (radius_m, width_m, pressure_bar)")
    tyre = dict(tyre)
    for key in tyre:
        if key not in TYRE_KEYS:
            raise _unknown(key, TYRE_KEYS, "key in [tyre]")
    for key in ("radius_m", "width_m", "pressure_bar"):
        if key not in tyre:
            raise InputError(f"[tyre] lacks {key}")
    if isinstance(tyre.get("pressure_bar"), (int, float)) and not isinstance(tyre["pressure_bar"], bool):
        try:
            if float(tyre["pressure_bar"]) > MAX_PRESSURE_BAR:
                raise InputError(
                    f"[tyre] pressure_bar = {float(tyre['pressure_bar']):g} looks like Pa or kPa, not bar "
                    f"(expected 0 < pressure_bar <= {MAX_PRESSURE_BAR:g}; 2.2 bar = 2.2e5 Pa)")
        except OverflowError:
            pass
    if isinstance(tyre.get("radius_m"), (int, float)) and not isinstance(tyre["radius_m"], bool):
        try:
            if 5.0 < float(tyre["radius_m"]) < 5000.0:
                raise InputError(f"[tyre] radius_m = {float(tyre['radius_m']):g} looks like mm, expected metres")
        except OverflowError:
            pass
    kw = {attr: _number(tyre, key, "tyre") for key, attr in _TYRE_KEYS.items() if key in tyre}
    state_values = {key: _number(tyre, key, "tyre") for key in STATE_TYRE_KEYS if key in tyre}
    if "tread_depth_mm" in state_values:
        tau_mm = 1e3 * kw.get("tread_thickness", TyreGeometry.tread_thickness)
        if state_values["tread_depth_mm"] >= tau_mm:
            raise InputError(f"[tyre] tread_depth_mm = {state_values['tread_depth_mm']:g} is not below the tread "
                             f"thickness {tau_mm:g} mm (tread_thickness_m): the depth is the grooves' part of the "
                             "tread (docs/physics.md §13.3)")
    if "tread_depth_new_mm" in state_values:
        if "tread_depth_mm" not in state_values:
            raise InputError("[tyre] tread_depth_new_mm needs tread_depth_mm (the depth d_ref at which [ring] holds): "
                             "without a tread law the depth is not estimated, and a bound on it says nothing")
        if state_values["tread_depth_new_mm"] < state_values["tread_depth_mm"]:
            raise InputError(f"[tyre] tread_depth_new_mm = {state_values['tread_depth_new_mm']:g} is below "
                             f"tread_depth_mm = {state_values['tread_depth_mm']:g}: the new tread is the deepest the "
                             "tyre has been, so it is at least the depth at which [ring] holds "
                             "(docs/physics.md §13.3)")
    pressure_bar = _number(tyre, "pressure_bar", "tyre")
    name = tyre.get("name", "")
    if not isinstance(name, str):
        raise InputError(f"[tyre] name = {_show(name)}: expected a string")
    geometry = TyreGeometry(pressure=pressure_bar * BAR, name=name, **kw)

    ring_table = dict(doc.pop("ring", {}) or {})
    by_key = {toml_key: short for short, (_, toml_key) in RING_PARAMETERS.items()}
    ring_values = {}
    covariance = None
    for key in ring_table:
        if key in ("covariance", "pressure"):
            continue
        if key in STATE_RING_KEYS:
            state_values[key] = _number(ring_table, key, "ring")
            continue
        if key not in by_key:
            raise _unknown(key, list(by_key) + list(STATE_RING_KEYS) + ["covariance", "pressure"], "key in [ring]")
        ring_values[by_key[key]] = _number(ring_table, key, "ring")
    if "pressure" in ring_table:
        state_values.update(_pressure_laws(ring_table["pressure"]))
    if "covariance" in ring_table:
        covariance = _covariance(ring_table["covariance"], ring_values, state_values)
    extra = {"tyre": {}, "ring": {}}
    extra.update(doc)  # [meta]
    return Tyre(geometry, ring_values, extra, source, covariance, state_values)


def _pressure_laws(table) -> dict:
    """``[ring.pressure]``: the pressure shares s of k_w, k_v, k_trd (docs/physics.md §13.1), each in [0, 1]."""
    if not isinstance(table, dict):
        raise InputError(f"ring.pressure = {_show(table)}: expected a [ring.pressure] table "
                         f"({', '.join(PRESSURE_KEYS)})")
    for key in table:
        if key not in PRESSURE_KEYS:
            raise _unknown(key, PRESSURE_KEYS, "key in [ring.pressure]")
    return {key: _number(table, key, "ring.pressure") for key in table}


#: Positive ring parameters a ``[ring.covariance]`` may name (it is a covariance of their logarithms).
COVARIANCE_PARAMETERS = ("rho_a", "ei", "kw", "kv", "damping_ratio", "k_tread", "ea")
#: The state laws ``ringfit identify`` identifies across states (docs/physics.md §11, §13) that a
#: ``[ring.covariance]`` may name besides: name -> the key that must hold its value. ``k_x`` (positive) enters as
#: ln k_x like the ring's; a pressure share s (in [0, 1], possibly 0) enters as s itself (:data:`LINEAR_COVARIANCE`);
#: ``friction`` (μ, held by identify with its doubt carried, §11 *friction*) as ln μ.
STATE_COVARIANCE_PARAMETERS = {"k_x": "kx_n_per_m2", "kw_share": "kw_share", "kv_share": "kv_share",
                               "k_tread_share": "k_tread_share", "friction": "friction"}
#: Names whose ``[ring.covariance]`` row is of the value itself, not of its logarithm (the pressure shares).
LINEAR_COVARIANCE = ("kw_share", "kv_share", "k_tread_share")
#: Largest σ of a pressure share in a ``[ring.covariance]``: more than the share's whole range [0, 1] says nothing.
SHARE_SD_MAX = 1.0


def _covariance(table, ring_values: dict, state_values: dict | None = None) -> "RingCovariance":
    """``[ring.covariance]``: ``names`` (short names) and ``ln`` (k × k covariance of ln θ; of the share itself for
    a pressure share, :data:`LINEAR_COVARIANCE`), checked."""
    where = "[ring.covariance]"
    if not isinstance(table, dict):
        raise InputError(f"ring.covariance = {_show(table)}: expected a [ring.covariance] table (names, ln)")
    for key in table:
        if key not in ("names", "ln", "source"):
            raise _unknown(key, ("names", "ln", "source"), f"key in {where}")
    names, ln = table.get("names"), table.get("ln")
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise InputError(f"{where} names: expected a list of ring parameter names, e.g. [\"ei\", \"k_tread\"]")
    state_values = state_values or {}
    known = COVARIANCE_PARAMETERS + tuple(STATE_COVARIANCE_PARAMETERS)
    for n in names:
        if n not in known:
            raise _unknown(n, known, f"parameter in {where} names")
        if n in STATE_COVARIANCE_PARAMETERS:
            key = STATE_COVARIANCE_PARAMETERS[n]
            if key not in state_values:
                table_of = "[ring.pressure]" if n in LINEAR_COVARIANCE else "[ring]"
                raise InputError(f"{where} names {n!r}, but {table_of} has no {key} for it")
        elif n not in ring_values:
            raise InputError(f"{where} names {n!r}, but [ring] has no value for it")
    if len(set(names)) != len(names):
        raise InputError(f"{where} names lists a parameter twice")
    k = len(names)
    if not isinstance(ln, list) or len(ln) != k or not all(isinstance(r, list) and len(r) == k for r in ln):
        raise InputError(f"{where} ln: expected a {k} × {k} array (one row per name)")
    try:
        cov = np.array([[float(x) for x in row] for row in ln], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"{where} ln: expected numbers") from None
    if any(isinstance(x, bool) for row in ln for x in row) or not np.all(np.isfinite(cov)):
        raise InputError(f"{where} ln: expected finite numbers")
    if not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-300):
        raise InputError(f"{where} ln: not symmetric")
    if np.linalg.eigvalsh(0.5 * (cov + cov.T)).min() < -1e-12 * max(1.0, float(np.abs(cov).max())):
        raise InputError(f"{where} ln: not positive semi-definite")
    sd = np.sqrt(np.diag(cov))
    linear = np.array([n in LINEAR_COVARIANCE for n in names])
    if np.any(sd[~linear] > 5.0):
        raise InputError(f"{where} ln: a standard deviation of ln θ above 5 (a factor e^5): not an uncertainty "
                         "a model can use")
    if np.any(sd[linear] > SHARE_SD_MAX):
        raise InputError(f"{where} ln: a pressure share's standard deviation above {SHARE_SD_MAX:g} (its whole "
                         "range [0, 1]): not an uncertainty a model can use")
    source = table.get("source", "")
    if not isinstance(source, str):
        raise InputError(f"{where} source = {_show(source)}: expected a string")
    return RingCovariance(tuple(names), cov if np.array_equal(cov, cov.T) else 0.5 * (cov + cov.T), source)


@dataclass(frozen=True)
class RingCovariance:
    """The tyre file's ``[ring.covariance]`` (docs/formats.md §1.1): covariance ``ln`` ``(k, k)`` of ln θ for
    ``names``; ``source`` says where it came from (e.g. the identify report).

    Besides ring parameters it may hold the state laws identified across states
    (:data:`STATE_COVARIANCE_PARAMETERS`: ln k_x, and the pressure shares as themselves, :data:`LINEAR_COVARIANCE`);
    :meth:`draws` and every reader that wants the ring's part take the ring parameters only."""

    names: tuple[str, ...]
    ln: np.ndarray
    source: str = ""

    @property
    def ring_names(self) -> tuple[str, ...]:
        """The names that are ring parameters (:data:`COVARIANCE_PARAMETERS`), in order."""
        return tuple(n for n in self.names if n in COVARIANCE_PARAMETERS)

    def sd_ln(self, name: str) -> float | None:
        """σ of ln θ of ``name`` (of the share itself for a pressure share), or None when the covariance does not
        hold it."""
        if name not in self.names:
            return None
        i = self.names.index(name)
        return float(math.sqrt(max(self.ln[i, i], 0.0)))

    def draws(self, ring: RingParams, n: int, seed: int = 0) -> list[RingParams]:
        """``n`` rings drawn from the log-normal ``ln θ ~ N(ln ring, ln)`` (the other parameters as in ``ring``)."""
        rng = np.random.default_rng(seed)
        names = self.ring_names  # the ring's marginal (the state laws' rows left out)
        idx = [self.names.index(k) for k in names]
        centre = np.log([float(getattr(ring, k)) for k in names])
        u = rng.multivariate_normal(centre, self.ln[np.ix_(idx, idx)], size=int(n), method="eigh")
        return [ring.replace(**{k: float(math.exp(x)) for k, x in zip(names, row)}) for row in u]

    def table(self) -> dict:
        """The ``[ring.covariance]`` table of the tyre TOML (docs/formats.md §1.1)."""
        return {"names": list(self.names), "ln": [[float(x) for x in row] for row in self.ln],
                **({"source": self.source} if self.source else {})}


def write_tyre(tyre: Tyre, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write a tyre TOML file (docs/formats.md §1). Refuses to overwrite unless asked."""
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
    if float(g.tread_rib_width) > 0:
        tyre_table["tread_rib_width_m"] = float(g.tread_rib_width)
    sv = tyre.state_values
    tyre_table.update({k: float(sv[k]) for k in STATE_TYRE_KEYS if k in sv})
    tyre_table.update(tyre.extra.get("tyre", {}))
    ring_table = {RING_PARAMETERS[k][1]: float(v) for k, v in tyre.ring_values.items() if math.isfinite(v)}
    ring_table.update({k: float(sv[k]) for k in STATE_RING_KEYS if k in sv})
    ring_table.update(tyre.extra.get("ring", {}))
    if any(k in sv for k in PRESSURE_KEYS):
        ring_table["pressure"] = {k: float(sv[k]) for k in PRESSURE_KEYS if k in sv}
    if tyre.covariance is not None:
        ring_table["covariance"] = tyre.covariance.table()
    doc = {"tyre": tyre_table, "ring": ring_table}
    doc.update({k: v for k, v in tyre.extra.items() if k not in ("tyre", "ring")})
    text = tomli_w.dumps(doc)
    atomic_write_text(path, text)
    return path
