"""``ringfit estimate --state`` (docs/formats.md §7.1): a profile and a continuous recording of the forward model at
known hidden states (no load, pressure, torque or depth stated), the JSON, the per-revolution CSV and the bad inputs."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from ringfit.cli import main
from ringfit.data import path as data_path
from ringfit.io.continuous import ContinuousRecord
from ringfit.io.profiles import Profile, grid_angles_deg, write_profile
from ringfit.io.continuous import write_continuous
from ringfit.io.tyre import read_tyre, write_tyre
from ringfit.physics.contact import ContactSolver
from ringfit.physics.profile import ProfileModel
from ringfit.physics.sensor import STANDARD_GRAVITY
from ringfit.physics.state import TyreState, solve_state

F_ROT = 12.0
SENSOR = ProfileModel().with_sensor(gravity=STANDARD_GRAVITY, tilt_gain=0.8, corner_hz=0.5)


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """A tyre file with the state laws, a profile and a recording at hidden states (the truths returned)."""
    root = tmp_path_factory.mktemp("state_cli")
    tyre = read_tyre(data_path("table9.tyre.toml")).with_state_values(tread_depth_mm=8.0, kx_n_per_m2=15e6,
                                                                     kw_share=0.5, kv_share=0.3)
    write_tyre(tyre, root / "t.tyre.toml")
    om = 2 * math.pi * F_ROT
    rng = np.random.default_rng(3)
    # a profile: driving at 2.5 bar, 6 mm
    # (solved on 2048 angles, four times the estimate's grid, whose model the estimate fits: docs/physics.md §13.4)
    _, ch, q_p = solve_state(tyre.geometry, tyre.ring, tyre.laws, TyreState(4500.0, 2.5e5, 0.006, 0.01, om),
                             model=SENSOR, solver=ContactSolver(n_grid=2048))
    ch = np.asarray(ch)[:, ::4]
    ch = ch + np.array([[1.0], [0.15]]) * rng.standard_normal(ch.shape)
    write_profile(Profile(grid_angles_deg(512), ch[0], ch[1], condition={"speed_kmh": 82.0, "rotation_hz": F_ROT}),
                  root / "p.profile.csv")
    # a recording: braking at 2.0 bar, 5 mm, 30 revolutions sampled in time with white noise
    _, ch, q_r = solve_state(tyre.geometry, tyre.ring, tyre.laws, TyreState(4200.0, 2.0e5, 0.005, -0.006, om),
                             model=SENSOR, solver=ContactSolver(n_grid=2048))
    ch = np.asarray(ch)[:, ::4]
    spec = np.fft.rfft(ch, axis=1) * 2 / ch.shape[1]
    fs = F_ROT * 1024
    t = np.arange(int(30 * fs / F_ROT)) / fs
    ang = -37.0 + 360 * F_ROT * t
    w = np.radians(ang) + np.pi  # φ on the grid φ_j = −π + 2πj/M
    x = sum((spec[:, k, None] * np.exp(1j * k * w[None, :])).real for k in range(1, 64))
    x = x + np.array([[2.0], [0.3]]) * rng.standard_normal(x.shape)
    rec = ContinuousRecord(acc=x, axes=("radial", "tangential"), fs_hz=fs, encoder_angle_deg=ang,
                           condition={"speed_kmh": 83.0}, source="synthetic")
    write_continuous(rec, root / "r.records.npz")
    return root, q_p, q_r


@pytest.fixture(scope="module")
def serial(case):
    """The serial commands' outputs, once per module (each state estimate is ~40 s of one core): the profile's
    JSON, and the recording's JSON, per-revolution CSV and plot. The batch test compares its worker's answers
    with the same JSONs (its plan's options are these commands' less the per-revolution CSV and plot, which add
    to the JSON and change no quantity)."""
    root, _, _ = case
    tyre = str(root / "t.tyre.toml")
    out = root / "serial"
    out.mkdir()
    assert main(["estimate", str(root / "p.profile.csv"), "--tyre", tyre, "--out", str(out / "p.estimate.json"),
                 "--state", "--quiet"]) == 0
    assert main(["estimate", str(root / "r.records.npz"), "--tyre", tyre, "--out", str(out / "r.estimate.json"),
                 "--state", "--per-revolution", str(out / "r.revs.csv"), "--plot", str(out / "r.png"),
                 "--quiet"]) == 0
    return out


@pytest.mark.slow
def test_state_of_a_profile_and_a_recording(case, serial, capsys):
    root, q_p, q_r = case
    doc = json.loads((serial / "p.estimate.json").read_text())
    Q = doc["state"]["quantities"]
    for key, value in (("load_n", 4500.0), ("pressure_bar", 2.5), ("slip", 0.01), ("fx_n", q_p["fx"]),
                       ("tread_depth_mm", 6.0), ("speed_kmh", q_p["speed"] * 3.6)):
        assert Q[key]["lo"] <= value <= Q[key]["hi"], (key, Q[key])
    assert doc["state"]["fit"]["channels"] == ["radial", "tangential"]
    assert "load_n" in doc  # the load-only estimate keeps its keys
    assert isinstance(doc["state"]["not_told_apart"], list)
    # pressure held at a TPMS reading
    out2 = root / "p2.estimate.json"
    assert main(["estimate", str(root / "p.profile.csv"), "--tyre", str(root / "t.tyre.toml"), "--out", str(out2),
                 "--state", "--fix", "pressure_bar=2.5", "--quiet"]) == 0
    Q2 = json.loads(out2.read_text())["state"]["quantities"]
    assert Q2["pressure_bar"]["status"] == "fixed" and Q2["pressure_bar"]["value"] == pytest.approx(2.5)

    # the recording: JSON, per-revolution CSV with each quantity and its interval, plot
    revs = serial / "r.revs.csv"
    png = serial / "r.png"
    doc = json.loads((serial / "r.estimate.json").read_text())
    Q = doc["state"]["quantities"]
    for key, value in (("load_n", 4200.0), ("pressure_bar", 2.0), ("slip", -0.006), ("fx_n", q_r["fx"]),
                       ("speed_kmh", q_r["speed"] * 3.6)):
        assert Q[key]["lo"] <= value <= Q[key]["hi"], (key, Q[key])
    assert abs(Q["load_n"]["value"] / 4200 - 1) < 0.005 and abs(Q["fx_n"]["value"] - q_r["fx"]) < 0.02 * 4200
    assert doc["state"]["per_revolution"]["revolutions"] >= 28
    with open(revs) as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == doc["state"]["per_revolution"]["revolutions"]
    for key in ("load_n", "pressure_bar", "slip", "fx_n", "tread_depth_mm", "speed_kmh"):
        assert {key, key + "_lo", key + "_hi"} <= set(rows[0])
    loads = np.array([float(r["load_n"]) for r in rows])
    inside = np.mean([float(r["load_n_lo"]) <= 4200.0 <= float(r["load_n_hi"]) for r in rows])
    assert abs(np.median(loads) / 4200 - 1) < 0.005 and inside >= 0.8
    assert png.stat().st_size > 10_000


@pytest.mark.parametrize("extra, match", [
    (["--fix", "pressure_bar=2.4"], "needs --state"),
    (["--state", "--fix", "pressure=2.4"], "NAME one of"),
    (["--state", "--fix", "pressure_bar=24"], "plausible range"),
    (["--state", "--fix", "pressure_bar=high"], "not a number"),
    (["--state", "--fix", "tread_depth_mm=stated"], "states no tread_depth_mm"),
])
def test_bad_state_options_are_refused_before_anything_is_written(tmp_path, capsys, extra, match):
    tyre = read_tyre(data_path("table9.tyre.toml"))
    write_tyre(tyre, tmp_path / "t.tyre.toml")
    angle = grid_angles_deg(64)
    write_profile(Profile(angle, np.cos(np.radians(angle)), np.sin(np.radians(angle)), condition={"speed_kmh": 50.0}),
                  tmp_path / "p.profile.csv")
    out = tmp_path / "p.estimate.json"
    code = main(["estimate", str(tmp_path / "p.profile.csv"), "--tyre", str(tmp_path / "t.tyre.toml"), "--out",
                 str(out), *extra])
    assert code == 2
    assert match in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.slow
def test_batch_runs_the_state_estimate_over_many_recordings(case, serial, tmp_path, monkeypatch, capsys):
    """issue 33 item 7: ``ringfit batch estimate … -- --state`` on a worker gives each input's state, the same
    as the serial command to a tenth of its σ (a profile and a continuous recording)."""
    import os

    from ringfit.batch import local_cluster
    from ringfit.cli.batch import plan_batch

    root, q_p, q_r = case
    monkeypatch.chdir(tmp_path)
    inputs = [os.path.relpath(root / "p.profile.csv"), os.path.relpath(root / "r.records.npz")]
    opts = ["--tyre", str(root / "t.tyre.toml"), "--state"]
    cl = local_cluster(1, memory_limit="4GB")
    try:
        status = main(["batch", "estimate", *inputs, "--out", "batch", "--scheduler", cl.scheduler_address,
                       "--quiet", "--", *opts])
    finally:
        cl.close()
    assert status == 0, capsys.readouterr().out
    for plan in plan_batch("estimate", inputs, tmp_path / "plan", opts):  # the serial commands' names (fixture)
        name = Path(plan.outputs[0]).name
        got, want = (json.loads((d / name).read_text())["state"]["quantities"] for d in (Path("batch"), serial))
        for key in ("load_n", "pressure_bar", "fx_n", "tread_depth_mm", "speed_kmh"):
            # the same answer to a tenth of its σ: not to the bit, since the serial command's XLA reductions are
            # multi-threaded (the workers' are not), and on the flat load–depth ridge their last bits moved the
            # load by 0.04 % (0.08 σ) on a loaded machine
            tol = 0.1 * want[key]["sd"]
            assert got[key]["value"] == pytest.approx(want[key]["value"], abs=tol), (name, key)
            assert got[key]["lo"] == pytest.approx(want[key]["lo"], abs=tol), (name, key)
    truth = json.loads((Path("batch") / "r.estimate.json").read_text())["state"]["quantities"]
    assert truth["load_n"]["lo"] <= 4200.0 <= truth["load_n"]["hi"]
