"""Universal File Format type 58 (UFF/UNV) time records, via ``pyuff`` (DATA.md §4).

Commercial modal-test systems exchange time histories as type-58 datasets
("function at nodal DOF", function type 1 = time response). ringfit maps
them to :class:`~ringfit.io.records.Records` as follows:

- one dataset per (record, axis) for acceleration (ordinate specific data
  type 12) and one per record for the hammer force (type 13, optional);
- the record is the response node (``rsp_node``, sorted ascending);
- the axis is the response direction: ``1`` tangential, ``2`` lateral,
  ``3`` radial (sign ignored on reading);
- the sample rate is written in full to ID line 3 as ``fs_hz=<value>``
  (the abscissa increment keeps only 6 digits); otherwise ``1 / abscissa_inc``;
- the sensor angle is written to ID line 4 as ``sensor_angle_deg=<value>``;
  files from other systems may instead carry node coordinates in a type-15
  or type-2411 dataset, from which the angle is ``atan2(y, x)`` in degrees.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.files import atomic_write, check_output_path
from ringfit.io.records import Records

#: axis name -> UFF direction code (R6 F7).
DIRECTION = {"tangential": 1, "lateral": 2, "radial": 3}
AXIS_OF_DIRECTION = {v: k for k, v in DIRECTION.items()}
ACCELERATION, FORCE = 12, 13  # ordinate specific data types
_ANGLE = re.compile(r"sensor_angle_deg\s*=\s*([-+0-9.eE]+)")
_FS = re.compile(r"fs_hz\s*=\s*([-+0-9.eE]+)")


def _pyuff():
    try:
        import pyuff
    except ImportError as exc:  # pragma: no cover - pyuff is a dependency
        raise ImportError("reading/writing UFF files needs pyuff: pip install pyuff") from exc
    return pyuff


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
            binary=1, func_type=1, ver_num=0, load_case_id=0, rsp_ent_name="tyre", rsp_node=r + 1,
            ref_ent_name="hammer", ref_node=0, ref_dir=3, abscissa_spacing=1, abscissa_min=0.0,
            abscissa_inc=dt, z_axis_value=0.0, abscissa_spec_data_type=17, abscissa_axis_units_lab="s",
            abscissa_len_unit_exp=0, abscissa_force_unit_exp=0, abscissa_temp_unit_exp=0,
            ordinate_len_unit_exp=0, ordinate_force_unit_exp=0, ordinate_temp_unit_exp=0,
            orddenom_spec_data_type=0, orddenom_len_unit_exp=0, orddenom_force_unit_exp=0,
            orddenom_temp_unit_exp=0, orddenom_axis_units_lab="", z_axis_spec_data_type=0,
            z_axis_len_unit_exp=0, z_axis_force_unit_exp=0, z_axis_temp_unit_exp=0, z_axis_axis_units_lab="",
            id1="ringfit records", id3=f"time response fs_hz={records.fs_hz!r}", id4=f"sensor_angle_deg={angle!r}", x=t,
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


def read_uff58(path: str | os.PathLike) -> Records:
    """Read type-58 time records (see the module docstring for the mapping).

    **Raises** :class:`InputError` when the file is missing or unreadable,
    holds no type-58 time responses, mixes sample rates or lengths, misses an
    axis for some record, or gives no sensor angle.
    """
    pyuff = _pyuff()
    path = Path(path)
    if not path.exists():
        raise InputError("file not found", source=path)
    try:
        uff = pyuff.UFF(str(path))
        types = list(uff.get_set_types())
        sets = uff.read_sets() if types else []
    except Exception as exc:  # pyuff raises assorted errors on bad files
        raise InputError(f"not a readable UFF file ({exc.__class__.__name__}: {exc})", source=path) from None
    if isinstance(sets, dict):
        sets = [sets]
    coords = _node_angles(sets)
    acc: dict[int, dict[str, np.ndarray]] = {}
    force: dict[int, np.ndarray] = {}
    angle: dict[int, float] = {}
    fs = None
    for i, s in enumerate(sets):
        if s.get("type") != 58 or int(s.get("func_type", 0)) != 1:
            continue
        where = f"dataset {i} (type 58)"
        inc = float(s.get("abscissa_inc", 0.0))
        if not (math.isfinite(inc) and inc > 0):
            raise InputError(f"{where}: abscissa increment {inc}; expected an even time step > 0", source=path)
        m = _FS.search(str(s.get("id3", "")))
        fs_i = float(m.group(1)) if m else 1.0 / inc  # the ID line keeps all digits; the record 5 digits
        if fs is None:
            fs = fs_i
        elif not math.isclose(fs_i, fs, rel_tol=1e-9):
            raise InputError(f"{where}: sample rate {fs_i:g} Hz differs from {fs:g} Hz", source=path)
        node = int(s["rsp_node"])
        data = np.real(np.asarray(s["data"], dtype=np.complex128 if np.iscomplexobj(s["data"]) else np.float64))
        m = _ANGLE.search(str(s.get("id4", "")) + " " + str(s.get("id5", "")))
        if m:
            angle[node] = float(m.group(1))
        elif node in coords:
            angle.setdefault(node, coords[node])
        if int(s.get("ordinate_spec_data_type", ACCELERATION)) == FORCE:
            force[node] = data
            continue
        direction = abs(int(s["rsp_dir"]))
        if direction not in AXIS_OF_DIRECTION:
            raise InputError(f"{where}: response direction {s['rsp_dir']}; expected 1, 2 or 3", source=path)
        acc.setdefault(node, {})[AXIS_OF_DIRECTION[direction]] = data
    if not acc:
        raise InputError("no type-58 time-response datasets with acceleration found", source=path)
    nodes = sorted(acc)
    axes = tuple(a for a in ("radial", "tangential", "lateral") if any(a in acc[n] for n in nodes))
    lengths = {len(v) for n in nodes for v in acc[n].values()} | {len(v) for v in force.values()}
    if len(lengths) != 1:
        raise InputError(f"records have different lengths {sorted(lengths)}; expected one length", source=path)
    for n in nodes:
        missing = [a for a in axes if a not in acc[n]]
        if missing:
            raise InputError(f"node {n}: no dataset for axis {missing[0]!r}", source=path)
        if n not in angle:
            raise InputError(f"node {n}: no sensor angle (ID line 4 'sensor_angle_deg=...' or node coordinates)", source=path)
    if force and set(force) != set(nodes):
        raise InputError(f"force datasets for nodes {sorted(force)} but acceleration for {nodes}", source=path)
    return Records(
        acc=np.stack([np.stack([acc[n][a] for a in axes]) for n in nodes]),
        axes=axes,
        sensor_angle_deg=np.array([angle[n] for n in nodes]),
        fs_hz=fs,
        force=np.stack([force[n] for n in nodes]) if force else None,
        source=str(path),
    )


def _node_angles(sets) -> dict[int, float]:
    """node -> atan2(y, x) [deg] from type-15 / type-2411 node datasets, if any."""
    out = {}
    for s in sets:
        if s.get("type") in (15, 2411) and "node_nums" in s:
            for n, x, y in zip(s["node_nums"], s["x"], s["y"]):
                out[int(n)] = math.degrees(math.atan2(float(y), float(x)))
    return out
