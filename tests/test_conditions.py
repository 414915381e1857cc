"""The consistency layer of stated conditions (ringfit.io.conditions) and the small checks of issue 34.

Expected values are closed forms or hand-made inputs, not the code under test.
"""

from __future__ import annotations

import json
import math
import os
from types import SimpleNamespace

import numpy as np
import pytest

from ringfit.errors import InputError
from ringfit.io.conditions import (check_profile_rotation, check_table_rotation, duplicate_inputs,
                                   pressure_conflict, rotation_speed_conflict, unique_inputs)
from ringfit.io.profiles import Profile

R_OUT = 0.316  # Table 9 ring radius 0.296 m + tread 0.020 m


def test_rotation_and_speed_agree_or_contradict_by_the_rolling_radius():
    v = 30 / 3.6
    for radius, contradicts in ((0.31, False), (0.316, False), (0.86 * R_OUT, False), (1.01 * R_OUT, False),
                                (0.84 * R_OUT, True), (1.03 * R_OUT, True), (0.1105, True)):
        rot = v / (2 * math.pi * radius)
        note = rotation_speed_conflict({"speed_kmh": 30.0, "rotation_hz": rot}, R_OUT)
        assert (note is not None) == contradicts, radius
    note = rotation_speed_conflict({"speed_kmh": 30.0, "rotation_hz": 12.0}, R_OUT)
    assert "rotation_hz = 12" in note and "speed_kmh = 30" in note
    assert f"{v / (2 * math.pi * 12.0):.3g} m" in note  # the rolling radius they imply
    # one of the two absent: nothing to compare
    assert rotation_speed_conflict({"speed_kmh": 30.0}, R_OUT) is None
    assert rotation_speed_conflict({"rotation_hz": 12.0}, R_OUT) is None
    with pytest.raises(InputError, match="rotation_hz = 12"):
        check_table_rotation({"speed_kmh": 30.0, "rotation_hz": 12.0}, R_OUT, source="t.modes.json")


def _patch_profile(omega, *, speed_kmh, rotation_hz, noise=0.0, patch=True, points=720, seed=0):
    """A hand-made rolling profile: centripetal level 0.75·Ω²·R_out outside, none inside a ±8° patch."""
    angle = -180.0 + 360.0 * np.arange(points) / points
    level = 0.75 * omega**2 * R_OUT
    radial = level * (1.0 - np.exp(-0.5 * (angle / 5.0) ** 8)) if patch else np.zeros(points)
    radial = radial - radial.mean() + noise * np.random.default_rng(seed).standard_normal(points)
    cond = {"speed_kmh": speed_kmh, "pressure_bar": 2.2, "load_n": 4000.0, "rotation_hz": rotation_hz}
    return Profile(angle, radial, np.zeros(points), condition=cond, source="x.profile.csv")


def test_a_profile_contradiction_is_settled_by_its_own_patch():
    speed = 50.0
    omega = speed / 3.6 / (0.98 * R_OUT)  # the truth: the speed is right
    ok = _patch_profile(omega, speed_kmh=speed, rotation_hz=omega / (2 * math.pi))
    same, note = check_profile_rotation(ok, R_OUT)
    assert same is ok and note is None
    # rotation_hz wrong (×2.5): the patch says the speed's Ω; rotation_hz is dropped (Ω = V/R_e then)
    bad_rot = _patch_profile(omega, speed_kmh=speed, rotation_hz=2.5 * omega / (2 * math.pi))
    fixed, note = check_profile_rotation(bad_rot, R_OUT)
    assert "rotation_hz" not in fixed.condition and "as speed_kmh says" in note
    assert bad_rot.condition["rotation_hz"] == pytest.approx(2.5 * omega / (2 * math.pi))  # the input untouched
    # speed_kmh wrong (×3): the patch agrees with the encoder's rotation_hz, which stays
    bad_speed = _patch_profile(omega, speed_kmh=3 * speed, rotation_hz=omega / (2 * math.pi))
    kept, note = check_profile_rotation(bad_speed, R_OUT)
    assert kept.condition["rotation_hz"] == pytest.approx(omega / (2 * math.pi)) and "as rotation_hz says" in note
    # no contact patch in the readings (noise): nothing tells which is right -> refused
    blind = _patch_profile(omega, speed_kmh=speed, rotation_hz=2.5 * omega / (2 * math.pi), noise=5.0, patch=False)
    with pytest.raises(InputError, match="correct the sidecar"):
        check_profile_rotation(blind, R_OUT)


def test_pressure_against_the_tyre_file():
    assert pressure_conflict({"pressure_bar": 2.25}, 2.2) is None  # 2.3 %: the same pressure
    assert pressure_conflict({}, 2.2) is None
    note = pressure_conflict({"pressure_bar": 3.5}, 2.2)
    assert "3.5" in note and "2.2" in note


def test_duplicates_by_path_symlink_and_content(tmp_path):
    a = tmp_path / "a.profile.csv"
    a.write_text("angle_deg\n1\n")
    (tmp_path / "a.profile.json").write_text(json.dumps({"load_n": 3000}))
    copy = tmp_path / "b.profile.csv"
    copy.write_text(a.read_text())
    (tmp_path / "b.profile.json").write_text(json.dumps({"load_n": 3000}))
    link = tmp_path / "0link.profile.csv"  # sorts first by name: the file is still the one kept
    os.symlink(a, link)
    os.symlink(tmp_path / "a.profile.json", tmp_path / "0link.profile.json")
    other = tmp_path / "c.profile.csv"
    other.write_text("angle_deg\n2\n")
    (tmp_path / "c.profile.json").write_text(json.dumps({"load_n": 3000}))
    assert [(k, d) for k, d, _ in duplicate_inputs([a, copy, link, other, a])] == [(0, 1), (0, 2), (0, 4)]
    kept, notes = unique_inputs([link, copy, a, other], lambda p: p.with_suffix(".json"), "profile")
    assert kept == [a, other] and len(notes) == 2
    assert any("0link.profile.csv" in n and "resolved path" in n for n in notes)
    assert any("b.profile.csv" in n and "SHA-256" in n for n in notes)
    # the same readings said to be measured at another load: refused, naming the copy
    (tmp_path / "b.profile.json").write_text(json.dumps({"load_n": 5000}))
    with pytest.raises(InputError, match="b.profile.csv.*load_n 3000 vs 5000"):
        unique_inputs([a, copy], lambda p: p.with_suffix(".json"), "profile")


def test_log_interval_never_overflows_and_stops_at_the_bounds():
    from ringfit.fit.identify import Z95, log_interval

    p = log_interval(2.0, 0.1, (0.001, 1000.0))
    assert p["lo95"] == pytest.approx(2.0 * math.exp(-Z95 * 0.1)) and p["hi95"] == pytest.approx(2.0 * math.exp(Z95 * 0.1))
    assert "to_bound" not in p
    wide = log_interval(0.5, 693.0, (0.001, 1000.0))  # the OverflowError of issue 34: e^(1.96·693)
    assert (wide["lo95"], wide["hi95"], wide["to_bound"]) == (0.001, 1000.0, ["lo", "hi"])
    below = log_interval(0.0005, 3.0, (0.001, 1000.0))  # a value past the bound keeps its interval around it
    assert below["lo95"] <= 0.0005 <= below["hi95"] and "lo" in below["to_bound"]
    none = log_interval(1.0, math.inf, (0.3, 30.0))
    assert none["sd_ln"] is None and (none["lo95"], none["hi95"]) == (0.3, 30.0)
    assert all(v is None or math.isfinite(v) for v in (none["value"], none["lo95"], none["hi95"]))


def test_cap_unbounded_gives_an_unbounded_parameter_the_plausible_spread():
    from ringfit.fit.identify import Z95, cap_unbounded
    from ringfit.fit.priors import BOUNDS

    cov = np.array([[0.01, 0.002, np.inf], [0.002, 0.04, np.inf], [np.inf, np.inf, np.inf]])
    out = cap_unbounded(cov, ("rho_a", "kw", "ei"))
    lo, hi = BOUNDS["ei"]
    assert out[2, 2] == pytest.approx((math.log(hi / lo) / (2 * Z95)) ** 2)
    assert out[0, 2] == out[2, 0] == 0.0 and out[1, 2] == 0.0
    np.testing.assert_array_equal(out[:2, :2], cov[:2, :2])  # the bounded ones untouched


def test_dashboard_address():
    from ringfit.batch import check_dashboard_address

    for bad in ("not an address", "", "host:99999", "host:port", "bad host!:8787"):
        with pytest.raises(InputError, match="--dashboard"):
            check_dashboard_address(bad)
    for local in ("127.0.0.1:8787", "localhost:8787", "[::1]:8787"):
        assert check_dashboard_address(local) is None
    for everywhere in ("0.0.0.0:8787", ":8787", "8787", "[::]:8787"):
        assert "every network interface" in check_dashboard_address(everywhere)
    assert "reachable from other machines" in check_dashboard_address("10.0.0.5:8787")


def test_cleat_ringing_windows_by_hand():
    from ringfit.fit.estimate.revolutions import _quiet

    # two revolutions of 0.1 s (10 Hz) centred at 0.05 s and 0.15 s, 4 grid angles each: read at t_mid + (j/4 − ½)/10
    block = SimpleNamespace(t_s=np.array([0.05, 0.15]), rotation_hz=np.array([10.0, 10.0]))
    arrivals = np.array([0.02, 0.12])
    quiet = _quiet(block, 4, arrivals, 0.04)
    # times: [0.0, 0.025, 0.05, 0.075] and [0.1, 0.125, 0.15, 0.175]; ringing [0.02, 0.06) and [0.12, 0.16)
    expected = np.array([[True, False, False, True], [True, False, False, True]])
    np.testing.assert_array_equal(quiet, expected)


@pytest.mark.slow
def test_the_patch_never_picks_the_wrong_rotation_over_many_operating_points():
    """Profiles of the rolling model (docs/physics.md §4–§5) at 16 random operating points — load 1.5–9 kN, speed
    20–110 km/h, flat road or a 0.5–2 m drum, 64–1024 angles, 1 % noise — with rotation_hz or speed_kmh wrong by a
    random factor 1.2–4: the contradiction is settled for the right value or refused, never for the wrong one,
    and one of 2.7× or more (Ω² 7×) is always settled."""
    from dataclasses import replace

    from ringfit.io.profiles import band_limited_resample, grid_angles_deg
    from ringfit.params import table9
    from ringfit.physics.profile import simulate_profile

    geometry, ring = table9()
    rng = np.random.default_rng(34)
    outcomes = {"right": 0, "refused": 0, "wrong": 0}
    for _ in range(16):
        load, speed = rng.uniform(1500, 9000), rng.uniform(20, 110)
        drum = None if rng.random() < 0.5 else float(rng.uniform(0.5, 2.0))
        points = int(rng.choice([64, 128, 512, 1024]))
        grid = simulate_profile(ring, geometry, speed_kmh=speed, load_n=load, drum_diameter_m=drum)
        radial = band_limited_resample(grid.channels, points)[0]
        radial = radial + 0.01 * np.std(radial) * rng.standard_normal(points)
        true_rot = float(grid.condition["rotation_hz"])
        base = Profile(grid_angles_deg(points), radial, np.zeros(points), source="p.profile.csv",
                       condition={"speed_kmh": speed, "rotation_hz": true_rot, "pressure_bar": 2.2})
        assert check_profile_rotation(base, float(geometry.outer_radius))[1] is None  # the truth agrees with itself
        for wrong in ("rotation_hz", "speed_kmh"):
            factor = float(rng.uniform(1.2, 4.0)) ** (1 if rng.random() < 0.5 else -1)
            cond = dict(base.condition, **{wrong: base.condition[wrong] * factor})
            prof = replace(base, condition=cond)
            if rotation_speed_conflict(cond, float(geometry.outer_radius)) is None:
                continue  # within the rolling radius's tolerance: no contradiction to settle
            try:
                out, _ = check_profile_rotation(prof, float(geometry.outer_radius))
            except InputError:
                outcomes["refused"] += 1
                assert max(factor, 1 / factor) < 2.7, (load, speed, drum, points, wrong, factor)
                continue
            kept_rotation = "rotation_hz" in out.condition
            right = kept_rotation == (wrong == "speed_kmh")
            outcomes["right" if right else "wrong"] += 1
    assert outcomes["wrong"] == 0, outcomes
    assert outcomes["right"] >= 20, outcomes  # 27 of 32 settled, 5 refused (factors below 2.7)


def test_a_stated_condition_is_contradicted_about_once_in_a_thousand_checks_when_it_is_true():
    """The stated value is the truth (the nominal speed: the truth off by its stated σ, 2 %) and the estimate a
    calibrated draw about it (normal for speed and torque, log-normal for load, pressure and depth, 95 % intervals
    of its σ): over 50,000 checks the share called a contradiction is the two-sided p of STATED_Z, 0.1 %, inside
    its Clopper–Pearson 99 % interval; a value 6 σ away is always one."""
    from scipy.stats import beta

    from ringfit.io.conditions import STATED_ESTIMATED, STATED_REL_SD, stated_against_estimate

    rng = np.random.default_rng(4)
    truth = {"load_n": 4000.0, "pressure_bar": 2.2, "tread_depth_mm": 6.0, "speed_kmh": 80.0, "torque_nm": 250.0}
    sd = {"load_n": 0.02, "pressure_bar": 0.015, "tread_depth_mm": 0.1, "speed_kmh": 0.3, "torque_nm": 20.0}
    n, flagged = 10_000, 0
    for _ in range(n):
        est = {}
        for key, log in STATED_ESTIMATED.items():
            e = rng.standard_normal()
            if log:
                v = truth[key] * math.exp(sd[key] * e)
                est[key] = {"value": v, "lo": v * math.exp(-1.96 * sd[key]), "hi": v * math.exp(1.96 * sd[key])}
            else:
                v = truth[key] + sd[key] * e
                est[key] = {"value": v, "lo": v - 1.96 * sd[key], "hi": v + 1.96 * sd[key]}
        stated = {k: v * (1.0 + STATED_REL_SD.get(k, 0.0) * rng.standard_normal()) for k, v in truth.items()}
        rows = stated_against_estimate(est, stated, source="run.profile.csv")
        assert len(rows) == len(STATED_ESTIMATED)
        flagged += sum(not r["consistent"] for r in rows)
    checks = n * len(STATED_ESTIMATED)
    lo, hi = beta.ppf(0.005, flagged, checks - flagged + 1), beta.ppf(0.995, flagged + 1, checks - flagged)
    assert lo <= 0.001 <= hi, (flagged, checks)
    far = stated_against_estimate({"load_n": {"value": 4000.0, "lo": 4000 * math.exp(-0.0392),
                                              "hi": 4000 * math.exp(0.0392)}}, {"load_n": 4000 * math.exp(0.12)})
    assert not far[0]["consistent"] and far[0]["z"] == pytest.approx(6.0, abs=0.01)


def test_only_what_the_data_read_is_compared_and_a_contradiction_names_the_file():
    from ringfit.io.conditions import stated_against_estimate

    est = {"load_n": {"value": 4000.0, "lo": 3920.0, "hi": 4080.0, "status": "estimated"},
           "pressure_bar": {"value": 2.2, "lo": 2.2, "hi": 2.2, "status": "fixed"},
           "tread_depth_mm": {"value": 5.0, "lo": 2.0, "hi": 9.0, "status": "not told"},
           "speed_kmh": {"value": 60.0, "lo": 59.9, "hi": 60.1}}
    rows = stated_against_estimate(est, {"load_n": 5000.0, "pressure_bar": 3.0, "tread_depth_mm": 1.0,
                                         "torque_nm": 100.0}, source="/x/run7.profile.csv")
    assert [r["quantity"] for r in rows] == ["load_n"]  # fixed, not told, and not estimated: not compared
    assert not rows[0]["consistent"] and rows[0]["z"] > 10
    assert rows[0]["sentence"].startswith("run7.profile.csv: the stated load_n = 5000 contradicts the data")
    assert stated_against_estimate(est, {}) == []


def test_a_stated_value_is_judged_by_the_interval_on_its_own_side():
    """An interval along a ridge or cut at a bound is not symmetric: a depth held at the new tread's 8 mm,
    [7.0, 8.0] mm, is consistent with a stated 7.5 mm (z = ln(7.5/8)/(ln(8/7)/1.96) ≈ −0.95) and contradicted by a
    stated 8.5 mm (no room above the bound); a load of 3,205 N in [3,197, 3,235] N takes σ from its upper side."""
    from ringfit.io.conditions import stated_against_estimate

    depth = {"tread_depth_mm": {"value": 8.0, "lo": 7.0, "hi": 8.0}}
    z = stated_against_estimate(depth, {"tread_depth_mm": 7.5})[0]["z"]
    assert z == pytest.approx(math.log(7.5 / 8.0) / (math.log(8.0 / 7.0) / 1.959964), abs=0.01)
    assert not stated_against_estimate(depth, {"tread_depth_mm": 8.5})[0]["consistent"]
    load = {"load_n": {"value": 3205.0, "lo": 3197.0, "hi": 3235.0}}
    up = stated_against_estimate(load, {"load_n": 3230.0})[0]["z"]
    assert up == pytest.approx(math.log(3230 / 3205) / (math.log(3235 / 3205) / 1.959964), abs=0.01)
    assert not stated_against_estimate(load, {"load_n": 3190.0})[0]["consistent"]  # 15 N below: σ there is 2 N
