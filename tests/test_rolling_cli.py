"""``ringfit roll`` and ``ringfit fit-rolling`` end to end, and their input errors."""

import shutil

import pytest

from ringfit.cli import main
from ringfit.data import path as data_path
from ringfit.io.profiles import read_profile
from ringfit.io.tyre import read_tyre


@pytest.fixture()
def tyre(tmp_path):
    dst = tmp_path / "tyre.toml"
    shutil.copy(data_path("table9.tyre.toml"), dst)
    text = dst.read_text().replace("k_tread_n_per_m2 = 19e6", "k_tread_n_per_m2 = 25e6")
    (tmp_path / "truth.toml").write_text(text)
    return dst


@pytest.mark.slow
def test_roll_then_fit_recovers_tread_stiffness(tmp_path, tyre, capsys):
    truth = tmp_path / "truth.toml"
    outs = []
    # four speeds: the fit then has the structure of tests/test_rolling_fit.py's (4 drum profiles, k_tread),
    # so the in-process CLI reuses that compiled fit when both files run in one session
    for v in (20, 30, 40, 50):
        out = tmp_path / f"sim{v}.profile.csv"
        assert main(["roll", "--tyre", str(truth), "--speed", str(v), "--drum", "1.2192", "--out", str(out),
                     *(["--plot", str(tmp_path / "sim.png")] if v == 30 else [])]) == 0
        outs.append(out)
    prof = read_profile(outs[1])
    assert prof.drum_diameter_m == 1.2192 and prof.rotation_hz > 0 and len(prof) == 1024
    assert (tmp_path / "sim.png").stat().st_size > 10_000
    fitted = tmp_path / "fitted2.toml"
    assert main(["fit-rolling", *map(str, outs), "--tyre", str(tyre), "--out", str(fitted),
                 "--plot", str(tmp_path / "fit.png")]) == 0
    # noise-free profiles of a sensor with no tilt, corner or liner offset, read through each run's sensor
    # nuisances (the default): their priors (tilt 0.5 ± 0.5, …) hold them a hair off zero (γ ≈ 0.005), k_tread 4e-6 off
    assert read_tyre(fitted).ring.k_tread == pytest.approx(25e6, rel=2e-5)
    out = capsys.readouterr().out
    assert "converged" in out
    # the nuisances' own flags (a corner the clean data cannot bound) are not the fit's warnings; each run's line is
    assert not [line for line in out.splitlines() if line.startswith("WARNING: corner_hz_")]
    assert out.count("IEPE corner") == 4
    # outputs are never overwritten silently
    assert main(["fit-rolling", *map(str, outs), "--tyre", str(tyre), "--out", str(fitted)]) == 2


def test_bad_profile_exits_2_with_one_line(tmp_path, tyre, capsys):
    bad = tmp_path / "bad.profile.csv"
    bad.write_text("angle,acc_radial_ms2,acc_tangential_ms2\n0,1,2\n")
    (tmp_path / "bad.profile.json").write_text('{"speed_kmh": 30}')
    assert main(["fit-rolling", str(bad), "--tyre", str(tyre), "--out", str(tmp_path / "o.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "bad.profile" in err
    assert main(["roll", "--tyre", str(tyre), "--speed", "30", "--load", "-5", "--out", str(tmp_path / "x.profile.csv")]) == 2
    assert not (tmp_path / "x.profile.csv").exists()
