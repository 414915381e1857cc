"""Stated conditions checked against each other, the tyre file and what the data say (docs/formats.md §3, §6).

A sidecar states a measurement's condition — speed, rotation, load, pressure — and every command trusts it.
Where two stated values, or a stated value and the data, can be compared, they are compared here, once, for
every command (identify, diagnose and campaign case folders, fit-rolling, estimate, campbell):

- :func:`rotation_speed_conflict`: ``rotation_hz`` (the rim encoder) against ``speed_kmh`` with the tyre's
  rolling radius: ``V / (2π·rotation_hz)`` must lie within :data:`ROLLING_RADIUS_SHARE` of the tyre file's
  outer radius R + τ (R_e = R_out − δ/3, δ the deflection: a few per cent below R_out);
- :func:`patch_drop_omega`: what a profile itself says of Ω — on the road the sensor runs straight through the
  contact patch, so its radial reading drops there by about Ω²·R from the centripetal level outside
  (docs/physics.md §5); :data:`PATCH_DROP_SHARE` brackets drop/(Ω² R_out) over loads, drums and grids;
- :func:`check_profile_rotation`: the two together for a profile — a contradiction the profile's own patch
  resolves is a ``WARNING`` and the value the data support is used; one it does not resolve is refused
  (exit 2: no answer can be right until the sidecar is corrected);
- :func:`check_table_rotation`: a mode table's sidecar (no data that tell Ω): a contradiction is refused;
- :func:`pressure_conflict`: a measurement's ``pressure_bar`` against the tyre file's;
- :func:`stated_against_estimate`: every stated condition an estimate also reads (load, pressure, tread depth,
  speed, torque) against the estimate's interval: a contradiction beyond :data:`STATED_Z` σ is named;
- :func:`duplicate_inputs`: the same file given twice (same resolved path — symlinks followed — or the same
  content hash).

The sampling-rate checks of recordings (the encoder and the cleat trigger against ``fs_hz``,
:mod:`ringfit.targets.faults`) use :data:`RATE_TOL` and :data:`ROLLING_RADIUS_M` from here.
NumPy only (io/ imports no JAX).
"""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from ringfit.errors import InputError
from ringfit.units import KMH, Z95

#: Rolling radii [m] a road tyre can have: an encoder rate that implies another contradicts the sampling rate.
ROLLING_RADIUS_M = (0.15, 0.75)
#: Relative disagreement between the encoder's rotation rate and the stated one that is called a contradiction.
RATE_TOL = 0.02
#: R_e / R_out a rolling tyre can have (R_e = R_out − δ/3; δ up to ~45 % of R_out would be a flat tyre): a
#: ``speed_kmh`` and ``rotation_hz`` whose ratio implies a radius outside this share of R_out contradict.
ROLLING_RADIUS_SHARE = (0.85, 1.0 + RATE_TOL)
#: drop / (Ω² R_out) of a rolling profile's radial reading (:func:`patch_drop_omega`): 0.50 at 1.5 kN, 0.72 at
#: 4 kN on a flat road, 0.96 on a 1.22 m drum, 1.53 at 9 kN on a 0.5 m drum (the patch curves the other way),
#: the same from 64 to 1024 angles (``ringfit roll`` profiles of Table 9's tyre); a stated Ω outside this bracket
#: is not the one the profile was read at. Its width (6.7×, Ω 2.6×) makes a wrong pick impossible: a smaller
#: contradiction fits both and is refused.
PATCH_DROP_SHARE = (0.3, 2.0)
#: The patch floor is looked for within this angle of the patch centre [deg].
PATCH_WINDOW_DEG = 10.0
#: Relative difference of a measurement's pressure from the tyre file's that is called a contradiction.
PRESSURE_TOL = 0.05


def _positive(condition: dict, key: str) -> float | None:
    value = condition.get(key)
    try:
        value = float(value)
    except (TypeError, ValueError):
        return None
    return value if math.isfinite(value) and value > 0 else None


def rotation_speed_conflict(condition: dict, outer_radius_m: float) -> str | None:
    """One sentence when ``rotation_hz`` and ``speed_kmh`` contradict each other for a tyre of outer radius
    ``outer_radius_m`` [m] (see the module docstring), else None (also when either is absent)."""
    rot, speed = _positive(condition, "rotation_hz"), _positive(condition, "speed_kmh")
    if rot is None or speed is None:
        return None
    radius = speed * KMH / (2.0 * math.pi * rot)
    lo, hi = (s * outer_radius_m for s in ROLLING_RADIUS_SHARE)
    if lo <= radius <= hi:
        return None
    r_nom = outer_radius_m * 0.98
    return (f"rotation_hz = {rot:g} and speed_kmh = {speed:g} contradict each other: together they mean a rolling "
            f"radius of {radius:.3g} m, but the tyre file's outer radius is {outer_radius_m:.4g} m (a rolling tyre's "
            f"is {lo:.3g}–{hi:.3g} m); at speed_kmh = {speed:g} the wheel turns about "
            f"{speed * KMH / (2 * math.pi * r_nom):.3g} Hz, and rotation_hz = {rot:g} means about "
            f"{2 * math.pi * rot * r_nom / KMH:.3g} km/h")


def patch_drop_omega(angle_deg: np.ndarray, radial_ms2: np.ndarray) -> float | None:
    """The radial reading's drop into the contact patch [m/s²]: the median outside (|φ| > 90°) less the patch's
    floor (the 10th percentile within ±:data:`PATCH_WINDOW_DEG` of its centre, below the edges' peaks); None
    when either is empty."""
    angle = np.asarray(angle_deg, dtype=np.float64)
    radial = np.asarray(radial_ms2, dtype=np.float64)
    if angle.size < 8:
        return None
    centre = np.abs(angle) <= PATCH_WINDOW_DEG
    outside = np.abs(angle) > 90.0
    if not centre.any() or not outside.any():
        return None
    return float(np.median(radial[outside]) - np.percentile(radial[centre], 10))


def _data_agree(drop: float, omega: float, outer_radius_m: float) -> bool:
    lo, hi = PATCH_DROP_SHARE
    return lo <= drop / (omega**2 * outer_radius_m) <= hi


def check_profile_rotation(profile, outer_radius_m: float) -> tuple[object, str | None]:
    """A profile whose ``rotation_hz`` and ``speed_kmh`` contradict (:func:`rotation_speed_conflict`), judged by
    its own contact patch (:func:`patch_drop_omega`).

    **Returns** ``(profile, warning)``: unchanged and None without a contradiction; when the patch supports
    ``rotation_hz`` alone, the profile unchanged (Ω = 2π·rotation_hz, as always) and a warning; when it supports
    ``speed_kmh`` alone, a copy without ``rotation_hz`` (Ω = V/R_e) and a warning. **Raises** InputError (exit 2)
    when the patch supports both or neither: no answer can be right until the sidecar is corrected.
    """
    from dataclasses import replace

    conflict = rotation_speed_conflict(profile.condition, outer_radius_m)
    if conflict is None:
        return profile, None
    rot = float(profile.condition["rotation_hz"])
    speed = float(profile.condition["speed_kmh"])
    om_rot = 2.0 * math.pi * rot
    om_speed = speed * KMH / (0.98 * outer_radius_m)
    drop = patch_drop_omega(profile.angle_deg, profile.acc_radial_ms2)
    where = f"{Path(str(profile.source)).name or 'the profile'}"
    if drop is not None and drop > 0:
        by_rot, by_speed = _data_agree(drop, om_rot, outer_radius_m), _data_agree(drop, om_speed, outer_radius_m)
        says = (f"the profile's own radial reading drops {drop:.4g} m/s² into the contact patch, which means "
                f"Ω ≈ {math.sqrt(drop / (0.75 * outer_radius_m)):.3g} rad/s")
        if by_rot and not by_speed:
            return profile, (f"{where}: {conflict}; {says}, as rotation_hz says: Ω = 2π·rotation_hz = {om_rot:.4g} "
                             f"rad/s is used and speed_kmh = {speed:g} is wrong")
        if by_speed and not by_rot:
            cond = {k: v for k, v in profile.condition.items() if k != "rotation_hz"}
            cond["rotation_hz_ignored"] = rot
            return replace(profile, condition=cond), (
                f"{where}: {conflict}; {says}, as speed_kmh says: rotation_hz = {rot:g} is wrong and ignored, "
                f"Ω = speed_kmh/R_e is used")
        raise InputError(f"{conflict}; {says}, which does not tell which is right: correct the sidecar",
                         source=_sidecar(profile.source))
    raise InputError(f"{conflict}; the profile shows no contact patch to tell which is right: correct the sidecar",
                     source=_sidecar(profile.source))


def check_table_rotation(condition: dict, outer_radius_m: float, *, source) -> None:
    """A mode table's (or recording's) ``rotation_hz`` and ``speed_kmh`` that contradict: InputError (exit 2),
    since its frequencies cannot tell which is right (:func:`rotation_speed_conflict`)."""
    conflict = rotation_speed_conflict(condition, outer_radius_m)
    if conflict is not None:
        raise InputError(f"{conflict}: correct the sidecar", source=source)


def pressure_conflict(condition: dict, tyre_pressure_bar: float) -> str | None:
    """One sentence when a measurement's ``pressure_bar`` differs from the tyre file's by more than
    :data:`PRESSURE_TOL`, else None (also when it states none)."""
    p = _positive(condition, "pressure_bar")
    if p is None or abs(p - tyre_pressure_bar) <= PRESSURE_TOL * tyre_pressure_bar:
        return None
    return (f"pressure_bar = {p:g} differs from the tyre file's {tyre_pressure_bar:g} bar (more than "
            f"{100 * PRESSURE_TOL:g} %): the ring's stiffness depends on the pressure (docs/physics.md §1)")


#: What :func:`check_stated` does with a measurement at another pressure than the tyre file's: ``"refuse"`` (an
#: InputError) or ``"warn"``.
OtherPressure = Literal["refuse", "warn"]


def check_stated(item, geometry, *, source, other_pressure: OtherPressure, used_as: str = "",
                 pressure_law: bool = False) -> tuple[object, list[str]]:
    """A measurement's stated condition checked against the tyre file's geometry — its pressure
    (:func:`pressure_conflict`) and its rotation against its speed (a profile, which has its radial reading:
    :func:`check_profile_rotation`; a mode table: :func:`check_table_rotation`) — the one rule every command that
    reads a measured table or profile beside a tyre file applies.

    ``other_pressure``: ``"refuse"`` (InputError: the command fits the tyre's stiffness, which the pressure sets)
    or ``"warn"`` (a warning that the measurement is used ``used_as`` at the tyre file's pressure).
    ``pressure_law``: the tyre file has the pressure law (``[ring.pressure]``, docs/physics.md §13.1): the model
    carries the ring to the measurement's pressure, so another pressure is accepted without a word (the rule:
    refuse or warn only where the model would use the tyre file's pressure for it).
    **Returns** ``(item, warnings)``: the item as it is to be used (a profile's contradicting ``rotation_hz``
    dropped where its patch says so) and the warning lines, for the caller to issue."""
    if other_pressure not in get_args(OtherPressure):
        raise InputError(f"other_pressure = {other_pressure!r}; expected one of {get_args(OtherPressure)}")
    notes = []
    tyre_bar = float(geometry.pressure) / 1e5
    note = None if pressure_law else pressure_conflict(item.condition, tyre_bar)
    if note and other_pressure == "refuse":
        raise InputError(f"{note}; use measurements at the tyre file's pressure (or a tyre file at theirs)",
                         source=source)
    if note:
        name = Path(str(getattr(item, "source", None) or source)).name
        notes.append(f"{name}: {note}; {used_as or 'it is used'} at the tyre file's "
                     f"{tyre_bar:g} bar")
    outer = float(geometry.outer_radius)
    if hasattr(item, "acc_radial_ms2"):
        item, rot = check_profile_rotation(item, outer)
        notes += [rot] if rot else []
    else:
        check_table_rotation(item.condition, outer, source=source)
    return item, notes


#: |z| of a stated condition against an estimate's 95 % interval beyond which the two contradict: 3.29, two-sided
#: p = 0.001 for a calibrated interval (about one false contradiction in a thousand checks).
STATED_Z = 3.29
#: Conditions a sidecar may state that an estimate also reads from the data, and whether the estimate's interval is
#: log-normal (docs/formats.md §7.1).
STATED_ESTIMATED = {"load_n": True, "pressure_bar": True, "tread_depth_mm": True, "speed_kmh": False,
                    "torque_nm": False}
#: Relative σ of a stated value, where the format says it is nominal (docs/formats.md §3: a sidecar's
#: ``speed_kmh`` may be off by a few per cent, a vehicle's speedometer or a drum's set point; the encoder's
#: ``rotation_hz`` is what the data use): in quadrature with the estimate's σ. Every other stated value counts
#: as exact (a rig's load cell, a gauge's pressure, a tread gauge, a torque hub).
STATED_REL_SD = {"speed_kmh": RATE_TOL}


def stated_against_estimate(estimates: dict, condition: dict, *, source=None) -> list[dict]:
    """Every condition the input states that the estimate also read from the data, compared (docs/formats.md §7.2).

    ``estimates``: quantity → ``{value, lo, hi[, status]}`` (its 95 % interval; :data:`STATED_ESTIMATED` says
    which are log-normal); ``condition``: the input's stated condition. A quantity held at a value (``status``
    ``fixed``) or not told by the data (``not told``: its interval is its prior's) is not compared. Per compared
    quantity: ``stated``, ``value``, ``lo``, ``hi``, ``z`` (the stated value's distance from the estimate in the
    σ of the interval's half on its side, (hi − value)/1.96 or (value − lo)/1.96 — an interval along a ridge or
    cut at a bound is not symmetric —, in logarithms for a log-normal one, with a nominal value's own σ
    :data:`STATED_REL_SD` in quadrature), ``consistent`` (|z| ≤ :data:`STATED_Z`) and, when not, a
    ``sentence`` naming the input, the stated value and what the data read."""
    rows = []
    name = Path(str(source)).name if source else "the input"
    for key, log in STATED_ESTIMATED.items():
        q = estimates.get(key)
        raw = condition.get(key)
        if q is None or raw is None or q.get("status", "estimated") != "estimated":
            continue
        try:
            stated, value, lo, hi = (float(x) for x in (raw, q["value"], q["lo"], q["hi"]))
        except (TypeError, ValueError, KeyError):
            continue
        if not all(map(math.isfinite, (stated, value, lo, hi))) or not hi > lo:
            continue
        rel = STATED_REL_SD.get(key, 0.0)
        if log and min(stated, value, lo) <= 0.0:
            continue
        f = math.log if log else (lambda x: x)
        # the interval's σ on the stated value's side of the estimate: an interval along a ridge, or cut at a
        # bound (a tread depth held at the new tread's), is not symmetric about its value
        side = (f(hi) - f(value)) if stated >= value else (f(value) - f(lo))
        sigma = math.hypot(max(side, 1e-12 * max(abs(f(value)), 1.0)) / Z95, rel * (1.0 if log else abs(stated)))
        z = (f(stated) - f(value)) / sigma
        row = {"quantity": key, "stated": stated, "value": value, "lo": lo, "hi": hi, "z": round(z, 2),
               "consistent": abs(z) <= STATED_Z}
        if not row["consistent"]:
            row["sentence"] = (f"{name}: the stated {key} = {stated:g} contradicts the data, which read {value:.5g} "
                               f"[{lo:.5g}, {hi:.5g}] (95 %; the stated value {abs(z):.1f} σ away, beyond "
                               f"{STATED_Z:g}): check the sidecar, or the tyre file")
        rows.append(row)
    return rows


def _sidecar(source) -> str | None:
    if not source:
        return None
    p = Path(str(source))
    return str(p.with_suffix(".json")) if p.suffix == ".csv" else str(p)


def content_hash(path: str | os.PathLike) -> str:
    """SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def duplicate_inputs(paths) -> list[tuple[int, int, str]]:
    """Inputs that are one file given twice: ``(kept, duplicate, how)`` indices into ``paths`` per duplicate, the
    first kept. Two paths are the same input when they resolve to the same file (symlinks followed) or their
    bytes are equal (SHA-256; only files of equal size are read, so a batch of large recordings is not)."""
    paths = [Path(p) for p in paths]

    def size(p):
        try:
            return p.stat().st_size if p.is_file() else None
        except OSError:
            return None

    sizes = [size(p) for p in paths]
    shared = {n for n in sizes if n is not None and sizes.count(n) > 1}  # only files of equal size are hashed
    seen: dict[object, int] = {}
    out = []
    for i, p in enumerate(paths):
        try:
            real = p.resolve()
        except OSError:
            real = p
        digest = None
        if sizes[i] in shared:
            try:
                digest = content_hash(p)
            except OSError:
                digest = None
        hit, how = seen.get(("path", real)), "the same file (its resolved path)"
        if hit is None and digest is not None:
            hit, how = seen.get(("hash", digest)), "the same content (SHA-256)"
        if hit is not None:
            out.append((hit, i, how))
            continue
        seen[("path", real)] = i
        if digest is not None:
            seen[("hash", digest)] = i
    return out


def unique_inputs(paths, sidecar, what: str) -> tuple[list[Path], list[str]]:
    """``paths`` (sorted by name) with every duplicate (:func:`duplicate_inputs`) counted once — a file kept before
    a symlink to it — and one warning per duplicate.

    ``sidecar``: path → its sidecar path. A duplicate whose sidecar states another condition (the same readings
    said to be measured twice, under two conditions) is refused: InputError naming both files, since at most one
    of the two can be right."""
    import json

    # of a file and a link to it, the file is the one kept; otherwise the first by name
    paths = sorted((Path(p) for p in paths), key=lambda p: (p.is_symlink(), p.name))
    dropped, notes = set(), []
    for k, d, how in duplicate_inputs(paths):
        kept, dup = paths[k], paths[d]
        a, b = Path(sidecar(kept)), Path(sidecar(dup))
        try:
            ca = json.loads(a.read_text()) if a.is_file() else None
            cb = json.loads(b.read_text()) if b.is_file() else None
        except (OSError, ValueError):
            ca = cb = None
        if ca != cb:
            raise InputError(f"holds {how} as {kept.name} but its sidecar {b.name} states another condition "
                             f"than {a.name} ({_diff(ca, cb)}): the same readings cannot be measured twice; "
                             f"remove one of them", source=dup)
        dropped.add(d)
        notes.append(f"{dup} is {how} as {kept}: the same {what} given twice is counted once ({kept.name} used)"
                     if dup.name == kept.name else
                     f"{dup.name} is {how} as {kept.name}: the same {what} given twice is counted once "
                     f"({kept.name} used)")
    return sorted((p for i, p in enumerate(paths) if i not in dropped), key=lambda p: p.name), notes


def _diff(a, b) -> str:
    if not isinstance(a, dict) or not isinstance(b, dict):
        return "one has no readable sidecar"
    keys = [k for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
    return ", ".join(f"{k} {a.get(k)!r} vs {b.get(k)!r}" for k in keys[:3])


__all__ = ["rotation_speed_conflict", "patch_drop_omega", "check_profile_rotation", "check_table_rotation",
           "pressure_conflict", "duplicate_inputs", "unique_inputs", "content_hash", "ROLLING_RADIUS_M", "RATE_TOL",
           "ROLLING_RADIUS_SHARE", "PATCH_DROP_SHARE", "PRESSURE_TOL", "stated_against_estimate", "STATED_Z",
           "STATED_ESTIMATED", "STATED_REL_SD", "OtherPressure"]


def case_inputs(folder) -> tuple[list[Path], list[Path]]:
    """A case folder's test mode tables (``*.modes.csv`` but ``free.modes.csv``) and profiles (``*.profile.csv``),
    sorted by name, each counted once (:func:`unique_inputs`: a copy or a symlink of another is warned about and
    left out; the same readings under two stated conditions are refused). The one rule of ``diagnose``,
    ``campaign`` and ``identify`` for which files of a folder are data (docs/formats.md §6)."""
    import warnings

    folder = Path(folder)
    tables, notes = unique_inputs((p for p in folder.glob("*.modes.csv") if p.name != "free.modes.csv"),
                                  lambda p: p.with_suffix(".json"), "mode table")
    profiles, more = unique_inputs(folder.glob("*.profile.csv"), lambda p: p.with_suffix(".json"), "profile")
    for note in notes + more:
        warnings.warn(note, stacklevel=3)
    return tables, profiles
