"""Rig files that contradict themselves or reach out of themselves (issue 34): a MATLAB v5 variable stored
twice, a truncated TDMS file whose reader logs to stderr, a header-only CSV, angles out of range."""

import io
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from ringfit.errors import InputError
from ringfit.io.channel_map import parse_channel_map
from ringfit.io.csv_records import read_csv_channels
from ringfit.io.matlab import read_mat_channels
from ringfit.io.records import Records, write_records

ROOT = Path(__file__).resolve().parents[1]


def _records(n=4, s=256):
    rng = np.random.default_rng(0)
    return Records(acc=rng.standard_normal((n, 1, s)), axes=("radial",), sensor_angle_deg=np.arange(n) * 90.0,
                   fs_hz=6400.0, force=rng.standard_normal((n, s)))


def _concatenated(path, extra):
    """A v5 file of the records and, appended as a second save would, the variables ``extra``."""
    write_records(_records(), path)
    buf = io.BytesIO()
    scipy.io.savemat(buf, extra, format="5")
    path.write_bytes(path.read_bytes() + buf.getvalue()[128:])


def test_mat_variable_stored_twice_with_other_values_refused(tmp_path):
    p = tmp_path / "twice.mat"
    _concatenated(p, {"fs_hz": np.float64(6000.0)})
    with pytest.raises(InputError) as e:
        read_mat_channels(p)
    line = str(e.value)
    assert "twice.mat" in line and "'fs_hz'" in line and "6400, then 6000" in line


def test_mat_variable_stored_twice_alike_is_read(tmp_path):
    p = tmp_path / "same.mat"
    _concatenated(p, {"fs_hz": np.float64(6400.0)})
    assert read_mat_channels(p).arrays["fs_hz"] == 6400.0


def test_mat_array_stored_twice_refused(tmp_path):
    p = tmp_path / "acc.mat"
    _concatenated(p, {"sensor_angle_deg": np.arange(4) * 45.0})
    with pytest.raises(InputError, match="'sensor_angle_deg' is stored 2 times"):
        read_mat_channels(p)


def test_truncated_tdms_one_stderr_line(tmp_path):
    """npTDMS logs through its own stderr handlers: a real process must print our one line only."""
    p = tmp_path / "rec.tdms"
    write_records(_records(), p)
    p.write_bytes(p.read_bytes()[:100])
    env = {**os.environ, "PYTHONPATH": str(ROOT), "JAX_PLATFORMS": "cpu"}
    run = subprocess.run([sys.executable, "-m", "ringfit", "ssi", str(p), "--out", str(tmp_path / "o.modes.csv")],
                         capture_output=True, text=True, env=env, timeout=120)
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert run.returncode == 2 and len(lines) == 1 and "truncated" in lines[0] and "rec.tdms" in lines[0], run.stderr


def test_nptdms_handlers_put_back(tmp_path):
    import logging

    from ringfit.io.tdms import read_tdms_channels

    import nptdms  # noqa: F401  (its module loggers exist once imported)

    names = [n for n in logging.root.manager.loggerDict if n.startswith("nptdms.")]
    before = {n: list(logging.getLogger(n).handlers) for n in names}
    p = tmp_path / "rec.tdms"
    write_records(_records(), p)
    p.write_bytes(p.read_bytes()[:100])
    with pytest.raises(InputError, match="truncated"):
        read_tdms_channels(p)
    assert {n: list(logging.getLogger(n).handlers) for n in names} == before


def test_csv_header_without_rows(tmp_path):
    p = tmp_path / "h.csv"
    p.write_text("# a comment\ntime [s],radial [g]\n\n")
    with pytest.raises(InputError, match="row 2 is a header and no data rows follow"):
        read_csv_channels(p)


@pytest.mark.parametrize("value", [1e300, -400.0, 721.0])
def test_channel_map_angle_out_of_range(value):
    doc = {"channels": {"a": {"axis": "radial", "unit": "g", "angle_deg": value}}}
    with pytest.raises(InputError, match=r"channels.'a'.angle_deg"):
        parse_channel_map(doc, source="m.toml")


@pytest.mark.parametrize("value", [1e-300, 1e300, -1e-12])
def test_channel_map_sensitivity_out_of_range(value):
    doc = {"channels": {"a": {"axis": "radial", "unit": "g", "angle_deg": 0.0, "sensitivity": value}}}
    with pytest.raises(InputError, match=r"channels.'a'.sensitivity"):
        parse_channel_map(doc, source="m.toml")


def test_channel_map_negative_sensitivity_and_angles_at_the_ends_accepted():
    doc = {"channels": {"a": {"axis": "radial", "unit": "g", "angle_deg": 720.0, "sensitivity": -0.1},
                        "b": {"axis": "radial", "unit": "g", "angle_deg": -360.0}}}
    m = parse_channel_map(doc, source="m.toml")
    assert m.channels["a"].sensitivity == -0.1 and m.channels["b"].angle_deg == -360.0


def test_records_angle_out_of_range():
    r = _records()
    with pytest.raises(InputError, match="sensor_angle_deg' = 1e\\+300 at record 0"):
        Records(acc=r.acc, axes=r.axes, sensor_angle_deg=np.array([1e300, 0.0, 90.0, 180.0]), fs_hz=r.fs_hz)


def _csv_with_rows(path, t, cols, names):
    lines = ["time [s]," + ",".join(f"{n} [m/s^2]" for n in names)]
    lines += [f"{float(a)!r}," + ",".join(f"{float(c[i])!r}" for c in cols) for i, a in enumerate(t)]
    path.write_text("\n".join(lines) + "\n")


def test_csv_dropped_rows_filled_on_the_time_grid_and_said(tmp_path):
    from ringfit.io.rig import read_rig_records
    from ringfit.io.channel_map import ChannelMap, ChannelSpec

    fs, n = 1000.0, 400
    full_t = np.arange(n) / fs
    x = np.sin(2 * np.pi * 37 * full_t)
    y = np.cos(2 * np.pi * 53 * full_t)
    drop = [100, 101, 250]  # rows lost: two in a row, then one
    keep = np.setdiff1d(np.arange(n), drop)
    _csv_with_rows(tmp_path / "d.csv", full_t[keep], [x[keep], y[keep]], ["a", "b"])
    cmap = ChannelMap(channels={"a": ChannelSpec("a", "acc", axis="radial", angle_deg=0.0, unit="m/s^2"),
                                "b": ChannelSpec("b", "acc", axis="radial", angle_deg=90.0, unit="m/s^2")})
    rec = read_rig_records(tmp_path / "d.csv", cmap)
    assert rec.fs_hz == pytest.approx(fs) and rec.n_samples == n
    got = rec.acc[0, 0]
    np.testing.assert_array_equal(got[keep], x[keep])
    # the lost samples lie on the straight line between their neighbours (by hand)
    assert got[100] == pytest.approx(x[99] + (x[102] - x[99]) / 3)
    assert got[101] == pytest.approx(x[99] + 2 * (x[102] - x[99]) / 3)
    assert got[250] == pytest.approx(0.5 * (x[249] + x[251]))
    assert any("dropped samples" in s and "3 samples missing" in s for s in rec.notes)


def test_csv_too_many_dropped_rows_refused(tmp_path):
    from ringfit.io.csv_records import read_csv_channels

    t = np.arange(400) / 1000.0
    keep = np.setdiff1d(np.arange(400), np.arange(100, 120))  # 20 in a row
    _csv_with_rows(tmp_path / "d.csv", t[keep], [np.sin(t[keep])], ["a"])
    with pytest.raises(InputError, match="20 samples dropped in 1 gap"):
        read_csv_channels(tmp_path / "d.csv")
