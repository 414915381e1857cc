"""Records I/O: npz and UFF58 round trips, clear errors (docs/formats.md §4)."""

import numpy as np
import pytest

from ringfit.errors import InputError
from ringfit.io.records import Records, read_records, write_records


def _records(force=True):
    rng = np.random.default_rng(0)
    return Records(acc=rng.standard_normal((3, 2, 64)), axes=("radial", "tangential"),
                   sensor_angle_deg=np.array([0.0, 15.5, -30.25]), fs_hz=48000.0,
                   force=rng.standard_normal((3, 64)) if force else None)


@pytest.mark.parametrize("name", ["a.records.npz", "a.uff", "a.unv"])
@pytest.mark.parametrize("force", [True, False])
def test_round_trip(tmp_path, name, force):
    rec = _records(force)
    back = read_records(write_records(rec, tmp_path / name))
    assert np.array_equal(back.acc, rec.acc)
    assert back.axes == rec.axes
    assert np.array_equal(back.sensor_angle_deg, rec.sensor_angle_deg)
    assert back.fs_hz == rec.fs_hz
    assert (back.force is None) == (not force)
    if force:
        assert np.array_equal(back.force, rec.force)


def test_refuses_overwrite(tmp_path):
    p = write_records(_records(), tmp_path / "a.records.npz")
    with pytest.raises(InputError, match="exists"):
        write_records(_records(), p)
    write_records(_records(), p, overwrite=True)


def _save(path, **kw):
    base = dict(acc=np.zeros((2, 1, 10)), axes=np.array(["radial"]), sensor_angle_deg=np.zeros(2), fs_hz=1000.0)
    base.update(kw)
    np.savez(path, **{k: v for k, v in base.items() if v is not None})
    return path


@pytest.mark.parametrize("kw, match", [
    (dict(acc=np.zeros((2, 10))), "'acc' has shape"),
    (dict(acc=np.full((2, 1, 10), np.nan)), "non-finite value at record 0, axis 0, sample 0"),
    (dict(axes=np.array(["vertical"])), "'axes': 'vertical'"),
    (dict(axes=np.array(["radial", "tangential"])), "2 names but 'acc' has 1 axes"),
    (dict(sensor_angle_deg=np.zeros(3)), "'sensor_angle_deg' has shape"),
    (dict(fs_hz=-1.0), "'fs_hz' = -1.0"),
    (dict(force=np.zeros((2, 9))), "'force' has shape"),
    (dict(force=np.array([[0.0] * 9 + [np.inf]] * 2)), "'force' has a non-finite value at record 0, sample 9"),
    (dict(fs_hz=None), "missing key 'fs_hz'"),
])
def test_bad_npz(tmp_path, kw, match):
    p = _save(tmp_path / "bad.records.npz", **kw)
    with pytest.raises(InputError, match=match) as exc:
        read_records(p)
    assert "bad.records.npz" in str(exc.value) and "\n" not in str(exc.value)


def test_missing_and_unreadable(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_records(tmp_path / "none.records.npz")
    (tmp_path / "junk.records.npz").write_text("not a zip")
    with pytest.raises(InputError, match="not a readable .npz"):
        read_records(tmp_path / "junk.records.npz")
    (tmp_path / "junk.uff").write_text("    -1\n   999\nnothing\n    -1\n")
    with pytest.raises(InputError, match="junk.uff"):
        read_records(tmp_path / "junk.uff")


def test_uff_foreign_angles_from_node_coordinates(tmp_path):
    """A UFF file without ringfit's ID line takes the angle from type-15 node coordinates."""
    import pyuff

    rec = _records(force=False)
    p = write_records(rec, tmp_path / "a.uff")
    sets = pyuff.UFF(str(p)).read_sets()
    for s in sets:
        s["id4"] = "no angle here"
    angles = np.deg2rad(rec.sensor_angle_deg)
    nodes = pyuff.prepare_15(node_nums=[1, 2, 3], def_cs=[0] * 3, disp_cs=[0] * 3, color=[1] * 3,
                             x=list(0.3 * np.cos(angles)), y=list(0.3 * np.sin(angles)), z=[0.0] * 3)
    q = tmp_path / "foreign.uff"
    pyuff.UFF(str(q)).write_sets([nodes] + sets, mode="add")
    back = read_records(q)
    assert np.allclose(back.sensor_angle_deg, rec.sensor_angle_deg, atol=1e-4)
    assert np.array_equal(back.acc, rec.acc)
