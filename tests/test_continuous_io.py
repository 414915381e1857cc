"""Continuous records (docs/records-continuous.md): round trip, §4 compatibility, encoder decoding, clear errors."""

import zipfile

import numpy as np
import pytest

from ringfit.errors import InputError
from ringfit.io.continuous import ContinuousRecord, ContinuousWriter, read_continuous, write_continuous
from ringfit.synth.cleat import CleatBench

FS = 6400.0


def _record(encoder="angle", seconds=3.0):
    bench = CleatBench(steady="analytic", fs_hz=FS, encoder=encoder, pulses_per_rev=256)
    return bench, bench.record(seconds)


def _walk(rec, chunk):
    parts = list(rec.chunks(chunk))
    return (np.concatenate([p.acc for p in parts], axis=1), np.concatenate([p.angle_deg for p in parts]),
            np.concatenate([p.hall for p in parts]))


@pytest.mark.parametrize("encoder", ["angle", "pulses"])
def test_round_trip_and_chunking(tmp_path, encoder):
    bench, rec = _record(encoder)
    path = write_continuous(rec, tmp_path / "x.records.npz")
    back = read_continuous(path)
    assert back.axes == rec.axes and back.fs_hz == FS and back.samples == rec.samples
    assert back.condition["speed_kmh"] == 40.0 and back.condition["drum_diameter_m"] == 1.2192
    assert back.hall_delay_s == rec.hall_delay_s and back.encoder_offset_deg == rec.encoder_offset_deg
    a0, p0, h0 = _walk(rec, 1 << 20)
    a1, p1, h1 = _walk(back, 777)  # odd chunk size: state carried across chunk edges
    np.testing.assert_array_equal(a0, a1)
    np.testing.assert_allclose(h0, h1.astype(np.float64), rtol=1e-6, atol=1e-6)  # hall stored as float32
    np.testing.assert_allclose(p0, p1, atol=1e-9)
    back.close()


@pytest.mark.parametrize("encoder,tol", [("angle", 360 / 4096 / 2 + 1e-9), ("pulses", None)])
def test_sensor_angle_decoding_matches_truth(encoder, tol):
    bench, rec = _record(encoder)
    _, phi, _ = _walk(rec, 5000)
    truth = bench.sensor_angle(np.arange(rec.samples) / FS)
    if encoder == "angle":  # absolute: unwrapped angle within half a count of the truth (up to 360 k)
        d = phi - truth
        d -= 360 * np.round(np.median(d) / 360)
        assert np.abs(d).max() <= tol
    else:  # pulses: edges are seen up to one sample late and the pulse length is known to ±1 sample,
        # so after the first two edges the error stays below two samples' rotation
        step = 360 / 256
        per_sample = np.degrees(bench.omega) / FS
        d = phi - truth
        settled = np.arange(rec.samples) > 3 * FS * step / np.degrees(bench.omega)
        assert np.abs(d[settled]).max() <= 2 * per_sample + 1e-6
        assert np.abs(d).max() <= step + per_sample


def test_file_is_a_section4_records_file(tmp_path):
    _, rec = _record()
    path = write_continuous(rec, tmp_path / "x.records.npz")
    with np.load(path) as z:  # a plain §4 reader
        assert z["acc"].shape == (1, 2, rec.samples)
        assert list(z["axes"]) == ["radial", "tangential"]
        assert z["sensor_angle_deg"].shape == (1,)
        assert float(z["fs_hz"]) == FS
        assert str(z["kind"]) == "continuous"
    with zipfile.ZipFile(path) as zf:  # stored, so that the reader can memory-map it
        assert all(i.compress_type == zipfile.ZIP_STORED for i in zf.infolist())


def test_compressed_file_is_streamed(tmp_path):
    _, rec = _record()
    plain = write_continuous(rec, tmp_path / "a.records.npz")
    with np.load(plain) as z:
        arrays = {k: z[k] for k in z.files}
    np.savez_compressed(tmp_path / "b.records.npz", **arrays)
    back = read_continuous(tmp_path / "b.records.npz")
    a0, p0, h0 = _walk(rec, 4096)
    a1, p1, h1 = _walk(back, 4096)
    np.testing.assert_array_equal(a0, a1)
    np.testing.assert_allclose(p0, p1, atol=1e-9)
    np.testing.assert_array_equal(back.read("acc:tangential", 100, 200), a0[1, 100:200])
    back.close()


def _npz(path, **arrays):
    np.savez(path, **arrays)
    return path


def _base(n=1000):
    return dict(kind=np.array("continuous"), acc=np.zeros((1, 1, n)), axes=np.array(["radial"]), fs_hz=np.float64(FS),
                sensor_angle_deg=np.zeros(1), encoder_angle_deg=np.linspace(0, 700, n))


@pytest.mark.parametrize("change,message", [
    (dict(kind=None), "not a continuous record"),
    (dict(acc=np.zeros((2, 1, 1000))), "expected (1, 1, samples)"),
    (dict(axes=np.array(["vertical"])), "unknown axis 'vertical'"),
    (dict(encoder_pulses=np.zeros(1000), pulses_per_rev=np.int64(64)), "expected one encoder"),
    (dict(hall=np.zeros(999)), "key 'hall' has 999 samples"),
    (dict(fs_hz=np.float64(-1.0)), "key 'fs_hz'"),
    (dict(encoder_angle_deg=None, encoder_pulses=np.zeros(1000)), "needs key 'pulses_per_rev'"),
])
def test_clear_errors(tmp_path, change, message):
    arrays = _base()
    for k, v in change.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = v
    path = _npz(tmp_path / "bad.records.npz", **arrays)
    with pytest.raises(InputError) as exc:
        read_continuous(path)
    assert message in str(exc.value) and "bad.records.npz" in str(exc.value)
    assert "\n" not in str(exc.value)


def test_errors_found_while_walking(tmp_path):
    arrays = _base()
    arrays["acc"][0, 0, 321] = np.nan
    rec = read_continuous(_npz(tmp_path / "nan.records.npz", **arrays))
    with pytest.raises(InputError, match="non-finite value at sample 321"):
        list(rec.chunks(100))
    arrays = _base()
    arrays.pop("encoder_angle_deg")
    arrays.update(encoder_pulses=(np.arange(1000) % 2).astype(np.uint8), pulses_per_rev=np.int64(64))
    rec = read_continuous(_npz(tmp_path / "fast.records.npz", **arrays))
    with pytest.raises(InputError, match="2 samples apart"):
        list(rec.chunks(100))
    with pytest.raises(InputError, match="file not found"):
        read_continuous(tmp_path / "missing.records.npz")


def test_writer_refuses_overwrite_and_leaves_nothing_on_failure(tmp_path):
    _, rec = _record(seconds=1.0)
    path = write_continuous(rec, tmp_path / "x.records.npz")
    with pytest.raises(InputError, match="refusing to overwrite"):
        write_continuous(rec, path)
    target = tmp_path / "y.records.npz"
    with pytest.raises(RuntimeError):
        with ContinuousWriter(target, axes=("radial",), fs_hz=FS, samples=100, hall=False) as w:
            w.write(np.zeros((1, 50)), encoder=np.zeros(50))
            raise RuntimeError("interrupted")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.records.npz"]


def test_in_memory_record_validates():
    with pytest.raises(InputError, match="key 'encoder_angle_deg' has 5 samples"):
        ContinuousRecord(acc=np.zeros((1, 10)), axes=("radial",), fs_hz=FS, encoder_angle_deg=np.zeros(5))
