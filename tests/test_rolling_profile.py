"""Rolling profiles from continuous recordings vs the synthetic truth (docs/physics.md §5 layer 5 for the high-pass)."""

import numpy as np
import pytest

from ringfit.errors import InputError
from ringfit.io.profiles import read_profile, write_profile
from ringfit.synth.cleat import CleatBench
from ringfit.targets.cleat import detect_cleat_arrivals
from ringfit.targets.rolling_profile import rolling_profile

FS = 6400.0
POINTS = 512
NOISE = 5.0


@pytest.fixture(scope="module")
def bench():
    return CleatBench(steady="analytic", fs_hz=FS, noise_ms2=NOISE)


@pytest.fixture(scope="module")
def rolling(bench):
    return bench.record(20.0, cleat=False)


def _bin_truth(bench, angle, axis, points):
    """Truth averaged over each angle bin (the profile averages samples spread evenly over the bin)."""
    sub = (np.arange(16) + 0.5) / 16 - 0.5
    return np.mean([bench.profile_truth(angle + s * 360 / points, axis) for s in sub], axis=0)


@pytest.mark.parametrize("axis", ["radial", "tangential"])
def test_profile_matches_truth_within_its_standard_error(bench, rolling, axis):
    prof = rolling_profile(rolling, points=POINTS, chunk=50_000)
    truth = _bin_truth(bench, prof.angle_deg, axis, POINTS)
    err = prof.channel(axis) - truth
    se = prof.standard_error()[prof.axes.index(axis)]
    # errors are noise: rms of err/se ≈ 1 (χ² with M dof), and no systematic residual
    z = err / se
    assert 0.7 < np.sqrt(np.mean(z**2)) < 1.3
    assert abs(np.mean(err)) < 4 * np.sqrt(np.mean(se**2) / POINTS)
    # spread ≈ noise of a bin mean: σ / √(samples per bin per revolution)
    per_bin = FS / (bench.rotation_hz * POINTS)
    np.testing.assert_allclose(np.nanmedian(prof.spread[prof.axes.index(axis)]), NOISE / np.sqrt(per_bin), rtol=0.2)


def test_rotation_rate_and_revolutions(bench, rolling):
    prof = rolling_profile(rolling, points=POINTS)
    assert prof.rotation_hz == pytest.approx(bench.rotation_hz, rel=1e-4)
    assert prof.full_revolutions in (int(20.0 * bench.rotation_hz) - 1, int(20.0 * bench.rotation_hz),
                                     int(20.0 * bench.rotation_hz) + 1)


def test_cleat_record_gives_its_own_no_cleat_profile(bench):
    rec = bench.record(40.0, cleat=True)
    arrivals = detect_cleat_arrivals(rec)
    prof = rolling_profile(rec, points=256, arrivals_samples=arrivals.sample, quiet_after_s=0.7 * bench.drum_period_s)
    truth = _bin_truth(bench, prof.angle_deg, "radial", 256)
    z = (prof.channel("radial") - truth) / prof.standard_error()[0]
    assert np.sqrt(np.mean(z**2)) < 1.5  # the cleat's vibration has died out in the kept samples
    dirty = rolling_profile(rec, points=256)  # keeping them: the cleat response shows up as spread
    assert np.nanmedian(dirty.spread[0]) > 3 * np.nanmedian(prof.spread[0])


def test_profile_file_round_trip(tmp_path, rolling):
    prof = rolling_profile(rolling, points=POINTS)
    path = write_profile(prof.to_profile(), tmp_path / "r.profile.csv")
    back = read_profile(path)
    np.testing.assert_array_equal(back.angle_deg, prof.angle_deg)
    np.testing.assert_array_equal(back.acc_radial_ms2, prof.channel("radial"))
    np.testing.assert_array_equal(back.extra["acc_radial_spread_ms2"].astype(float), prof.spread[0])
    assert back.condition["revolutions"] == prof.full_revolutions
    assert back.condition["rotation_hz"] == prof.rotation_hz and back.condition["speed_kmh"] == 40.0


def test_profile_keeps_every_stated_condition(tmp_path, rolling):
    """A recording's stated state (torque, tread depth, pressure, load: what ``identify`` reads from a profile's
    sidecar, docs/formats.md §3) reaches the profile it is averaged into; the rotation is the one measured."""
    import dataclasses

    stated = dict(rolling.condition, load_n=3200.0, pressure_bar=2.4, torque_nm=-195.5, tread_depth_mm=6.5,
                  rotation_hz=99.0)
    prof = rolling_profile(dataclasses.replace(rolling, condition=stated), points=POINTS)
    back = read_profile(write_profile(prof.to_profile(), tmp_path / "s.profile.csv"))
    for key in ("load_n", "pressure_bar", "torque_nm", "tread_depth_mm", "speed_kmh"):
        assert back.condition[key] == stated[key], key
    assert back.condition["rotation_hz"] == prof.rotation_hz != 99.0


def test_profile_errors(bench):
    short = bench.record(0.2, cleat=False)
    with pytest.raises(InputError, match="at least 2"):
        rolling_profile(short, points=64)
    rec = bench.record(2.0, cleat=False)
    with pytest.raises(InputError, match="got no samples"):
        rolling_profile(rec, points=8192)
    from ringfit.io.continuous import ContinuousRecord

    blind = ContinuousRecord(acc=np.zeros((1, 100)), axes=("radial",), fs_hz=FS)
    with pytest.raises(InputError, match="no encoder"):
        rolling_profile(blind)
