"""MATLAB .mat files: v5 (``scipy.io.loadmat``) and v7.3 (HDF5, ``h5py``) (docs/formats.md §17.2).

Two layouts are read:

- **ringfit's keys** — a variable ``acc`` (records × axes × samples, as
  MATLAB shows it) with ``axes`` (char matrix or cell array of names),
  ``sensor_angle_deg``, ``fs_hz`` and optional ``force``: the npz keys of
  docs/formats.md §4 (continuous: §9 keys ``encoder_angle_deg``,
  ``encoder_pulses``, ``hall``, ``pulses_per_rev``, … with ``acc`` of 1 record),
  SI units. No channel map.
- **channels** — every numeric vector variable is a channel named by the
  variable; numeric scalars are file-level values (``fs_hz``,
  ``pulses_per_rev``, ``speed_kmh``, …). The channel map gives what the file
  does not (unit, axis, angle).

v7.3 files are HDF5 with MATLAB's column-major order (dimensions reversed on
disk) and a ``MATLAB_class`` attribute per variable; ``char`` is UTF-16
code units, ``cell`` an array of object references. Structs, objects,
sparse and complex variables are skipped with a warning (refused when
``acc`` is one of them). Nothing is unpickled; MATLAB objects stay opaque.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np

from ringfit.errors import InputError
from ringfit.io.channel_map import SCALAR_KEYS
from ringfit.io.files import atomic_write, check_output_path, existing_file
from ringfit.io.record_types import Records
from ringfit.io.rig_types import RawChannel, RigFile

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: Keys of ringfit's own layout (docs/formats.md §4, §9); the scalars among them are ``SCALAR_KEYS``.
OWN_KEYS = ("acc", "axes", "sensor_angle_deg", "force", "encoder_angle_deg", "encoder_pulses", "hall", "kind",
            *SCALAR_KEYS)


def is_v73(path: Path) -> bool:
    """True for a MATLAB v7.3 (HDF5) file: the HDF5 signature at byte 0 or 512 (after MATLAB's text header)."""
    with open(path, "rb") as fh:
        head = fh.read(520)
    return head[:8] == HDF5_SIGNATURE or head[512:520] == HDF5_SIGNATURE


# --------------------------------------------------------------------------- reading the variables


def _strings(value) -> list[str] | None:
    """A char matrix / cell array of text / string as a list of names, else None."""
    a = np.asarray(value)
    if a.dtype.kind == "U":
        return [str(s).strip() for s in a.ravel()]
    if a.dtype == object:
        out = []
        for item in a.ravel():
            s = _strings(item)
            if s is None or len(s) != 1:
                return None
            out += s
        return out
    return None


def _load_v5(path: Path) -> tuple[dict, list[str]]:
    import scipy.io

    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            raw = scipy.io.loadmat(str(path), squeeze_me=False, chars_as_strings=True, struct_as_record=True)
        if any("Duplicate variable name" in str(w.message) for w in caught):
            _refuse_duplicates(path)
    except InputError:
        raise
    except NotImplementedError:  # "Please use HDF reader for matlab v7.3 files"
        raise InputError("a MATLAB v7.3 file without its HDF5 signature; truncated or corrupted?", source=path) from None
    except Exception as exc:  # noqa: BLE001 - scipy raises assorted errors on bad files
        text = str(exc).splitlines()[0][:120] if str(exc) else ""
        raise InputError(f"not a readable MATLAB file ({exc.__class__.__name__}: {text}); truncated or corrupted?",
                         source=path) from None
    out, skipped = {}, []
    for key, value in raw.items():
        if key.startswith("__"):
            continue
        a = np.asarray(value)
        names = _strings(a)
        if names is not None:
            out[key] = names
        elif a.dtype.kind in "fiub":
            out[key] = a
        else:
            skipped.append(key)  # structs, complex, objects, sparse
    return out, skipped


def _shown(value) -> str:
    a = np.asarray(value)
    if a.dtype.kind in "fiub" and a.size == 1:
        return f"{a.reshape(()).item():g}" if a.dtype.kind == "f" else str(a.reshape(()).item())
    if a.dtype.kind in "U":
        return repr(" ".join(str(x) for x in a.ravel()))[:40]
    return f"an array of shape {a.shape}"


def _refuse_duplicates(path: Path) -> None:
    """A v5 file that stores a variable twice (a concatenated save, ``save -append`` by hand): scipy keeps the
    last, silently. Each variable's copies are read (``scipy.io.matlab.varmats_from_mat``); copies that differ
    are refused, naming the variable and both values (which one holds, the file cannot tell)."""
    import scipy.io
    from scipy.io.matlab import varmats_from_mat

    seen: dict[str, list] = {}
    with open(path, "rb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for name, stream in varmats_from_mat(fh):
            value = scipy.io.loadmat(stream, squeeze_me=False, chars_as_strings=True).get(name)
            seen.setdefault(name, []).append(value)
    for name, values in seen.items():
        first = np.asarray(values[0])
        for other in values[1:]:
            other = np.asarray(other)
            same = first.shape == other.shape and first.dtype.kind == other.dtype.kind and (
                np.array_equal(first, other, equal_nan=first.dtype.kind == "f") if first.dtype != object
                else first.tolist() == other.tolist())
            if not same:
                raise InputError(f"variable {name!r} is stored {len(values)} times with different values "
                                 f"({', then '.join(_shown(v) for v in values)}; a concatenated save?): which one "
                                 "holds the file cannot tell (scipy keeps the last); expected each variable once",
                                 source=path)


def _load_v73(path: Path) -> tuple[dict, list[str]]:
    import h5py

    out, skipped = {}, []
    try:
        with h5py.File(path, "r") as f:
            for key in f:
                if key.startswith("#"):
                    continue  # '#refs#', '#subsystem#'
                _check_link(f, key, path)
                obj = f[key]
                if not isinstance(obj, h5py.Dataset):
                    skipped.append(key)  # a struct is a group
                    continue
                value = _v73_value(f, obj)
                if value is None:
                    skipped.append(key)
                else:
                    out[key] = value
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - h5py raises assorted errors on bad files
        text = str(exc).splitlines()[0][:120] if str(exc) else ""
        raise InputError(f"not a readable MATLAB v7.3 (HDF5) file ({exc.__class__.__name__}: {text}); truncated "
                         "or corrupted?", source=path) from None
    return out, skipped


def _check_link(f, key: str, path: Path, depth: int = 0, via: str = "") -> None:
    """Refuse a variable whose link leaves the file: an external link (to any file on the machine), or a soft
    link that ends at one or at nothing. h5py would follow them."""
    import h5py

    link = f.get(key, getlink=True)
    name = via or repr(key.lstrip("/"))
    if isinstance(link, h5py.ExternalLink):
        raise InputError(f"variable {name} is an external link to {link.filename!r}:{link.path}; refusing to follow "
                         "data out of the file", source=path)
    if isinstance(link, h5py.SoftLink):
        target = link.path if link.path.startswith("/") else "/" + link.path
        here = f"{name} (a soft link to {link.path!r})"
        if depth > 16 or f.get(target, getlink=True) is None:
            raise InputError(f"variable {here} points at nothing in the file; refusing to follow it", source=path)
        _check_link(f, target, path, depth + 1, via=here)


def _check_storage(ds, path: Path) -> None:
    """Refuse a dataset whose data are stored outside the file: external raw storage or a virtual dataset
    (whose sources may be any file)."""
    name = ds.name.lstrip("/")
    if ds.external:
        raise InputError(f"variable {name!r} keeps its data in the external file {ds.external[0][0]!r}; refusing "
                         "to read data from outside the file", source=path)
    if ds.is_virtual:
        files = sorted({str(v.file_name) for v in ds.virtual_sources()})
        raise InputError(f"variable {name!r} is a virtual dataset drawing on {', '.join(files[:3])}; refusing to read "
                         "data from outside the file", source=path)


def _attr(obj, name) -> str:
    v = obj.attrs.get(name)
    if v is None:
        return ""
    return v.decode() if isinstance(v, bytes) else str(v)


def _v73_value(f, ds):
    """A v7.3 variable in MATLAB's own dimension order: numbers, or a list of names; None if unsupported."""
    _check_storage(ds, Path(f.filename))
    cls = _attr(ds, "MATLAB_class")
    if ds.attrs.get("MATLAB_empty", 0):
        return np.zeros((0,))
    data = ds[()]
    if cls == "char":
        a = np.atleast_2d(np.asarray(data)).T  # (rows, characters)
        return ["".join(chr(c) for c in row if c).strip() for row in a]
    if cls == "cell":
        names = []
        for ref in np.asarray(data).T.ravel():
            item = f[ref]
            if _attr(item, "MATLAB_class") != "char":
                return None
            got = _v73_value(f, item)
            if len(got) != 1:
                return None
            names += got
        return names
    a = np.asarray(data)
    if a.dtype.kind not in "fiub" or a.dtype.names:  # complex is a compound (real, imag)
        return None
    return np.ascontiguousarray(a.T)  # C order, as the other readers give


# --------------------------------------------------------------------------- to a RigFile


def read_mat_channels(path: str | os.PathLike) -> RigFile:
    """Read a .mat file (v5 or v7.3) into a :class:`RigFile` (module docstring: the two layouts)."""
    path = existing_file(Path(path), "a MATLAB .mat file")
    if path.stat().st_size == 0:
        raise InputError("empty file", source=path)
    fmt = "matlab-7.3" if is_v73(path) else "matlab-5"
    variables, skipped = _load_v73(path) if fmt == "matlab-7.3" else _load_v5(path)
    if "acc" in skipped:
        raise InputError("variable 'acc' is not a real numeric array (a struct, cell, or complex?)", source=path)
    if skipped:
        warnings.warn(f"{path}: {len(skipped)} variable(s) that are not numeric arrays or text skipped: "
                      f"{', '.join(skipped[:4])}", stacklevel=2)
    if not variables:
        raise InputError("no numeric variables", source=path)
    rig = RigFile(source=str(path), format=fmt)
    if "acc" in variables:
        rig.arrays = _own_layout(variables, path)
        return rig
    for key, value in variables.items():
        if isinstance(value, list):
            continue  # text: no channel
        a = np.asarray(value)
        if a.size == 1:
            if key in SCALAR_KEYS:
                rig.props[key] = float(a.reshape(()))
            continue
        if a.ndim > 2 or (a.ndim == 2 and min(a.shape) != 1):
            raise InputError(f"variable {key!r} has shape {a.shape}; expected a vector (one channel) or ringfit's "
                             "'acc' layout", source=path)
        rig.channels.append(RawChannel(name=key, short=key, data=a.ravel()))
    if not rig.channels:
        raise InputError("no channel vectors and no 'acc' variable", source=path)
    return rig


def _own_layout(v: dict, path: Path) -> dict:
    out = {}
    for key in OWN_KEYS:
        if key not in v:
            continue
        value = v[key]
        if key in ("axes", "kind"):
            if not isinstance(value, list):
                raise InputError(f"variable {key!r} must be text (a char matrix or a cell array of names)", source=path)
            out[key] = value if key == "axes" else " ".join(value)
            continue
        if isinstance(value, list):
            raise InputError(f"variable {key!r} is text; expected numbers", source=path)
        a = np.asarray(value)
        if key in SCALAR_KEYS:
            if a.size != 1:
                raise InputError(f"variable {key!r} has shape {a.shape}; expected a scalar", source=path)
            out[key] = a.reshape(()).item()
        elif key in ("sensor_angle_deg", "encoder_angle_deg", "encoder_pulses", "hall"):
            if a.ndim > 2 or (a.ndim == 2 and min(a.shape) > 1):
                raise InputError(f"variable {key!r} has shape {a.shape}; expected a vector", source=path)
            out[key] = a.ravel()
        else:
            out[key] = a
    return out


# --------------------------------------------------------------------------- writing


def write_mat_records(records: Records, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``records`` as a MATLAB v5 .mat file with ringfit's keys (``acc``, ``axes``, …; SI units)."""
    import scipy.io

    path = check_output_path(path, overwrite=overwrite)
    payload = {"acc": records.acc, "axes": np.array(records.axes, dtype=object),
               "sensor_angle_deg": records.sensor_angle_deg, "fs_hz": np.float64(records.fs_hz)}
    if records.force is not None:
        payload["force"] = records.force

    def write(tmp: Path):
        with open(tmp, "wb") as fh:  # a handle keeps scipy from appending '.mat' to the temp name
            scipy.io.savemat(fh, payload, format="5", do_compression=False, oned_as="row")

    atomic_write(path, write)
    return path
