"""UFF58 files written by other software: vendored examples (tests/data/uff, MIT) and files from pyuff's writer.

Expected values come from outside ringfit's reader: pyuff's own parse of the
same file (times the unit's SI factor, g = 9.80665 m/s² by definition), the
angles the test placed its nodes at, and modes the test put into its FRFs.
"""

from pathlib import Path

import numpy as np
import pytest

from ringfit.errors import InputError
from ringfit.io.records import MeasuredFRF, Records, read_measurement, read_records

DATA = Path(__file__).parent / "data" / "uff"
G = 9.80665


def _pyuff_sets(path):
    import pyuff

    sets = pyuff.UFF(str(path)).read_sets()
    return [sets] if isinstance(sets, dict) else sets


# ----------------------------------------------------------------------------- vendored files


def test_binary_58b_in_g_read_and_scaled():
    path = DATA / "binary8byte.uff"
    rec = read_records(path, axes={0: "radial"}, angles={1: 0.0})
    raw = _pyuff_sets(path)[0]
    assert rec.acc.shape == (1, 1, 250) and rec.axes == ("radial",) and rec.fs_hz == pytest.approx(100.0)
    np.testing.assert_allclose(rec.acc[0, 0], G * np.asarray(raw["data"]), rtol=1e-15)
    spec = np.abs(np.fft.rfft(rec.acc[0, 0]))
    assert np.fft.rfftfreq(250, 1 / rec.fs_hz)[np.argmax(spec)] == pytest.approx(5.0, abs=0.4)  # "sine 5 Hz", 0.4 Hz bins


def test_catman_time_history_general_type_with_acceleration_unit():
    path = DATA / "time-history-not-all-columns-filled.uff"
    rec = read_records(path, axes={0: "tangential"}, angles={0: 90.0})
    raw = _pyuff_sets(path)[0]
    assert rec.axes == ("tangential",) and rec.sensor_angle_deg.tolist() == [90.0]
    assert rec.fs_hz == pytest.approx(20000.0)
    np.testing.assert_array_equal(rec.acc[0, 0], np.asarray(raw["data"], dtype=float))


def test_frf_with_non_utf8_unit_read_as_accelerance():
    path = DATA / "non_ascii_header.uff"
    m = read_measurement(path, axes={0: "radial"}, angles={0: 0.0})
    raw = _pyuff_sets(path)[0]
    assert isinstance(m, MeasuredFRF) and m.frf.shape == (1, 1, 6)
    np.testing.assert_allclose(m.freq_hz, 0.195313 * np.arange(6))
    np.testing.assert_array_equal(m.frf[0, 0], np.asarray(raw["data"]))
    with pytest.raises(InputError, match="FRFs"):
        read_records(path, axes={0: "radial"}, angles={0: 0.0})  # SSI needs time records


@pytest.mark.parametrize("kw, match", [
    ({}, r"direction 0 .*--axes 0=radial"),
    ({"axes": {0: "radial"}}, r"node 1 has no sensor angle; give --angles 1=DEG"),
])
def test_foreign_file_says_what_it_needs(kw, match):
    with pytest.raises(InputError, match=match) as e:
        read_records(DATA / "binary8byte.uff", **kw)
    assert "binary8byte.uff" in str(e.value) and "\n" not in str(e.value)


def test_truncated_microphone_file_refused():
    with pytest.raises(InputError, match="announces 2508876 points but holds 42"):
        read_records(DATA / "dataset_milestone_in_header.uff")


# ----------------------------------------------------------------------------- files from pyuff's writer

RADIUS = 0.3
NODES = np.arange(1, 17)
NODE_DEG = (NODES - 1) * 22.5 + 10.0  # on a circle in the x-z plane (axle along y)
HAMMER_NODE, HAMMER_DEG = 100, 10.0


def _wrap(deg):
    return (np.asarray(deg) + 180.0) % 360.0 - 180.0


def _geometry(kind=15):
    import pyuff

    nodes = list(NODES) + [HAMMER_NODE]
    deg = np.radians(list(NODE_DEG) + [HAMMER_DEG])
    # about the y axis, angles run z -> x: x = R sin, z = R cos
    prep = pyuff.prepare_15 if kind == 15 else pyuff.prepare_2411
    return prep(node_nums=nodes, def_cs=[0] * len(nodes), disp_cs=[0] * len(nodes), color=[1] * len(nodes),
                x=list(RADIUS * np.sin(deg)), y=[0.05] * len(nodes), z=list(RADIUS * np.cos(deg)))


def _dataset(node, direction, data, *, func_type, inc, ordinate, units, denom=0, ref=HAMMER_NODE, binary=0):
    import pyuff

    return pyuff.prepare_58(
        binary=binary, id1="test system export", id2="", id3="", id4="", id5="", func_type=func_type, ver_num=0,
        load_case_id=0, rsp_ent_name="tyre", rsp_node=int(node), rsp_dir=int(direction), ref_ent_name="hammer",
        ref_node=ref, ref_dir=3, abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=inc, z_axis_value=0.0,
        abscissa_spec_data_type=17 if func_type == 1 else 18, abscissa_len_unit_exp=0, abscissa_force_unit_exp=0,
        abscissa_temp_unit_exp=0, abscissa_axis_units_lab="s" if func_type == 1 else "Hz",
        ordinate_spec_data_type=ordinate, ordinate_len_unit_exp=0, ordinate_force_unit_exp=0,
        ordinate_temp_unit_exp=0, ordinate_axis_units_lab=units, orddenom_spec_data_type=denom,
        orddenom_len_unit_exp=0, orddenom_force_unit_exp=0, orddenom_temp_unit_exp=0,
        orddenom_axis_units_lab="N" if denom else "", z_axis_spec_data_type=0, z_axis_len_unit_exp=0,
        z_axis_force_unit_exp=0, z_axis_temp_unit_exp=0, z_axis_axis_units_lab="", data=data,
        x=np.arange(len(data)) * inc,
    )


def _write(path, sets):
    import pyuff

    pyuff.UFF(str(path)).write_sets(sets, mode="add")
    return path


#: modes put into the measured FRFs: (n, frequency Hz, damping ratio)
MODES = ((2, 118.0, 0.02), (3, 139.0, 0.02), (4, 164.0, 0.02), (5, 192.0, 0.02))


def _accelerance(theta, f):
    """Ring FRF at sensor angles theta [rad] (from the hammer), accelerance [m/s²/N]: modal sum, radial only."""
    w = 2 * np.pi * f
    h = np.zeros((theta.size, f.size), complex)
    for n, fn, z in MODES:
        wn = 2 * np.pi * fn
        h += np.cos(n * theta)[:, None] * (-(w**2)) / (2.0 * (wn**2 - w**2 + 2j * z * wn * w))
    return h


def test_measured_frfs_from_other_software_give_the_modes(tmp_path, capsys):
    from ringfit.cli import main

    f = np.arange(0, 2049) * 0.125  # 0-256 Hz
    theta = np.radians(NODE_DEG - HAMMER_DEG)
    h = _accelerance(theta, f)
    # the export writes the radial axis as direction -3 (sign flipped) and in g/N
    sets = [_geometry(2411)]
    sets += [_dataset(n, -3, -h[i] / G, func_type=4, inc=0.125, ordinate=12, units="g/N", denom=13)
             for i, n in enumerate(NODES)]
    sets += [_dataset(n, -3, np.full(f.size, 0.99 + 0j), func_type=6, inc=0.125, ordinate=0, units="")
             for n in NODES]
    path = _write(tmp_path / "export.uff", sets)
    m = read_measurement(path)
    assert isinstance(m, MeasuredFRF) and m.axes == ("radial",)
    np.testing.assert_allclose(m.sensor_angle_deg, _wrap(NODE_DEG - HAMMER_DEG), atol=1e-3)
    np.testing.assert_allclose(m.frf[:, 0], h, rtol=1e-5, atol=1e-9)  # g/N -> m/s²/N, sign of -3 undone
    assert m.coherence is not None and np.allclose(m.coherence, 0.99)
    out = tmp_path / "measured.modes.csv"
    assert main(["frf", str(path), "--out", str(out), "--band", "90:240"]) == 0
    from ringfit.io.modes import read_mode_table

    t = read_mode_table(out)
    for n, fn, z in MODES:
        rows = np.flatnonzero(t.n == n)
        assert rows.size == 1, (n, t.n, t.freq_hz)
        assert abs(t.freq_hz[rows[0]] - fn) < 0.005 * fn
        assert abs(t.damping_pct[rows[0]] / 100 - z) < 0.3 * z
    assert "measured FRFs" in t.condition["method"]


def _time_sets(binary=1, repeats=2, with_force=True, fs=2048.0, samples=512, units="g", ordinate=12):
    rng = np.random.default_rng(3)
    sets, truth, forces = [], [], []
    for take in range(repeats):
        for i, n in enumerate(NODES[:6]):
            for direction in (3, 1):
                x = rng.standard_normal(samples)
                truth.append((n, take, direction, x))
                sets.append(_dataset(n, direction, x, func_type=1, inc=1 / fs, ordinate=ordinate, units=units,
                                     binary=binary))
            if with_force:
                fz = rng.standard_normal(samples)
                forces.append(fz)
                sets.append(_dataset(HAMMER_NODE, 3, fz, func_type=1, inc=1 / fs, ordinate=13, units="N",
                                     binary=binary))
    return sets, truth, forces


@pytest.mark.parametrize("binary", [0, 1])
def test_time_records_repeated_impacts_kept_and_paired(tmp_path, binary):
    sets, truth, forces = _time_sets(binary=binary)
    path = _write(tmp_path / "impacts.unv", [_geometry(15)] + sets)
    rec = read_records(path)
    assert isinstance(rec, Records) and rec.axes == ("radial", "tangential")
    assert rec.n_records == 12  # 6 nodes x 2 takes: a repeated node/direction is a new record, never dropped
    np.testing.assert_allclose(rec.sensor_angle_deg, np.tile(NODE_DEG[:6] - HAMMER_DEG, 2), atol=1e-3)
    for k, (n, take, direction, x) in enumerate(truth):
        r = take * 6 + list(NODES).index(n)
        a = 0 if direction == 3 else 1
        np.testing.assert_allclose(rec.acc[r, a], G * x, rtol=1e-6 if not binary else 1e-15)
    np.testing.assert_allclose(rec.force, np.stack(forces), rtol=1e-6 if not binary else 1e-15)
    assert rec.fs_hz == pytest.approx(2048.0, rel=1e-6)


@pytest.mark.parametrize("ordinate, units, match", [
    (15, "Pa", "ordinate is pressure"),
    (1, "Pa", "a pressure"),
    (11, "m/s", "velocity"),
    (1, "V", "unit 'V'"),
])
def test_units_that_are_not_acceleration_refused(tmp_path, ordinate, units, match):
    sets, _, _ = _time_sets(repeats=1, with_force=False, ordinate=ordinate, units=units)
    path = _write(tmp_path / "mic.uff", [_geometry(15)] + sets)
    with pytest.raises(InputError, match=match) as e:
        read_records(path)
    assert "mic.uff" in str(e.value) and "\n" not in str(e.value)


@pytest.mark.parametrize("binary", [0, 1])
@pytest.mark.parametrize("keep", [0.3, 0.6, 0.97])
def test_truncated_file_refused(tmp_path, binary, keep):
    sets, _, _ = _time_sets(binary=binary, repeats=1)
    full = _write(tmp_path / "full.uff", [_geometry(15)] + sets)
    data = full.read_bytes()
    cut = tmp_path / "cut.uff"
    cut.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(InputError, match="cut.uff") as e:
        read_records(cut)
    assert "\n" not in str(e.value)


def test_mixed_function_types_and_unpaired_forces_refused(tmp_path):
    sets, _, _ = _time_sets(repeats=1, with_force=False)
    frf = _dataset(1, 3, np.ones(64, complex), func_type=4, inc=1.0, ordinate=12, units="m/s^2/N", denom=13)
    path = _write(tmp_path / "mixed.uff", [_geometry(15)] + sets + [frf])
    with pytest.raises(InputError, match="mixes time responses"):
        read_records(path)
    sets, _, forces = _time_sets(repeats=1)
    path = _write(tmp_path / "extra_force.uff", [_geometry(15)] + sets + [sets[2]])
    with pytest.raises(InputError, match="force datasets for 6 records"):
        read_records(path)


def test_ssi_cli_on_a_foreign_uff_with_angles_map(tmp_path, capsys):
    """The catman-style single channel file: --axes and --angles make it readable; too short for SSI, said so."""
    from ringfit.cli import main

    out = tmp_path / "m.modes.csv"
    status = main(["ssi", str(DATA / "time-history-not-all-columns-filled.uff"), "--out", str(out),
                   "--axes", "0=radial", "--angles", "0=0"])
    err = capsys.readouterr().err.strip()
    assert status == 2 and len(err.splitlines()) == 1 and "13 samples" in err and not out.exists()
