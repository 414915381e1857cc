"""Tyre TOML and mode-table I/O (docs/formats.md §1–2): read, validate, write, round-trip."""

import json

import numpy as np
import pytest

from ringfit.data import path as data_path
from ringfit.errors import InputError
from ringfit.io.modes import ModeTable, read_mode_table, write_mode_table
from ringfit.io.tyre import read_tyre, write_tyre


def test_bundled_tyre_matches_table9():
    t = read_tyre(data_path("table9.tyre.toml"))
    assert t.geometry.radius == 0.296 and t.geometry.width == 0.152
    assert t.geometry.pressure == pytest.approx(2.2e5)
    assert t.ring.ei == 0.9426 and t.ring.kw == 1.294e6 and t.ring.k_tread == 19e6
    # derived quantities of docs/physics.md §1
    assert float(t.geometry.pretension) == pytest.approx(9898, abs=1)
    assert float(t.geometry.hoop_pressure_stiffness) == pytest.approx(1.1297e5, rel=1e-4)


def test_tyre_round_trip(tmp_path):
    t = read_tyre(data_path("table9.tyre.toml"))
    out = write_tyre(t, tmp_path / "a.toml")
    t2 = read_tyre(out)
    assert t2.ring_values == t.ring_values
    assert t2.geometry.radius == t.geometry.radius and t2.geometry.pressure == pytest.approx(t.geometry.pressure)
    with pytest.raises(InputError, match="refusing to overwrite"):
        write_tyre(t, out)


@pytest.mark.parametrize("text, match", [
    ("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 220000\n", "looks like Pa"),
    ("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\n", "lacks pressure_bar"),
    ("[tyre]\nradius_m = 'big'\nwidth_m = 0.152\npressure_bar = 2.2\n", "radius_m"),
    ("[tyre]\nradius_m = 0.296\nwidth_m = -1\npressure_bar = 2.2\n", "width_m"),
    ("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n[ring]\nei_n_m2 = nan\n", "ei_n_m2"),
    ("[tyre\n", "TOML"),
])
def test_bad_tyre_files(tmp_path, text, match):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(InputError, match=match) as e:
        read_tyre(p)
    assert "bad.toml" in str(e.value) and "\n" not in str(e.value)


def test_seed_mode_tables_load():
    t = read_mode_table(data_path("free-ssi.modes.csv"))
    assert len(t) == 10 and t.state == "free" and t.condition["frame"] == "fixed"
    assert list(t.n[:9]) == list(range(1, 10)) and t.n[9] == -1 and t.kind[9] == "acoustic"
    assert t.freq_hz[9] == 227.0 and np.isnan(t.freq_std_hz).all()
    f = read_mode_table(data_path("free-frf.modes.csv"))
    assert "direction" in f.extra and f.extra["direction"][0] == "tangential"


def test_mode_table_round_trip(tmp_path):
    t = read_mode_table(data_path("free-frf.modes.csv"))
    t.freq_std_hz[:] = np.linspace(0.1, 0.9, 9) / 3  # not exactly representable in decimal
    t.branch[2] = "backward"
    out = write_mode_table(t, tmp_path / "x.modes.csv")
    back = read_mode_table(out)
    for c in ("n", "a", "tag", "kind", "branch"):
        assert list(getattr(back, c)) == list(getattr(t, c))
    np.testing.assert_array_equal(back.freq_hz, t.freq_hz)
    np.testing.assert_array_equal(back.freq_std_hz, t.freq_std_hz)
    np.testing.assert_array_equal(back.damping_pct, t.damping_pct)
    assert list(back.extra["direction"]) == list(t.extra["direction"])
    assert back.condition == t.condition
    assert json.loads((tmp_path / "x.modes.json").read_text())["state"] == "free"


def test_columns_in_any_order_and_defaults(tmp_path):
    p = tmp_path / "m.modes.csv"
    p.write_text("freq_hz,n,comment\n107.5,1,first\n120,,\n")
    t = read_mode_table(p)
    assert list(t.n) == [1, -1] and list(t.kind) == ["structural"] * 2 and t.extra["comment"][0] == "first"
    assert t.state == "free"


@pytest.mark.parametrize("body, match", [
    ("n,freq\n1,100\n", "missing column 'freq_hz'"),
    ("n,freq_hz\n1,nan\n", "row 2, column 'freq_hz'"),
    ("n,freq_hz\n1,-100\n", "expected a positive value"),
    ("n,freq_hz\n1,abc\n", "not a number"),
    ("n,freq_hz,kind\n1,100,fluid\n", "expected one of"),
    ("n,freq_hz\n1.5,100\n", "column 'n'"),
    ("n,freq_hz,freq_std_hz\n1,100,-1\n", "freq_std_hz"),
    ("", "empty file"),
])
def test_bad_mode_tables(tmp_path, body, match):
    p = tmp_path / "bad.modes.csv"
    p.write_text(body)
    with pytest.raises(InputError, match=match) as e:
        read_mode_table(p)
    assert "bad.modes.csv" in str(e.value) and "\n" not in str(e.value)


def test_bad_sidecar(tmp_path):
    p = tmp_path / "m.modes.csv"
    p.write_text("n,freq_hz\n1,100\n")
    (tmp_path / "m.modes.json").write_text('{"state": "free", "pressure_bar": 220000}')
    with pytest.raises(InputError, match="looks like Pa"):
        read_mode_table(p)
    (tmp_path / "m.modes.json").write_text('{"state": "spinning"}')
    with pytest.raises(InputError, match="state"):
        read_mode_table(p)


def test_missing_file():
    with pytest.raises(InputError, match="file not found"):
        read_mode_table("/nonexistent/x.modes.csv")


def test_mode_table_constructor_validates_shapes():
    with pytest.raises(ValueError):
        ModeTable(freq_hz=[1.0, 2.0], n=[1])
