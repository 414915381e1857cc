"""Profile side of the gap diagnosis: null exactness of every profile effect, closed-form checks off the null,
the noise estimate, incomplete folders, blind profile cases, the JSON contract and the CLI."""

import json
import math
import shutil

import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.cli import main
from ringfit.errors import InputError
from ringfit.gap import diagnose, read_case, read_diagnosis
from ringfit.gap import effects as lib
from ringfit.gap.profile import BASE, ProfileData, profile_predict
from ringfit.gap.profile_noise import profile_noise
from ringfit.params import table9
from ringfit.physics.contact import ContactSolver, as_traced
from ringfit.physics.operating import FlatRoad
from ringfit.synth.cases import coloured_noise, make_profile_case

SOLVER = ContactSolver(n_grid=256)
M = SOLVER.n_grid
PROFILE_EFFECTS = tuple(n for n in lib.BUILTIN if lib.get(n).speaks_to_profiles)


def _data(band_kmax=None):
    g, r = table9()
    omega = jnp.asarray([20.0, 45.0])
    band = np.ones((2, M // 2 + 1))
    band[:, -1] = 0.0
    if band_kmax is not None:
        band[:, band_kmax + 1:] = 0.0
    return ProfileData(ring=as_traced(r), geometry=as_traced(g), omega=omega, load=jnp.asarray([4000.0, 4000.0]),
                       roads=FlatRoad(), band=jnp.asarray(band)), g, r


def _predict(effects, values, data, k_tread=19e6, offset=0.0):
    sizes = tuple(len(e.params_for("profiles")) for e in effects)
    theta = jnp.asarray([k_tread, offset] + list(values))
    return np.asarray(profile_predict(theta, data, effects=effects, sizes=sizes, solver=SOLVER)).reshape(2, 2, M)


def test_profile_effect_set():
    # PHYSICS.md §6: these speak to rolling profiles; ground contact and the cavity do not
    assert set(PROFILE_EFFECTS) == {"sensor_tilt", "gravity", "iepe_highpass", "wave_damping", "tread_shear",
                                    "rotation", "sensor_mass", "ring_extensibility"}


def test_baseline_matches_rolling_fit_model():
    """The diagnosis's baseline is ringfit.fit.rolling's model (§6 baseline sensor, mean removed)."""
    from ringfit.fit.rolling import model_profiles

    data, g, r = _data()
    ours = _predict((), [], data, offset=0.01)
    ref = np.asarray(model_profiles(r, g, data.omega, data.load, FlatRoad(), 0.01, solver=SOLVER))
    np.testing.assert_allclose(ours, ref, atol=1e-9 * np.abs(ref).max())


@pytest.mark.parametrize("name", PROFILE_EFFECTS)
def test_null_is_baseline_profiles(name):
    data, _, _ = _data()
    e = lib.get(name)
    base = _predict((), [], data)
    null = _predict((e,), [p.null for p in e.params_for("profiles")], data)
    if name == "ring_extensibility":  # extensible form with EA = 1e12 N at the null (PHYSICS.md §4.2 test: ~1e-6)
        np.testing.assert_allclose(null, base, atol=1e-6 * np.abs(base).max())
    else:
        assert np.array_equal(null, base)
    off = _predict((e,), [p.start for p in e.params_for("profiles")], data)
    assert np.max(np.abs(off - base)) > 1e-6 * np.abs(base).max()  # and it does something off the null


def test_gravity_adds_the_1g_field():
    """PHYSICS.md §5 layer 3: radial (inward +) gains +g cos φ, tangential +g sin φ (both zero-mean)."""
    data, _, _ = _data()
    e = lib.get("gravity")
    d = _predict((e,), [1.0], data) - _predict((e,), [0.0], data)
    phi = -np.pi + 2 * np.pi * np.arange(M) / M
    np.testing.assert_allclose(d[:, 0], np.broadcast_to(9.81 * np.cos(phi), (2, M)), atol=1e-9)
    np.testing.assert_allclose(d[:, 1], np.broadcast_to(9.81 * np.sin(phi), (2, M)), atol=1e-9)


def test_highpass_gain_and_lead():
    """PHYSICS.md §5 layer 5: revolution harmonic k gets gain 1/√(1+(f_c/kf_rot)²) and lead atan(f_c/kf_rot).

    (k = 1 carries no acceleration for the inextensible ring — rigid translation, §4.6 — so k = 2, 3.)
    """
    data, _, _ = _data()
    e = lib.get("iepe_highpass")
    fc = 1.0
    a = np.fft.rfft(_predict((e,), [0.0], data), axis=-1)[..., 2:4]
    b = np.fft.rfft(_predict((e,), [fc], data), axis=-1)[..., 2:4]
    f = (np.asarray(data.omega) / (2 * np.pi))[:, None, None] * np.array([2.0, 3.0])
    ratio = b / a
    np.testing.assert_allclose(np.abs(ratio), np.broadcast_to(1 / np.sqrt(1 + (fc / f) ** 2), ratio.shape), rtol=1e-9)
    np.testing.assert_allclose(np.angle(ratio), np.broadcast_to(np.arctan(fc / f), ratio.shape), atol=1e-9)


def test_sensor_mass_is_the_belt_impedance_lowpass():
    """PHYSICS.md §6: Z/(Z + iωm_s), Z = 2√(T0 ρA), ω = kΩ."""
    data, g, r = _data()
    e = lib.get("sensor_mass")
    m = 0.02
    a = np.fft.rfft(_predict((e,), [0.0], data), axis=-1)
    b = np.fft.rfft(_predict((e,), [m], data), axis=-1)
    Z = 2 * math.sqrt(g.pressure * g.width * g.radius * r.rho_a)
    k = np.arange(1, 40)
    expect = Z / (Z + 1j * k[None, :] * np.asarray(data.omega)[:, None] * m)
    np.testing.assert_allclose(b[:, 0, 1:40] / a[:, 0, 1:40], expect, rtol=1e-8)


def test_rotation_speed_independence_only_at_chi_one():
    """PHYSICS.md §4.1: with χ = 1 (inextensible) the profiles scale exactly with Ω²; χ < 1 breaks it."""
    data, _, _ = _data()
    e = lib.get("rotation")
    base = _predict((e,), [0.0], data)
    w2 = (np.asarray(data.omega) ** 2)[:, None, None]
    np.testing.assert_allclose(base[0] / w2[0], base[1] / w2[1], atol=1e-9 * np.abs(base[1] / w2[1]).max())
    soft = _predict((e,), [0.7], data)
    assert np.max(np.abs(soft[0] / w2[0] - soft[1] / w2[1])) > 1e-3 * np.abs(soft[1] / w2[1]).max()


def test_band_limit_applies_to_the_model():
    data, _, _ = _data(band_kmax=50)
    y = _predict((), [], data)
    spec = np.fft.rfft(y, axis=-1)
    assert np.all(np.abs(spec[..., 51:]) < 1e-9 * np.abs(spec).max())


@pytest.mark.parametrize("colour", ["white", "pink", "band"])
def test_noise_estimate_recovers_known_sigma(colour):
    """Pure noise of known σ on four profiles: the far-side spectral estimate is within 15 %."""
    rng = np.random.default_rng(3)
    phi = -np.pi + 2 * np.pi * np.arange(512) / 512
    x = np.stack([[coloured_noise(rng, 512, s, colour) for _ in range(2)] for s in (0.5, 1.0, 1.5, 2.0)])
    x = x - x.mean(-1, keepdims=True)
    sigma, _ = profile_noise(x, phi, np.full(4, 255))
    true = np.sqrt(np.mean(np.stack([x[:, :, :], x])[0] ** 2, axis=-1))
    assert np.sqrt(np.mean(sigma**2)) == pytest.approx(np.sqrt(np.mean(true**2)), rel=0.15)


def test_incomplete_profile_folders(tmp_path):
    make_profile_case(tmp_path / "c", "none", seed=5)
    case = read_case(tmp_path / "c")
    assert len(case.profiles) == 4 and [p.speed_kmh for p in case.profiles] == sorted(p.speed_kmh for p in case.profiles)
    bad = tmp_path / "bad"
    shutil.copytree(tmp_path / "c", bad)
    (bad / "run1.profile.json").unlink()
    with pytest.raises(InputError, match="sidecar"):
        read_case(bad)
    shutil.rmtree(bad)
    shutil.copytree(tmp_path / "c", bad)
    text = (bad / "run2.profile.csv").read_text().splitlines()
    text[5] = text[5].split(",")[0] + ",abc,1.0"
    (bad / "run2.profile.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(InputError, match="row 6"):
        read_case(bad)


@pytest.mark.slow
def test_blind_profile_subset_json_and_cli(tmp_path, capsys):
    cases = [(2001, "sensor_tilt"), (2002, "gravity"), (2000, "none"), (2006, "tread_pitch")]
    for seed, effect in cases:
        label = make_profile_case(tmp_path / effect, effect, seed)
        d = diagnose(tmp_path / effect, progress=False)
        assert d.verdict["effect"] == label.expected_verdict, (effect, d.verdict)
        c = d.content
        assert {"data", "baseline", "where", "candidates", "verdict"} <= set(c)
        assert {"model", "rms", "unit", "heldout_rms"} <= set(c["baseline"])
        assert c["baseline"]["model"] == "gong-rolling" and c["baseline"]["unit"] == "m/s^2"
        assert sum(w["share"] for w in c["where"]) <= 1.0 + 1e-9
        assert all(w["region"].split()[0] in ("radial", "tangential") for w in c["where"])
        names = {x["effect"] for x in c["candidates"]}
        assert names == set(PROFILE_EFFECTS)
        for cand in c["candidates"]:
            assert {"effect", "rms", "heldout_rms", "shrink_pct", "heldout_shrink_pct", "evidence", "params"} <= set(cand)
        assert c["verdict"]["effects"][0] == c["verdict"]["effect"]
        if effect == "sensor_tilt":
            p = c["candidates"][0]["params"]["tilt_gain"]
            assert abs(p["value"] - label.magnitude["tilt_gain"]) < 0.05
            assert c["where"][0]["region"].startswith("tangential")
            ideal = 100 * (1 - label.noise["grid_rms_ms2"] / c["baseline"]["heldout_rms"])
            assert abs(c["candidates"][0]["heldout_shrink_pct"] - ideal) < 10
        if effect == "gravity":
            p = c["candidates"][0]["params"]["gravity_gain"]
            assert p["lo"] - 0.01 <= label.magnitude["gravity_gain"] <= p["hi"] + 0.01
    out = tmp_path / "g.diagnosis.json"
    report = tmp_path / "g.html"
    assert main(["diagnose", str(tmp_path / "gravity"), "--out", str(out), "--report", str(report), "--quiet"]) == 0
    back = read_diagnosis(out)
    assert back["verdict"]["effect"] == "gravity"
    assert json.loads(out.read_text())["data"][0].endswith(".csv")
    assert report.read_text().startswith("<!doctype html>")
    assert main(["diagnose", str(tmp_path / "gravity"), "--out", str(out), "--quiet"]) == 2  # exists
