"""Rolling profile files (docs/formats.md §3): round trip, validation errors, resampling onto the model grid."""

import json

import numpy as np
import pytest

from ringfit.errors import InputError
from ringfit.io.profiles import Profile, read_profile, resample_profile, write_profile

CONDITION = {"speed_kmh": 30.0, "load_n": 4000.0, "pressure_bar": 2.2, "revolutions": 26, "sample_rate_hz": 25600}


def make_profile(n=360, **condition):
    angle = -180.0 + 360.0 * np.arange(n) / n
    a = np.radians(angle)
    return Profile(angle, 3.0 * np.cos(2 * a) + 1.0, -2.0 * np.sin(5 * a + 0.4), condition={**CONDITION, **condition})


def write_raw(tmp_path, rows, header="angle_deg,acc_radial_ms2,acc_tangential_ms2", condition=CONDITION):
    path = tmp_path / "run.profile.csv"
    path.write_text(header + "\n" + "\n".join(",".join(map(str, r)) for r in rows) + "\n")
    if condition is not None:
        (tmp_path / "run.profile.json").write_text(json.dumps(condition))
    return path


def good_rows(n=64):
    return [(-180.0 + 360.0 * i / n, 0.1 * i, -0.2 * i) for i in range(n)]


def test_round_trip_is_exact(tmp_path):
    prof = make_profile(drum_diameter_m=1.2192, rotation_hz=7.66)
    path = write_profile(prof, tmp_path / "x.profile.csv")
    back = read_profile(path)
    for name in ("angle_deg", "acc_radial_ms2", "acc_tangential_ms2"):
        np.testing.assert_array_equal(getattr(back, name), getattr(prof, name))
    assert back.condition == prof.condition
    assert back.drum_diameter_m == 1.2192 and back.rotation_hz == 7.66
    with pytest.raises(InputError, match="exists"):
        write_profile(prof, path)


def test_omega_from_encoder_or_rolling_radius():
    assert make_profile(rotation_hz=5.0).omega()[0] == pytest.approx(2 * np.pi * 5.0)
    omega, source = make_profile().omega(0.31)
    assert omega == pytest.approx(30 / 3.6 / 0.31) and "R_e = 0.31" in source
    with pytest.raises(InputError, match="rolling radius"):
        make_profile().omega()


@pytest.mark.parametrize(
    "case,match",
    [
        ("columns", "missing column.*acc_tangential_ms2"),
        ("unsorted", "row 7.*-157.5 after -151.875.*increase strictly"),
        ("gap", "row 12.*gap"),
        ("partial", "wrap-around"),
        ("nonnumeric", "row 4, column 'acc_radial_ms2'.*not a number"),
        ("range", "outside \\[-180, 180\\)"),
        ("no_sidecar", "missing sidecar"),
        ("sidecar_field", "missing field 'speed_kmh'"),
        ("sidecar_value", "'pressure_bar'.*Pa"),
        ("short", "at least 16"),
    ],
)
def test_bad_profiles_raise_one_line_input_errors(tmp_path, case, match):
    rows = good_rows()
    header = "angle_deg,acc_radial_ms2,acc_tangential_ms2"
    condition = dict(CONDITION)
    if case == "columns":
        header = "angle_deg,acc_radial_ms2,acc_tan"
    elif case == "unsorted":
        rows[4], rows[5] = rows[5], rows[4]
    elif case == "gap":
        del rows[10]
    elif case == "partial":
        rows = rows[:40]
    elif case == "nonnumeric":
        rows[2] = (rows[2][0], "abc", 0.0)
    elif case == "range":
        rows[-1] = (180.0, 0.0, 0.0)
    elif case == "no_sidecar":
        condition = None
    elif case == "sidecar_field":
        del condition["speed_kmh"]
    elif case == "sidecar_value":
        condition["pressure_bar"] = 220000
    elif case == "short":
        rows = good_rows(8)
    path = write_raw(tmp_path, rows, header, condition)
    with pytest.raises(InputError, match=match) as info:
        read_profile(path)
    assert "\n" not in str(info.value) and "run.profile" in str(info.value)


def test_resampling_is_exact_for_band_limited_profiles_with_offset():
    prof = make_profile(n=500)  # 500 angles onto a 256-point grid
    grid = np.radians(-180.0 + 360.0 * np.arange(256) / 256)
    out = resample_profile(prof, 256)
    np.testing.assert_allclose(out[0], 3.0 * np.cos(2 * grid) + 1.0, atol=1e-12)
    np.testing.assert_allclose(out[1], -2.0 * np.sin(5 * grid + 0.4), atol=1e-12)
    # φ = α + offset: the recorded channel at α = φ − offset
    off = 1.5
    shifted = resample_profile(prof, 256, offset_deg=off)
    np.testing.assert_allclose(shifted[0], 3.0 * np.cos(2 * (grid - np.radians(off))) + 1.0, atol=1e-12)


def test_a_sidecar_without_load_reads_but_its_load_is_an_error_naming_the_file(tmp_path):
    """``ringfit estimate`` reads profiles whose load is unknown; every command that needs it still fails."""
    condition = dict(CONDITION)
    del condition["load_n"]
    prof = read_profile(write_raw(tmp_path, good_rows(), "angle_deg,acc_radial_ms2,acc_tangential_ms2", condition))
    assert "load_n" not in prof.condition and prof.speed_kmh == 30.0
    with pytest.raises(InputError, match="run.profile.*missing field 'load_n'") as info:
        prof.load_n
    assert "\n" not in str(info.value)
