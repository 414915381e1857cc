"""Rig files (issue 23 item 1; docs/formats.md §17): TDMS, MATLAB v5 / v7.3 and CSV written by their own
libraries' writers (npTDMS, scipy.io.savemat, h5py with MATLAB's header and attributes, numpy text), read
back into the same records as the npz, and `ringfit ssi` / `ringfit profile` giving the same tables as on
the npz; bad files and channel maps end in one line, exit 2, nothing written."""

import csv

import h5py
import numpy as np
import pytest
import scipy.io
from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

from ringfit.cli import main
from ringfit.errors import InputError
from ringfit.io.continuous import read_continuous, write_continuous
from ringfit.io.records import read_records, write_records
from ringfit.synth.records import impact_records, ring_modes

G = 9.80665  # m/s² per g: the expected conversion, independent of the code's table
LBF = 4.4482216152605  # N per lbf
FS = 6400.0
SSI_OPTS = ["--delay", "0.0004", "--band", "60:400", "--orders", "2:40:2", "--block-rows", "20", "--no-jackknife",
            "--workers", "1", "--quiet"]


@pytest.fixture(scope="module")
def rec():
    from ringfit.params import table9

    geometry, ring = table9()
    modes = ring_modes(ring, geometry, n_values=range(1, 6), seed=3)
    return impact_records(modes, np.arange(12) * 30.0, ring=ring, geometry=geometry, fs_hz=FS, duration_s=0.25,
                          sensor_delay_s=0.4e-3, noise=0.01, seed=4)


@pytest.fixture(scope="module")
def npz_table(rec, tmp_path_factory):
    d = tmp_path_factory.mktemp("npz")
    path = write_records(rec, d / "r.records.npz")
    out = d / "npz.modes.csv"
    assert main(["ssi", str(path), "--out", str(out), *SSI_OPTS]) == 0
    return _table(out)


def _table(path):
    with open(path) as fh:
        rows = [r for r in csv.reader(line for line in fh if not line.startswith("#"))]
    return rows[0], rows[1:]


def _same_table(a, b, rtol=1e-7):
    (ha, ra), (hb, rb) = a, b
    assert ha == hb and len(ra) == len(rb) and len(ra) >= 4
    for x, y in zip(ra, rb):
        for u, v in zip(x, y):
            try:
                fu, fv = float(u), float(v)
            except ValueError:
                assert u == v
                continue
            assert fu == pytest.approx(fv, rel=rtol, abs=1e-9)


def _map(path, text):
    path.write_text(text)
    return path


# ----------------------------------------------------------------------------- the writers of each library


def _labview_tdms(rec, path, *, unit="g", sensitivity=0.1):
    """A LabVIEW-style file: one group 'Impacts', channels 'Acc R 01', 'Acc T 01', 'Hammer 01' in volts."""
    dt = 1.0 / rec.fs_hz
    objs = [RootObject(properties={"operator": "bench 3"}), GroupObject("Impacts")]
    scale = G if unit == "g" else 1.0
    for r in range(rec.n_records):
        for a, short in zip(range(len(rec.axes)), ("R", "T")):
            objs.append(ChannelObject("Impacts", f"Acc {short} {r:02d}", rec.acc[r, a] / scale * sensitivity,
                                      properties={"wf_increment": dt, "unit_string": "V"}))
        objs.append(ChannelObject("Impacts", f"Hammer {r:02d}", rec.force[r] / LBF * 0.01,
                                  properties={"wf_increment": dt, "unit_string": "V"}))
    objs.append(ChannelObject("Impacts", "Stamp", np.array(["a", "b"]), properties={}))
    with TdmsWriter(str(path)) as w:
        w.write_segment(objs)
    lines = []
    for r in range(rec.n_records):
        angle = float(rec.sensor_angle_deg[r])
        for a, short in zip(rec.axes, ("R", "T")):
            lines.append(f'[channels."Acc {short} {r:02d}"]\naxis = "{a}"\nangle_deg = {angle!r}\n'
                         f'unit = "{unit}"\nsensitivity = {sensitivity!r}\n')
        lines.append(f'[channels."Impacts/Hammer {r:02d}"]\nrole = "force"\nangle_deg = {angle!r}\n'
                     f'unit = "lbf"\nsensitivity = 0.01\n')
    return "\n".join(lines)


def _mat73(path, variables):
    """A MATLAB v7.3 file as MATLAB writes it: a 512-byte text header, HDF5, column-major, MATLAB_class."""
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Thu Nov 26 2026 HDF5 schema 1.00 ."
    with h5py.File(path, "w", userblock_size=512) as f:
        for key, value in variables.items():
            if isinstance(value, list):  # a char matrix, rows padded with blanks
                width = max(map(len, value))
                codes = np.array([[ord(c) for c in s.ljust(width)] for s in value], dtype=np.uint16)
                ds = f.create_dataset(key, data=codes.T)
                ds.attrs["MATLAB_class"] = np.bytes_("char")
                ds.attrs["MATLAB_int_decode"] = np.int32(2)
            else:
                a = np.asarray(value, dtype=np.float64)
                a = a.reshape(1, -1) if a.ndim == 1 else (a.reshape(1, 1) if a.ndim == 0 else a)
                ds = f.create_dataset(key, data=a.T)  # MATLAB stores column-major: dimensions reversed
                ds.attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as fh:
        fh.write(header.ljust(116) + b"\x00" * 8 + b"\x00\x02IM")


# ----------------------------------------------------------------------------- impact records: same records


def _check_same_records(back, rec, rtol=1e-12):
    assert back.axes == rec.axes and back.acc.shape == rec.acc.shape
    np.testing.assert_allclose(back.acc, rec.acc, rtol=rtol, atol=1e-12 * np.abs(rec.acc).max())
    np.testing.assert_allclose(back.force, rec.force, rtol=rtol, atol=1e-12 * np.abs(rec.force).max())
    np.testing.assert_allclose(back.sensor_angle_deg, rec.sensor_angle_deg)
    assert back.fs_hz == pytest.approx(rec.fs_hz, rel=1e-12)


def test_tdms_labview_style_with_channel_map(rec, tmp_path, npz_table, capsys):
    path = tmp_path / "bench.tdms"
    cmap = _map(tmp_path / "bench.toml", _labview_tdms(rec, path))
    with pytest.warns(UserWarning, match="non-numeric"):
        back = read_records(path, channels=cmap)
    _check_same_records(back, rec)
    out = tmp_path / "tdms.modes.csv"
    assert main(["ssi", str(path), "--channels", str(cmap), "--out", str(out), *SSI_OPTS]) == 0
    _same_table(_table(out), npz_table)
    assert "WARNING:" in capsys.readouterr().err  # the skipped timestamp channel is said


def test_tdms_written_by_ringfit_needs_no_map(rec, tmp_path, npz_table):
    path = write_records(rec, tmp_path / "r.tdms")
    _check_same_records(read_records(path), rec, rtol=0)
    out = tmp_path / "t.modes.csv"
    assert main(["ssi", str(path), "--out", str(out), *SSI_OPTS]) == 0
    assert _table(out) == npz_table  # bit for bit
    # frf reads it through the same dispatcher
    frf = {}
    for name, p in (("npz", write_records(rec, tmp_path / "r.records.npz")), ("tdms", path)):
        frf[name] = tmp_path / f"{name}.frf.modes.csv"
        assert main(["frf", str(p), "--out", str(frf[name]), "--delay", "0.0004", "--band", "60:400"]) == 0
    assert _table(frf["tdms"]) == _table(frf["npz"])


def test_mat_v5_own_keys_and_channel_vectors(rec, tmp_path, npz_table):
    own = tmp_path / "own.mat"
    scipy.io.savemat(own, {"acc": rec.acc, "axes": np.array(rec.axes, dtype=object),
                           "sensor_angle_deg": rec.sensor_angle_deg, "fs_hz": rec.fs_hz, "force": rec.force})
    _check_same_records(read_records(own), rec, rtol=0)
    # channel vectors in mm/s² and kN, one variable each, fs_hz a scalar variable
    chans = {"fs_hz": rec.fs_hz}
    text = []
    for r in range(rec.n_records):
        for a, axis in enumerate(rec.axes):
            chans[f"a{r}_{axis[0]}"] = rec.acc[r, a] * 1e3
            text.append(f'[channels.a{r}_{axis[0]}]\naxis = "{axis}"\nangle_deg = {float(rec.sensor_angle_deg[r])!r}\n'
                        f'unit = "mm/s^2"\nrecord = {r}\n')
        chans[f"f{r}"] = rec.force[r] / 1e3
        text.append(f'[channels.f{r}]\nrole = "force"\nunit = "kN"\nrecord = {r}\n')
    vec = tmp_path / "vec.mat"
    scipy.io.savemat(vec, chans)
    cmap = _map(tmp_path / "vec.toml", "\n".join(text))
    _check_same_records(read_records(vec, channels=cmap), rec)
    out = tmp_path / "m.modes.csv"
    assert main(["ssi", str(vec), "--channels", str(cmap), "--out", str(out), *SSI_OPTS]) == 0
    _same_table(_table(out), npz_table)


def test_mat_v73_hdf5(rec, tmp_path, npz_table):
    path = tmp_path / "r73.mat"
    _mat73(path, {"acc": rec.acc, "axes": list(rec.axes), "sensor_angle_deg": rec.sensor_angle_deg,
                  "fs_hz": rec.fs_hz, "force": rec.force})
    with open(path, "rb") as fh:
        assert fh.read(19) == b"MATLAB 7.3 MAT-file"
    with pytest.raises(NotImplementedError):  # scipy refuses it: the h5py path is the one that reads it
        scipy.io.loadmat(path)
    _check_same_records(read_records(path), rec, rtol=0)
    out = tmp_path / "h.modes.csv"
    assert main(["ssi", str(path), "--out", str(out), *SSI_OPTS]) == 0
    assert _table(out) == npz_table


def test_csv_with_header_units_and_map(rec, tmp_path, npz_table):
    path = tmp_path / "r.csv"
    cols, header, text = [np.arange(rec.n_samples) / rec.fs_hz * 1e3], ["time [ms]"], ["fs_hz = 6400.0\n"]
    for r in range(rec.n_records):
        for a, axis in enumerate(rec.axes):
            cols.append(rec.acc[r, a] / G)
            header.append(f"s{r} {axis} [g]")
            text.append(f'[channels."s{r} {axis}"]\naxis = "{axis}"\nangle_deg = {float(rec.sensor_angle_deg[r])!r}\n'
                        'unit = "g"\n')
        cols.append(rec.force[r])
        header.append(f"hammer {r} (N)")
        text.append(f'[channels."hammer {r}"]\nrole = "force"\nangle_deg = {float(rec.sensor_angle_deg[r])!r}\n'
                    'unit = "N"\n')
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(header), comments="", fmt="%.17g")
    cmap = _map(tmp_path / "r.toml", "\n".join(text))
    _check_same_records(read_records(path, channels=cmap), rec)
    out = tmp_path / "c.modes.csv"
    assert main(["ssi", str(path), "--channels", str(cmap), "--out", str(out), *SSI_OPTS]) == 0
    _same_table(_table(out), npz_table)
    # without fs_hz in the map the time column (in ms) gives the rate
    cmap2 = _map(tmp_path / "r2.toml", "\n".join(text[1:]))
    assert read_records(path, channels=cmap2).fs_hz == pytest.approx(FS, rel=1e-12)


@pytest.mark.parametrize("fmt", ["tdms", "mat", "csv"])
def test_example_records_in_each_format(fmt, tmp_path):
    out = tmp_path / "ex"
    assert main(["example", "records", "--out", str(out), "--format", fmt, "--quiet"]) == 0
    ref = read_records(out / "impact.records.npz")
    cmap = out / "impact.channels.toml" if fmt == "csv" else None
    assert (cmap is not None) == (out / "impact.channels.toml").exists()
    back = read_records(out / f"impact.{fmt}", channels=cmap)
    _check_same_records(back, ref, rtol=0)
    assert f"impact.{fmt}" in (out / "README.md").read_text()


# ----------------------------------------------------------------------------- continuous recordings


@pytest.fixture(scope="module")
def drum(tmp_path_factory):
    from ringfit.synth.cleat import CleatBench

    bench = CleatBench(steady="analytic", fs_hz=FS, encoder="angle")
    rec = bench.record(3.0)
    d = tmp_path_factory.mktemp("drum")
    write_continuous(rec, d / "d.records.npz")
    return rec, d


def test_profile_from_tdms_and_csv_equals_npz(drum, tmp_path):
    rec, d = drum
    acc = [rec.read(f"acc:{a}") for a in rec.axes]
    enc, hall = rec.read("encoder_angle_deg"), rec.read("hall")
    tdms = tmp_path / "drum.tdms"
    inc = {"wf_increment": 1.0 / FS}
    with TdmsWriter(str(tdms)) as w:
        w.write_segment([RootObject(properties={"speed_kmh": rec.condition.get("speed_kmh", 0.0)}), GroupObject("Drum")]
                        + [ChannelObject("Drum", f"ch{k}", x / G, properties={**inc, "unit_string": "g"})
                           for k, x in enumerate(acc)]
                        + [ChannelObject("Drum", "rim", np.deg2rad(enc), properties=inc),
                           ChannelObject("Drum", "hall", hall, properties=inc)])
    lines = [f'[channels.ch{k}]\naxis = "{a}"\nunit = "g"\n' for k, a in enumerate(rec.axes)]
    lines += ['[channels.rim]\nrole = "encoder"\nunit = "rad"\n', '[channels.hall]\nrole = "trigger"\n']
    cond = "".join(f"{k} = {float(v)!r}\n" for k, v in rec.condition.items())
    cmap = _map(tmp_path / "drum.toml", f"encoder_offset_deg = {float(rec.encoder_offset_deg)!r}\n"
                f"hall_delay_s = {float(rec.hall_delay_s)!r}\n[condition]\n{cond}\n" + "\n".join(lines))
    back = read_continuous(tdms, channels=cmap)
    np.testing.assert_allclose(back.read("acc:radial"), rec.read("acc:radial"), rtol=1e-13, atol=1e-9)
    np.testing.assert_allclose(back.read("encoder_angle_deg"), enc, rtol=1e-13, atol=1e-9)
    assert back.condition == rec.condition
    csvp = tmp_path / "drum.csv"
    np.savetxt(csvp, np.column_stack([np.arange(enc.size) / FS, *acc, enc, hall]), delimiter=",", fmt="%.17g",
               header=",".join(["time_s", *[f"{a} [m/s^2]" for a in rec.axes], "encoder_angle_deg [deg]", "hall"]),
               comments="")
    cond_only = _map(tmp_path / "cond.toml", f"encoder_offset_deg = {float(rec.encoder_offset_deg)!r}\n"
                     f"hall_delay_s = {float(rec.hall_delay_s)!r}\n[condition]\n{cond}")
    outs = {}
    for name, path, extra in (("npz", d / "d.records.npz", []), ("tdms", tdms, ["--channels", str(cmap)]),
                              ("csv", csvp, ["--channels", str(cond_only)])):
        outs[name] = tmp_path / f"{name}.profile.csv"
        assert main(["profile", str(path), "--out", str(outs[name]), "--points", "64", "--quiet", *extra]) == 0
    ref = np.loadtxt(outs["npz"], delimiter=",", skiprows=1, comments="#")
    for name in ("tdms", "csv"):
        got = np.loadtxt(outs[name], delimiter=",", skiprows=1, comments="#")
        np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-6 * np.abs(ref).max())
    # cleat reads the TDMS recording with --channels MAP.toml, as the other commands do
    fields = {}
    for name, path, extra in (("npz", d / "d.records.npz", []), ("tdms", tdms, ["--channels", str(cmap)])):
        fields[name] = tmp_path / f"{name}.field.npz"
        assert main(["cleat", str(path), "--out", str(fields[name]), "--sectors", "16", "--duration", "0.05",
                     "--no-baseline", "--quiet", *extra]) == 0
    with np.load(fields["npz"]) as a, np.load(fields["tdms"]) as b:
        np.testing.assert_allclose(b["mean"], a["mean"], rtol=1e-9, atol=1e-9 * np.nanmax(np.abs(a["mean"])),
                                   equal_nan=True)


# ----------------------------------------------------------------------------- bad input


def _run_bad(argv, capsys, *must, out=None):
    status = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    errors = [e for e in err if not e.startswith("WARNING:")]
    assert status == 2, err
    assert len(errors) == 1, err
    for m in must:
        assert m in errors[0], errors[0]
    if out is not None:
        assert not out.exists()
    return errors[0]


@pytest.fixture
def small_tdms(rec, tmp_path):
    path = tmp_path / "b.tdms"
    text = _labview_tdms(rec, path)
    return path, text


@pytest.mark.parametrize("change, must", [
    (lambda t: t.replace('unit = "g"\n', "", 1), ["missing key 'unit'", "Acc R 00"]),
    (lambda t: t.replace('unit = "g"', 'unit = "furlong"', 1), ["'furlong'", "not an acceleration", "Acc R 00"]),
    (lambda t: t.replace('axis = "radial"', 'axis = "up"', 1), ["axis = 'up'"]),
    (lambda t: t.replace('sensitivity = 0.1', 'sensitivity = 0.0', 1), ["sensitivity = 0.0", "non-zero"]),
    (lambda t: t.replace('[channels."Acc R 00"]', '[channels."Acc X 00"]', 1), ["'Acc X 00' is not a channel"]),
    (lambda t: t.replace('role = "force"', 'role = "hammer"', 1), ["role = 'hammer'"]),
    (lambda t: t + "\nfs = 3\n", ["unknown key"]),
    (lambda t: t.replace('angle_deg = 0.0\n', "", 1), ["no sensor angle", "Acc R 00"]),
    (lambda t: "[channels", ["not a valid TOML"]),
])
def test_bad_channel_map(small_tdms, tmp_path, capsys, change, must):
    path, text = small_tdms
    cmap = _map(tmp_path / "bad.toml", change(text))
    out = tmp_path / "o.modes.csv"
    _run_bad(["ssi", str(path), "--channels", str(cmap), "--out", str(out), *SSI_OPTS], capsys, *must, out=out)


def test_bad_files(rec, tmp_path, capsys):
    out = tmp_path / "o.modes.csv"
    ssi = ["--out", str(out), *SSI_OPTS]
    # a matrix that is neither a channel vector nor ringfit's acc
    scipy.io.savemat(tmp_path / "m.mat", {"data": np.zeros((4, 100)), "fs_hz": FS})
    _run_bad(["ssi", str(tmp_path / "m.mat"), *ssi], capsys, "m.mat", "'data'", "shape (4, 100)", out=out)
    # ringfit's keys with a 2-D acc
    scipy.io.savemat(tmp_path / "a.mat", {"acc": np.zeros((4, 100)), "axes": "radial", "sensor_angle_deg": [0.0],
                                          "fs_hz": FS})
    _run_bad(["ssi", str(tmp_path / "a.mat"), *ssi], capsys, "a.mat", "'acc'", "(records, axes, samples)", out=out)
    # a truncated TDMS file and a truncated .mat
    full = write_records(rec, tmp_path / "t.tdms")
    cut = tmp_path / "cut.tdms"
    cut.write_bytes(full.read_bytes()[: full.stat().st_size // 2])
    _run_bad(["ssi", str(cut), *ssi], capsys, "cut.tdms", "TDMS", out=out)
    mat = write_records(rec, tmp_path / "t.mat")
    cutm = tmp_path / "cut.mat"
    cutm.write_bytes(mat.read_bytes()[:3000])
    _run_bad(["ssi", str(cutm), *ssi], capsys, "cut.mat", "MATLAB", out=out)
    # CSV: a short row, a word among the numbers, uneven time
    base = "time_s,radial [m/s^2],force [N]\n" + "".join(f"{k / FS!r},{np.sin(k)},{k}\n" for k in range(200))
    (tmp_path / "short.csv").write_text(base.replace("\n", "\n1.0,2.0\n", 50).replace("\n1.0,2.0\n", "\n", 49))
    _run_bad(["ssi", str(tmp_path / "short.csv"), *ssi], capsys, "short.csv", "row ", "2 fields", out=out)
    (tmp_path / "word.csv").write_text(base.replace(",7\n", ",seven\n"))
    _run_bad(["ssi", str(tmp_path / "word.csv"), *ssi], capsys, "row 9", "'force'", "'seven'", out=out)
    lines = base.splitlines()
    lines[20] = "0.5," + lines[20].split(",", 1)[1]
    (tmp_path / "uneven.csv").write_text("\n".join(lines) + "\n")
    _run_bad(["ssi", str(tmp_path / "uneven.csv"), *ssi], capsys, "row 21", "uneven time step", out=out)
    # no angle anywhere, no map
    (tmp_path / "ok.csv").write_text(base)
    _run_bad(["ssi", str(tmp_path / "ok.csv"), *ssi], capsys, "no sensor angle", "--channels", out=out)
    # a channel of unknown meaning
    (tmp_path / "what.csv").write_text(base.replace("radial [m/s^2]", "AI0 [V]"))
    _run_bad(["ssi", str(tmp_path / "what.csv"), *ssi], capsys, "'AI0'", "--channels MAP.toml", out=out)
    # unequal channel lengths in a TDMS file
    with TdmsWriter(str(tmp_path / "len.tdms")) as w:
        w.write_segment([GroupObject("g", properties={"sensor_angle_deg": 0.0}),
                         ChannelObject("g", "radial", np.zeros(300), properties={"unit_string": "g",
                                                                                   "wf_increment": 1 / FS}),
                         ChannelObject("g", "force", np.zeros(200), properties={"unit_string": "N",
                                                                                  "wf_increment": 1 / FS})])
    _run_bad(["ssi", str(tmp_path / "len.tdms"), *ssi], capsys, "'g/force' has 200 samples", out=out)
    # --channels on an npz
    npz = write_records(rec, tmp_path / "r.records.npz")
    cm = _map(tmp_path / "c.toml", '[channels.x]\naxis = "radial"\nunit = "g"\n')
    _run_bad(["ssi", str(npz), "--channels", str(cm), *ssi], capsys, "--channels applies to", out=out)
    # a recording without an encoder for profile, and a force channel in a recording
    (tmp_path / "rec.csv").write_text(base)
    prof = tmp_path / "p.profile.csv"
    _run_bad(["profile", str(tmp_path / "rec.csv"), "--out", str(prof)], capsys, "force channel", out=prof)


def test_channel_map_is_never_written(small_tdms, tmp_path, capsys):
    path, text = small_tdms
    cmap = _map(tmp_path / "m.toml", text)
    before = cmap.read_bytes()
    _run_bad(["ssi", str(path), "--channels", str(cmap), "--out", str(cmap), "--force", *SSI_OPTS], capsys,
             "input file")
    assert cmap.read_bytes() == before


def test_unmapped_channels_are_warned(rec, tmp_path):
    path = write_records(rec, tmp_path / "r.tdms")
    text = []
    for r in range(rec.n_records):
        for a in rec.axes:
            text.append(f'[channels."record {r:03d}/{a}"]\naxis = "{a}"\nunit = "m/s^2"\n')
    cmap = _map(tmp_path / "m.toml", "\n".join(text))
    with pytest.warns(UserWarning, match=f"{rec.n_records} channel.* not in the channel map"):
        back = read_records(path, channels=cmap)
    assert back.force is None and back.acc.shape == rec.acc.shape


def test_short_name_ambiguous_across_groups(rec, tmp_path):
    path = write_records(rec, tmp_path / "r.tdms")
    cmap = _map(tmp_path / "m.toml", '[channels.radial]\naxis = "radial"\nunit = "g"\nangle_deg = 0.0\n')
    with pytest.raises(InputError, match="GROUP/CHANNEL"):
        read_records(path, channels=cmap)


def test_estimate_tells_a_profile_from_a_csv_recording(tmp_path):
    from ringfit.cli.estimate import _input_kind

    (tmp_path / "side.csv").write_text("x\n")
    (tmp_path / "side.json").write_text("{}\n")
    assert _input_kind(tmp_path / "run.profile.csv") == "profile"
    assert _input_kind(tmp_path / "side.csv") == "profile"  # a CSV with its JSON sidecar is a profile (§3)
    assert _input_kind(tmp_path / "drum.csv") == "recording"
    for name in ("d.records.npz", "d.tdms", "d.MAT"):
        assert _input_kind(tmp_path / name) == "recording"
    with pytest.raises(InputError, match="expected a"):
        _input_kind(tmp_path / "d.uff")


def test_example_format_only_for_records(tmp_path, capsys):
    out = tmp_path / "ex"
    assert main(["example", "profiles", "--out", str(out), "--format", "csv"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--format csv applies to `ringfit example records` only" in err[0]
    assert not out.exists()
    assert main(["example", "records", "--out", str(out), "--format", "xlsx"]) == 2
    assert not out.exists()


def test_map_rate_overriding_the_file_is_warned(rec, tmp_path):
    path = write_records(rec, tmp_path / "r.tdms")
    cmap = _map(tmp_path / "m.toml", "fs_hz = 6000.0\n")
    with pytest.warns(UserWarning, match="fs_hz = 6000 Hz overrides the file's 6400 Hz"):
        assert read_records(path, channels=cmap).fs_hz == 6000.0


# ----------------------------------------------------------------------------- fuzz: InputError or a valid read

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

FUZZ = settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                       HealthCheck.function_scoped_fixture],
                derandomize=True)
CELLS = st.one_of(st.sampled_from(["", "nan", "inf", "1e400", "-0", "x", "1,2", '"', "1e-320", "0x1"]),
                  st.floats(allow_nan=True, allow_infinity=True).map(repr), st.text(max_size=6))


def _read_or_input_error(path, channels=None, continuous=False):
    try:
        if continuous:
            read_continuous(path, channels=channels)
        else:
            read_records(path, channels=channels)
    except InputError as exc:
        assert "\n" not in str(exc)


@FUZZ
@given(header=st.lists(st.sampled_from(["time_s", "t [ms]", "radial [g]", "force (N)", "hall", "radial",
                                        "encoder_angle_deg [rad]", "x [V]", "", "radial [furlong]"]),
                       min_size=1, max_size=4),
       rows=st.lists(st.lists(CELLS, min_size=0, max_size=5), min_size=0, max_size=6))
def test_fuzz_csv(tmp_path_factory, header, rows):
    d = tmp_path_factory.mktemp("fz")
    path = d / "f.csv"
    path.write_text(",".join(header) + "\n" + "\n".join(",".join(r) for r in rows) + "\n",
                    encoding="utf-8", errors="surrogatepass")
    cmap = _map(d / "m.toml", "fs_hz = 100.0\n")
    for continuous in (False, True):
        _read_or_input_error(path, cmap, continuous)


@pytest.fixture(scope="module")
def binaries(rec, tmp_path_factory):
    d = tmp_path_factory.mktemp("bin")
    small = type(rec)(acc=rec.acc[:2, :, :64], axes=rec.axes, sensor_angle_deg=rec.sensor_angle_deg[:2],
                      fs_hz=rec.fs_hz, force=rec.force[:2, :64])
    return {s: write_records(small, d / f"v{s}").read_bytes() for s in (".tdms", ".mat")}


@FUZZ
@given(suffix=st.sampled_from([".tdms", ".mat"]), cut=st.floats(0.0, 1.0), flips=st.lists(
    st.tuples(st.floats(0.0, 1.0), st.integers(1, 255)), max_size=4))
def test_fuzz_binary_files(binaries, tmp_path_factory, suffix, cut, flips):
    data = bytearray(binaries[suffix])
    for where, xor in flips:
        data[int(where * (len(data) - 1))] ^= xor
    data = bytes(data[: max(0, int(cut * len(data)))] if cut < 0.999 else data)
    path = tmp_path_factory.mktemp("fb") / f"f{suffix}"
    path.write_bytes(data)
    _read_or_input_error(path)


@FUZZ
@given(key=st.sampled_from(["role", "axis", "angle_deg", "unit", "sensitivity", "record", "bogus"]),
       value=st.one_of(st.sampled_from(['"acc"', '"force"', '"radial"', '"g"', '"N"', "0", "-1", "nan", "inf",
                                        "1e400", "true", "[1]", "{a = 1}", '""']),
                       st.floats(allow_nan=False).map(repr)))
def test_fuzz_channel_map(small_tdms, tmp_path_factory, key, value):
    path, text = small_tdms
    d = tmp_path_factory.mktemp("fm")
    cmap = _map(d / "m.toml", text.replace('[channels."Acc R 00"]\n', f'[channels."Acc R 00"]\n{key} = {value}\n', 1))
    _read_or_input_error(path, cmap)


def test_tdms_recording_is_read_chunk_by_chunk(drum, tmp_path, monkeypatch):
    """A continuous TDMS recording is never held whole: every read is one chunk, and the walk equals the arrays."""
    import nptdms

    from ringfit.io.rig_types import ScaledChannel

    rec, _ = drum
    acc = [rec.read(f"acc:{a}") for a in rec.axes]
    enc = rec.read("encoder_angle_deg")
    path = tmp_path / "long.tdms"
    inc = {"wf_increment": 1.0 / FS}
    with TdmsWriter(str(path)) as w:
        for part in np.array_split(np.arange(enc.size), 5):  # several segments, as LabVIEW appends them
            w.write_segment([ChannelObject("Drum", a, x[part], properties={**inc, "unit_string": "m/s^2"})
                             for a, x in zip(rec.axes, acc)]
                            + [ChannelObject("Drum", "encoder_angle_deg", enc[part], properties=inc)])
    asked = []
    real = nptdms.tdms.TdmsChannel.read_data

    def spy(self, offset=0, length=None, scaled=True):
        asked.append(length)
        return real(self, offset=offset, length=length, scaled=scaled)

    monkeypatch.setattr(nptdms.tdms.TdmsChannel, "read_data", spy)
    with read_continuous(path) as back:
        assert isinstance(back._channels["acc:radial"], ScaledChannel)
        parts = list(back.chunks(1000))
    assert asked and max(asked) <= 1000
    np.testing.assert_array_equal(np.concatenate([p.acc for p in parts], axis=1), np.stack(acc))
    # the decoded angle is the npz record's, less its encoder offset (not given here)
    want = np.concatenate([p.angle_deg for p in rec.chunks(1000, acc=False)]) - rec.encoder_offset_deg
    np.testing.assert_allclose(np.concatenate([p.angle_deg for p in parts]), want, atol=1e-9)
    # a recording cut short is refused up front, not walked up to the cut
    cut = tmp_path / "cut.tdms"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size - 5000])
    with pytest.raises(InputError, match="truncated"):
        read_continuous(cut)


def test_mat_v73_cell_array_of_axis_names_and_skipped_struct(rec, tmp_path):
    """axes = {'radial','tangential'} as MATLAB -v7.3 stores a cell: object references into '#refs#'."""
    path = tmp_path / "cell73.mat"
    _mat73(path, {"acc": rec.acc, "sensor_angle_deg": rec.sensor_angle_deg, "fs_hz": rec.fs_hz})
    with h5py.File(path, "a") as f:
        refs = f.create_group("#refs#")
        cells = []
        for i, name in enumerate(rec.axes):
            ds = refs.create_dataset(f"a{i}", data=np.array([[ord(c)] for c in name], dtype=np.uint16))
            ds.attrs["MATLAB_class"] = np.bytes_("char")
            cells.append(ds.ref)
        cell = f.create_dataset("axes", data=np.array([[r] for r in cells], dtype=h5py.ref_dtype))
        cell.attrs["MATLAB_class"] = np.bytes_("cell")
        grp = f.create_group("bench")  # a struct: skipped with a warning
        grp.attrs["MATLAB_class"] = np.bytes_("struct")
    with pytest.warns(UserWarning, match="bench"):
        back = read_records(path)
    assert back.axes == rec.axes
    np.testing.assert_array_equal(back.acc, rec.acc)


@pytest.mark.slow
def test_estimate_on_a_mat_recording_equals_the_npz(tmp_path):
    """`ringfit estimate` on the same drum recording as npz and as MATLAB v5 channel vectors (+ map): same JSON."""
    import json

    from ringfit.data import path as data_path
    from ringfit.synth.cleat import CleatBench

    bench = CleatBench(speed_kmh=60.0, load_n=4000.0, fs_hz=8192.0, noise_ms2=4.0, highpass_hz=0.5, seed=4)
    npz = bench.write(tmp_path / "run.records.npz", 1.0, cleat=False)
    rec = read_continuous(npz)
    variables = {"fs_hz": rec.fs_hz, "enc": rec.read("encoder_angle_deg")}
    variables.update({f"acc_{a}": rec.read(f"acc:{a}") / G for a in rec.axes})
    scipy.io.savemat(tmp_path / "run.mat", variables)
    cond = "".join(f"{k} = {float(v)!r}\n" for k, v in rec.condition.items())
    lines = [f'[channels.acc_{a}]\naxis = "{a}"\nunit = "g"\n' for a in rec.axes]
    cmap = _map(tmp_path / "run.toml", f"encoder_offset_deg = {float(rec.encoder_offset_deg)!r}\n[condition]\n{cond}\n"
                + "\n".join(lines) + '\n[channels.enc]\nrole = "encoder"\n')
    rec.close()
    docs = {}
    for name, path, extra in (("npz", npz, []), ("mat", tmp_path / "run.mat", ["--channels", str(cmap)])):
        out = tmp_path / f"{name}.estimate.json"
        assert main(["estimate", str(path), "--tyre", str(data_path("table9.tyre.toml")), "--out", str(out),
                     "--quiet", *extra]) == 0
        docs[name] = json.loads(out.read_text())
    a, b = docs["npz"], docs["mat"]
    assert a["load_n"]["value"] == pytest.approx(b["load_n"]["value"], rel=1e-6)
    assert abs(a["load_n"]["value"] / 4000.0 - 1) < 0.02
