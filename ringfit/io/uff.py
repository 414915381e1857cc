"""Universal File Format dataset 58 (UFF/UNV): time records and measured FRFs, via ``pyuff`` (docs/formats.md §4).

:func:`read_uff` reads function type 1 (time response) into :class:`~ringfit.io.record_types.Records` and type 4
(FRF, with its coherence) into :class:`~ringfit.io.record_types.MeasuredFRF`; units, axes, sensor angles and
completeness are checked, never guessed (§4 gives every rule: unit labels, direction codes, the order in which
an angle is looked for, a truncated file refused). :func:`write_uff58` writes time records as binary 58 datasets
that round-trip exactly (the sample rate in full on ID line 3, the angle on ID line 4).

Example (``ringfit example records --out ex``)::

    rec = read_records("ex/impact.records.npz")
    write_uff58(rec, "impact.uff")
    back = read_uff("impact.uff")
    back.fs_hz == rec.fs_hz, np.array_equal(back.acc, rec.acc), back.axes   # True, True, ('radial', 'tangential')
"""

from __future__ import annotations

import math
import os
import re
import warnings
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.files import atomic_write, check_output_path, existing_file
from ringfit.io.record_types import AXES, MeasuredFRF, Records
from ringfit.units import G_UNIT

#: ringfit's axis -> UFF direction code (the accelerometer's x, y, z inside the tyre).
DIRECTION = {"tangential": 1, "lateral": 2, "radial": 3}
AXIS_OF_DIRECTION = {v: k for k, v in DIRECTION.items()}
#: Function types (UFF58 record 6, field 1) read by ringfit.
TIME_RESPONSE, FRF, COHERENCE = 1, 4, 6
#: Ordinate specific data types (record 9, field 1).
DISPLACEMENT, VELOCITY, ACCELERATION, FORCE, PRESSURE, SOUND_PRESSURE = 8, 11, 12, 13, 15, 21
_SPECIFIC = {0: "unknown", 1: "general", 2: "stress", 3: "strain", 5: "temperature", 6: "heat flux",
             8: "displacement", 9: "reaction force", 11: "velocity", 12: "acceleration", 13: "excitation force",
             15: "pressure", 16: "mass", 17: "time", 18: "frequency", 19: "rpm", 20: "order", 21: "sound pressure",
             22: "sound intensity", 23: "sound power"}
_FUNCTIONS = {0: "general or unknown", 1: "time response", 2: "auto spectrum", 3: "cross spectrum",
              4: "frequency response function", 5: "transmissibility", 6: "coherence", 7: "auto correlation",
              8: "cross correlation", 9: "power spectral density", 10: "energy spectral density",
              11: "probability density function", 12: "spectrum", 13: "cumulative frequency distribution"}
STANDARD_GRAVITY = G_UNIT  # m/s² per g (ringfit.units)
_ANGLE = re.compile(r"sensor_angle_deg\s*=\s*([-+0-9.eE]+)")
_FS = re.compile(r"fs_hz\s*=\s*([-+0-9.eE]+)")
_OWN_ID = "ringfit records"

# unit words: quantity, scale to SI
_ACC = {"m/s^2": 1.0, "m/s2": 1.0, "m/s²": 1.0, "ms^-2": 1.0, "ms-2": 1.0, "m/s/s": 1.0, "m/s\ufffd": 1.0,
        "mm/s^2": 1e-3, "mm/s2": 1e-3, "mm/s²": 1e-3, "g": STANDARD_GRAVITY, "gn": STANDARD_GRAVITY,
        "g's": STANDARD_GRAVITY}
_VEL = {"m/s": 1.0, "mm/s": 1e-3}
_DISP = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6}
_FORCE = {"n": 1.0, "kn": 1e3, "lbf": 4.4482216152605, "lb": 4.4482216152605}
_PRESSURE = {"pa", "kpa", "mpa", "bar", "psi", "dbspl", "db"}


def _pyuff():
    try:
        import pyuff
    except ImportError as exc:  # pragma: no cover - pyuff is a dependency
        raise ImportError("reading/writing UFF files needs pyuff: pip install pyuff") from exc
    return pyuff


# --------------------------------------------------------------------------- writing


def write_uff58(records: Records, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``records`` as binary UFF type-58 datasets (float64, exact round trip).

    Refuses to overwrite an existing file unless ``overwrite``; writes atomically.
    """
    pyuff = _pyuff()
    path = check_output_path(path, overwrite=overwrite)
    dt = 1.0 / records.fs_hz
    t = np.arange(records.n_samples) * dt
    sets = []
    for r in range(records.n_records):
        angle = float(records.sensor_angle_deg[r])
        common = dict(
            binary=1, func_type=TIME_RESPONSE, ver_num=0, load_case_id=0, rsp_ent_name="tyre", rsp_node=r + 1,
            ref_ent_name="hammer", ref_node=0, ref_dir=3, abscissa_spacing=1, abscissa_min=0.0,
            abscissa_inc=dt, z_axis_value=0.0, abscissa_spec_data_type=17, abscissa_axis_units_lab="s",
            abscissa_len_unit_exp=0, abscissa_force_unit_exp=0, abscissa_temp_unit_exp=0,
            ordinate_len_unit_exp=0, ordinate_force_unit_exp=0, ordinate_temp_unit_exp=0,
            orddenom_spec_data_type=0, orddenom_len_unit_exp=0, orddenom_force_unit_exp=0,
            orddenom_temp_unit_exp=0, orddenom_axis_units_lab="", z_axis_spec_data_type=0,
            z_axis_len_unit_exp=0, z_axis_force_unit_exp=0, z_axis_temp_unit_exp=0, z_axis_axis_units_lab="",
            id1=_OWN_ID, id3=f"time response fs_hz={records.fs_hz!r}", id4=f"sensor_angle_deg={angle!r}", x=t,
        )
        for a, axis in enumerate(records.axes):
            sets.append(pyuff.prepare_58(
                **common, id2=f"record {r} {axis} acceleration", id5="unit m/s^2", rsp_dir=DIRECTION[axis],
                ordinate_spec_data_type=ACCELERATION, ordinate_axis_units_lab="m/s^2",
                data=np.ascontiguousarray(records.acc[r, a], dtype=np.float64),
            ))
        if records.force is not None:
            sets.append(pyuff.prepare_58(
                **common, id2=f"record {r} force", id5="unit N", rsp_dir=3,
                ordinate_spec_data_type=FORCE, ordinate_axis_units_lab="N",
                data=np.ascontiguousarray(records.force[r], dtype=np.float64),
            ))

    def write(tmp: Path):
        tmp.unlink()  # pyuff appends to existing files
        pyuff.UFF(str(tmp)).write_sets(sets, mode="add")

    atomic_write(path, write)
    return path


# --------------------------------------------------------------------------- reading


def read_uff(path: str | os.PathLike, *, angles: dict | None = None, axes: dict | None = None
             ) -> Records | MeasuredFRF:
    """Read the dataset-58 time records or FRFs of a UFF file (module docstring: the mapping and checks).

    **Arguments:**

    - ``angles``: ``{node: angle_deg}`` — sensor angle of each response node,
      for files without ringfit's ID line or node coordinates (overrides both).
    - ``axes``: ``{direction_code: axis_name}`` — e.g. ``{0: "radial"}`` for
      scalar channels or ``{3: "tangential"}`` to override ringfit's convention.

    **Returns:** :class:`Records` for time responses, :class:`MeasuredFRF` for FRFs.

    **Raises** :class:`InputError` (one line naming the file and dataset) for a
    missing, unreadable or truncated file, no usable dataset 58, a unit that
    is not acceleration/force, a direction or angle it cannot place, datasets
    of different lengths or sample rates.
    """
    path = Path(path)
    axis_of = _axis_map(axes, path)
    angles = {int(k): float(v) for k, v in (angles or {}).items()}
    sets = _read_sets(path)
    coords = _node_coordinates(sets)
    d58 = [(i, s) for i, s in enumerate(sets) if s.get("type") == 58]
    if not d58:
        kinds = sorted({str(s.get("type")) for s in sets})
        raise InputError(f"no dataset 58 (function at nodal DOF); found dataset types {', '.join(kinds) or 'none'}",
                         source=path)
    for i, s in d58:
        n_pts, data = int(s.get("num_pts", -1)), np.asarray(s.get("data", []))
        if data.ndim != 1 or data.size != n_pts:
            raise InputError(f"dataset {i} (58) announces {n_pts} points but holds {data.size}: "
                             "the file is truncated or corrupted", source=path)
    funcs = {int(s.get("func_type", 0)) for _, s in d58}
    usable = funcs & {TIME_RESPONSE, FRF}
    if not usable:
        names = ", ".join(f"{f} ({_FUNCTIONS.get(f, '?')})" for f in sorted(funcs))
        raise InputError(f"dataset-58 function types {names}; ringfit reads time responses (1) and "
                         "frequency response functions (4)", source=path)
    if usable == {TIME_RESPONSE, FRF}:
        raise InputError("mixes time responses (function type 1) and FRFs (type 4); give one kind per file",
                         source=path)
    skipped = [(i, int(s.get("func_type", 0))) for i, s in d58
               if int(s.get("func_type", 0)) not in usable | ({COHERENCE} if FRF in usable else set())]
    if skipped:
        kinds = ", ".join(f"{f} ({_FUNCTIONS.get(f, '?')})" for f in sorted({f for _, f in skipped}))
        warnings.warn(f"{path}: {len(skipped)} dataset(s) of function type {kinds} not used", stacklevel=2)
    own = all(str(s.get("id1", "")).strip() == _OWN_ID for _, s in d58)
    ctx = _Context(path, axis_of, angles, coords, own)
    if TIME_RESPONSE in usable:
        return _time_records(ctx, [(i, s) for i, s in d58 if int(s.get("func_type", 0)) == TIME_RESPONSE])
    return _frf_records(ctx, [(i, s) for i, s in d58 if int(s.get("func_type", 0)) in (FRF, COHERENCE)])


class _Context:
    def __init__(self, path, axis_of, angles, coords, own):
        self.path, self.axis_of, self.angles, self.coords, self.own = path, axis_of, angles, coords, own
        self.order: list[tuple] = []  # record keys (response node, reference node, take) in file order
        self.angle_of: dict[tuple, float] = {}
        self.seen: dict[tuple, int] = {}

    def place(self, table: dict, i, s, axis: str, values) -> None:
        """Put dataset i's ``values`` into ``table[record][axis]``; a repeated node/reference/axis starts a new take."""
        node, ref = int(s.get("rsp_node", 0)), int(s.get("ref_node", 0))
        take = self.seen.get((node, ref, axis), 0)
        self.seen[(node, ref, axis)] = take + 1
        key = (node, ref, take)
        if key not in table:
            table[key] = {}
            self.order.append(key)
            self.angle_of[key] = self.angle(i, s)
        table[key][axis] = values

    def complete(self, table: dict, what: str) -> tuple[list, dict, list]:
        """(record keys, their angles, axes used) once every record has every axis that any record has."""
        if not table:
            raise InputError(f"no {what} found", source=self.path)
        used = [a for a in AXES if any(a in table[k] for k in self.order)]
        for k in self.order:
            missing = [a for a in used if a not in table[k]]
            if missing:
                raise InputError(f"node {k[0]} (reference {k[1]}, take {k[2] + 1}): no dataset for axis "
                                 f"{missing[0]!r} while other records have it", source=self.path)
        return self.order, self.angle_of, used

    def axis(self, i, s) -> tuple[str, float]:
        """(axis name, sign) of dataset i's response direction."""
        code = int(s.get("rsp_dir", 0))
        name = self.axis_of.get(abs(code))
        if name is None:
            if code == 0:
                raise InputError(f"dataset {i} (node {s.get('rsp_node')}): response direction 0 (a scalar channel); "
                                 "say which axis it is, e.g. --axes 0=radial", source=self.path)
            raise InputError(f"dataset {i} (node {s.get('rsp_node')}): response direction {code}; expected ±1, ±2, "
                             "±3, or map it with --axes CODE=AXIS", source=self.path)
        return name, (-1.0 if code < 0 else 1.0)

    def angle(self, i, s) -> float:
        """Sensor angle [deg] from the excitation point of dataset i's response node."""
        node, ref = int(s.get("rsp_node", 0)), int(s.get("ref_node", 0))
        if node in self.angles:
            return self.angles[node]
        m = _ANGLE.search(str(s.get("id4", "")) + " " + str(s.get("id5", "")))
        if m:
            return float(m.group(1))
        if node in self.coords:
            a = self.coords[node]
            if ref in self.coords and ref != node:
                a -= self.coords[ref]
            return (a + 180.0) % 360.0 - 180.0
        raise InputError(f"dataset {i}: node {node} has no sensor angle; give --angles {node}=DEG,... or node "
                         "coordinates (dataset 15 or 2411)", source=self.path)


def _read_sets(path: Path) -> list[dict]:
    path = existing_file(path, "a UFF file")
    _check_complete(path)
    pyuff = _pyuff()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            uff = pyuff.UFF(str(path))
            types = list(uff.get_set_types())
            sets = uff.read_sets() if types else []
    except Exception as exc:  # noqa: BLE001 - pyuff raises assorted errors on bad files
        text = str(exc).splitlines()[0][:120] if str(exc) else ""
        raise InputError(f"not a readable UFF file ({exc.__class__.__name__}: {text})", source=path) from None
    if isinstance(sets, dict):
        sets = [sets]
    if not sets:
        raise InputError("no UFF datasets found (expected blocks between '    -1' lines)", source=path)
    return list(sets)


def _check_complete(path: Path) -> None:
    """A UFF file ends with a dataset delimiter line '-1'; anything else was cut off."""
    size = path.stat().st_size
    if size == 0:
        raise InputError("empty file", source=path)
    with open(path, "rb") as fh:
        fh.seek(max(0, size - 256))
        tail = fh.read()
    if not re.search(rb"(^|\s)-1$", tail.rstrip()):  # binary data may run right up to the "    -1"
        raise InputError("does not end with a dataset delimiter ('    -1'): the file is truncated", source=path)


def _axis_map(axes: dict | None, path) -> dict[int, str]:
    out = dict(AXIS_OF_DIRECTION)
    for code, name in (axes or {}).items():
        code, name = int(code), str(name)
        if name not in AXES:
            raise InputError(f"--axes {code}={name}: expected an axis from {list(AXES)}", source=path)
        if code < 0:
            raise InputError(f"--axes {code}={name}: give the direction code without its sign", source=path)
        out[code] = name
    return out


def unit_scale(label: str) -> tuple[str, float] | None:
    """(quantity, scale to SI) of a unit label, e.g. 'g' -> ('acc', 9.80665); None if unknown."""
    t = label.strip().lower().replace(" ", "").replace("**", "^")
    t = t.strip("[]()")
    if t in ("", "none"):
        return None
    for table, kind in ((_ACC, "acc"), (_VEL, "vel"), (_DISP, "disp"), (_FORCE, "force")):
        if t in table:
            return kind, table[t]
    if t in _PRESSURE:
        return "pressure", 1.0
    return None


def _ratio_unit(label: str) -> tuple[str, float] | None:
    """(numerator quantity, scale to SI) of an FRF label such as '(m/s^2)/N', 'g/N', '(1/N)*(m/s²)'."""
    t = label.strip().lower().replace(" ", "")
    m = re.fullmatch(r"\(?1/([a-z]+)\)?\*\(?(.+?)\)?", t)  # (1/N)*(m/s²)
    if m:
        den, num = m.group(1), m.group(2)
    else:
        m = re.fullmatch(r"\(?(.+?)\)?/\(?([a-z]+)\)?", t)
        if not m:
            return None
        num, den = m.group(1), m.group(2)
    n, d = unit_scale(num), unit_scale(den)
    if n is None or d is None or d[0] != "force":
        return None
    return n[0], n[1] / d[1]


def _ordinate(i, s, path) -> tuple[str, float]:
    """(quantity, scale) of a time-response dataset's ordinate: 'acc' or 'force'; others refused."""
    spec = int(s.get("ordinate_spec_data_type", 0))
    label = str(s.get("ordinate_axis_units_lab", ""))
    unit = unit_scale(label)
    where = f"dataset {i} (node {s.get('rsp_node')}, direction {s.get('rsp_dir')})"
    kind = {ACCELERATION: "acc", FORCE: "force", 9: "force"}.get(spec)
    if spec in (PRESSURE, SOUND_PRESSURE) or (unit and unit[0] == "pressure"):
        what = _SPECIFIC[spec] if spec in (PRESSURE, SOUND_PRESSURE) else "a pressure"
        raise InputError(f"{where}: ordinate is {what} [{label.strip() or '?'}], not acceleration "
                         "(a microphone?); ringfit reads accelerometer records", source=path)
    if spec in (DISPLACEMENT, VELOCITY) or (unit and unit[0] in ("disp", "vel") and kind is None):
        raise InputError(f"{where}: ordinate is {_SPECIFIC.get(spec) if spec in (8, 11) else unit[0]} "
                         f"[{label.strip()}], not acceleration", source=path)
    if kind is None:
        if unit is None:
            raise InputError(f"{where}: ordinate type {spec} ({_SPECIFIC.get(spec, '?')}) with unit "
                             f"{label.strip()!r}; expected an acceleration (m/s², g) or a force (N)", source=path)
        return unit
    if unit is None:
        return kind, 1.0  # typed by the header, unit label empty: SI
    if unit[0] != kind:
        raise InputError(f"{where}: ordinate type {spec} ({_SPECIFIC[spec]}) but unit {label.strip()!r}", source=path)
    return unit


def _time_records(ctx: _Context, sets) -> Records:
    path = ctx.path
    fs = length = None
    acc: dict[tuple, dict[str, np.ndarray]] = {}  # (rsp node, ref node, take) -> axis -> samples
    forces: list[np.ndarray] = []
    for i, s in sets:
        inc = float(s.get("abscissa_inc", 0.0))
        if int(s.get("abscissa_spacing", 1)) != 1 or not (math.isfinite(inc) and inc > 0):
            raise InputError(f"dataset {i}: uneven or missing time step (abscissa increment {inc}); expected an "
                             "evenly sampled time response", source=path)
        m = _FS.search(str(s.get("id3", "")))
        fs_i = float(m.group(1)) if m else 1.0 / inc  # the ID line keeps all digits; the header 6
        if fs is None:
            fs = fs_i
        elif not math.isclose(fs_i, fs, rel_tol=1e-5):
            raise InputError(f"dataset {i}: sample rate {fs_i:g} Hz differs from {fs:g} Hz", source=path)
        data = np.asarray(s["data"])
        if np.iscomplexobj(data):
            raise InputError(f"dataset {i}: complex data in a time response", source=path)
        if length is None:
            length = data.size
        elif data.size != length:
            raise InputError(f"dataset {i}: {data.size} samples; the others have {length}", source=path)
        kind, scale = _ordinate(i, s, path)
        data = data.astype(np.float64) * scale
        if kind == "force":
            forces.append(data)
            continue
        name, sign = ctx.axis(i, s)
        ctx.place(acc, i, s, name, sign * data)
    order, angle_of, used = ctx.complete(acc, "acceleration datasets (dataset 58, function type 1)")
    if forces and len(forces) != len(order):
        raise InputError(f"{len(forces)} force datasets for {len(order)} records; expected one force per record "
                         "(paired in file order) or none", source=path)
    return Records(
        acc=np.stack([np.stack([acc[k][a] for a in used]) for k in order]),
        axes=tuple(used),
        sensor_angle_deg=np.array([angle_of[k] for k in order]),
        fs_hz=fs,
        force=np.stack(forces) if forces else None,
        source=str(path),
    )


def _frf_records(ctx: _Context, sets) -> MeasuredFRF:
    path = ctx.path
    freq = None
    frf: dict[tuple, dict[str, np.ndarray]] = {}
    coh: dict[tuple, dict[str, np.ndarray]] = {}
    for i, s in sets:
        inc, f0, n = float(s.get("abscissa_inc", 0.0)), float(s.get("abscissa_min", 0.0)), int(s["num_pts"])
        if int(s.get("abscissa_spacing", 1)) != 1 or not (math.isfinite(inc) and inc > 0 and math.isfinite(f0)):
            raise InputError(f"dataset {i}: uneven or missing frequency step; expected evenly spaced lines",
                             source=path)
        f = f0 + inc * np.arange(n)
        if freq is None:
            freq = f
        elif f.size != freq.size or not np.allclose(f, freq, rtol=1e-6, atol=1e-9):
            raise InputError(f"dataset {i}: frequency axis differs from the first dataset's", source=path)
        name, sign = ctx.axis(i, s)
        node, ref = int(s.get("rsp_node", 0)), int(s.get("ref_node", 0))
        data = np.asarray(s["data"])
        if int(s.get("func_type")) == COHERENCE:
            coh.setdefault((node, ref), {}).setdefault(name, []).append(np.abs(data).astype(np.float64))
            continue
        kind, scale = _frf_ordinate(i, s, path)
        h = sign * scale * data.astype(np.complex128)
        w = 2 * np.pi * f
        if kind == "vel":  # mobility -> accelerance: A = iω V
            h = 1j * w * h
        elif kind == "disp":  # receptance -> accelerance: A = -ω² X
            h = -(w**2) * h
        ctx.place(frf, i, s, name, h)
    order, angle_of, used = ctx.complete(frf, "FRF datasets (dataset 58, function type 4)")
    coherence = None
    if coh:
        try:
            coherence = np.stack([np.stack([coh[k[:2]][a][k[2]] for a in used]) for k in order])
        except (KeyError, IndexError):
            warnings.warn(f"{path}: coherence datasets do not cover every FRF; coherence not used", stacklevel=3)
    return MeasuredFRF(freq_hz=freq, frf=np.stack([np.stack([frf[k][a] for a in used]) for k in order]),
                       axes=tuple(used), sensor_angle_deg=np.array([angle_of[k] for k in order]),
                       coherence=coherence, source=str(path))


def _frf_ordinate(i, s, path) -> tuple[str, float]:
    """(numerator quantity, scale) of an FRF: accelerance, mobility or receptance over force."""
    spec = int(s.get("ordinate_spec_data_type", 0))
    den = int(s.get("orddenom_spec_data_type", 0))
    label = str(s.get("ordinate_axis_units_lab", ""))
    where = f"dataset {i} (node {s.get('rsp_node')}, direction {s.get('rsp_dir')})"
    by_type = {ACCELERATION: "acc", VELOCITY: "vel", DISPLACEMENT: "disp"}.get(spec)
    if spec in (PRESSURE, SOUND_PRESSURE):
        raise InputError(f"{where}: FRF of a {_SPECIFIC[spec]} (a microphone?), not of an acceleration", source=path)
    ratio = _ratio_unit(label)
    if ratio is None:
        unit = unit_scale(label)
        if unit and unit[0] == "pressure":
            raise InputError(f"{where}: FRF unit {label.strip()!r} is a pressure, not an acceleration per force",
                             source=path)
        if by_type is not None and den in (0, FORCE) and unit is None:
            return by_type, 1.0  # typed by the header; unit label missing: SI per N
        if by_type is not None and unit is not None and unit[0] == by_type and den == FORCE:
            den_unit = unit_scale(str(s.get("orddenom_axis_units_lab", ""))) or ("force", 1.0)
            return by_type, unit[1] / den_unit[1]
        raise InputError(f"{where}: FRF unit {label.strip()!r} (ordinate type {spec}, {_SPECIFIC.get(spec, '?')}); "
                         "expected acceleration, velocity or displacement per force, e.g. '(m/s^2)/N'", source=path)
    if ratio[0] == "pressure":
        raise InputError(f"{where}: FRF unit {label.strip()!r} is a pressure per force", source=path)
    if by_type is not None and by_type != ratio[0]:
        raise InputError(f"{where}: ordinate type {spec} ({_SPECIFIC[spec]}) but unit {label.strip()!r}", source=path)
    return ratio


def _node_coordinates(sets) -> dict[int, float]:
    """node -> angle [deg] around the axle, from dataset 15 / 2411 coordinates.

    The origin of the coordinates is on the axle; the axle is the coordinate
    axis along which the nodes spread least (a ring of nodes lies in a plane;
    z with fewer than 3 nodes); the angle is measured in the other two in
    cyclic order (x→y about z, y→z about x, z→x about y).
    """
    nodes, xyz = [], []
    for s in sets:
        if s.get("type") in (15, 2411) and "node_nums" in s:
            for n, x, y, z in zip(s["node_nums"], s["x"], s["y"], s.get("z", np.zeros(len(s["x"])))):
                nodes.append(int(n))
                xyz.append((float(x), float(y), float(z)))
    if not nodes:
        return {}
    p = np.asarray(xyz)
    axle = int(np.argmin(np.ptp(p, axis=0))) if len(nodes) >= 3 else 2
    u, v = (axle + 1) % 3, (axle + 2) % 3
    return {n: math.degrees(math.atan2(q[v], q[u])) for n, q in zip(nodes, p)}
