"""The tyre's state in the forward model (docs/physics.md §13): pressure and tread laws, drive/brake in the brush.

Expected values come from outside the code: hand-computed laws, the closed-form slip stiffness of a rigid-carcass
brush (Pacejka, Tyre and Vehicle Dynamics, §3.2: C_Fκ = 2 c_px a²), finite differences, and the existing free-rolling
brush (BrushShearLoad without a given road length) for the null.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.io.tyre import InputError, read_tyre, write_tyre
from ringfit.params import BAR, RingParams, TyreLaws, table9
from ringfit.physics.contact import BrushShearLoad, ContactSolver, as_traced, patch_edges, solve_rolling_jit
from ringfit.physics.operating import OperatingPoint
from ringfit.physics.profile import ProfileModel, flat_or_drum, full_band, profile_channels
from ringfit.physics.state import TyreState, solve_state, state_solution, state_tyre

GEO, RING = table9()
LAWS = TyreLaws(tread_depth_ref=0.008, k_x=15e6, kw_share=0.5, kv_share=0.3, k_tread_share=0.2,
                has_tread_depth=True, has_brush=True)
OMEGA = 2 * math.pi * 10.0


def test_laws_at_the_reference_state_are_the_tyre_file_exactly():
    geo, ring, k_x = state_tyre(GEO, RING, LAWS, GEO.pressure, LAWS.tread_depth_ref)
    assert ring.as_dict() == RING.as_dict()
    assert (geo.radius, geo.width, geo.pressure, geo.tread_thickness) == (GEO.radius, GEO.width, GEO.pressure,
                                                                          GEO.tread_thickness)
    assert k_x == LAWS.k_x


def test_pressure_law_by_hand():
    p = 1.5 * GEO.pressure
    geo, ring, _ = state_tyre(GEO, RING, LAWS, p, LAWS.tread_depth_ref)
    assert float(ring.kw) == pytest.approx(RING.kw * (0.5 + 0.5 * 1.5), rel=1e-14)
    assert float(ring.kv) == pytest.approx(RING.kv * (0.7 + 0.3 * 1.5), rel=1e-14)
    assert float(ring.k_tread) == pytest.approx(RING.k_tread * (0.8 + 0.2 * 1.5), rel=1e-14)
    assert float(geo.pretension) == pytest.approx(3.3e5 * 0.152 * 0.296, rel=1e-14)  # T0 = p b R
    assert float(ring.ei) == RING.ei and float(ring.rho_a) == RING.rho_a


def test_tread_law_by_hand():
    d = 0.003  # worn from 8 to 3 mm
    geo, ring, k_x = state_tyre(GEO, RING, LAWS, GEO.pressure, d)
    tau = 0.020 - 0.005
    assert float(geo.tread_thickness) == pytest.approx(tau, rel=1e-14)
    assert float(geo.outer_radius) == pytest.approx(0.296 + tau, rel=1e-14)
    assert float(ring.k_tread) == pytest.approx(19e6 * 0.020 / tau, rel=1e-14)
    assert float(k_x) == pytest.approx(15e6 * 0.020 / tau, rel=1e-14)
    assert float(ring.rho_a) == pytest.approx(2.715 - 1100 * 0.152 * 0.7 * 0.005, rel=1e-14)
    # without the tread law the depth changes nothing
    geo2, ring2, _ = state_tyre(GEO, RING, LAWS.replace(has_tread_depth=False), GEO.pressure, d)
    assert ring2.as_dict() == RING.as_dict() and geo2.tread_thickness == GEO.tread_thickness


def _brush_channels(k_x, **brush):
    """The gap diagnosis's lever brush (free rolling by default) through profile_channels, at the reference, iterated
    as the state model iterates it (``BRUSH_PASSES`` relaxed passes)."""
    from ringfit.physics.state import BRUSH_PASSES, BRUSH_RELAXATION

    model = ProfileModel(hook_passes=BRUSH_PASSES, hook_relaxation=BRUSH_RELAXATION).with_load_hook(
        BrushShearLoad(k_x, lever=True, **brush))
    ch = profile_channels(*as_traced((model, RING, GEO)), np.array([OMEGA]), np.array([4000.0]), flat_or_drum(None, 1),
                          full_band(1, 512), 0.0, ContactSolver())
    return np.asarray(ch[0])


@pytest.mark.slow
def test_free_rolling_state_is_the_free_rolling_brush():
    _, ch, q = solve_state(GEO, RING, LAWS, TyreState(4000.0, GEO.pressure, 0.008, 0.0, OMEGA))
    np.testing.assert_allclose(ch, _brush_channels(15e6), rtol=0, atol=1e-9 * np.abs(ch).max())
    assert q["slip"] == 0.0 and q["r_free"] == q["r_road"]
    assert abs(q["fx"]) < 1e-4 * 4000.0  # the tips as a whole push no net force at free rolling
    # a slip κ is a road length per radian r_road = r_free/(1 + κ), r_free read on the driven patch (the brush
    # iterated to its fixed point: the patch under drive is not the free-rolling one, so r_free moves a little)
    _, ch_k, q_k = solve_state(GEO, RING, LAWS, TyreState(4000.0, GEO.pressure, 0.008, 0.02, OMEGA))
    assert q_k["r_road"] == pytest.approx(q_k["r_free"] / 1.02, rel=1e-9)
    assert q_k["r_free"] == pytest.approx(q["r_free"], rel=5e-3)  # 0.24 % at κ = 0.02 on Table 9
    # and given that r_road, the state is the same one (channels, Fx, κ)
    _, ch_r, q_r = solve_state(GEO, RING, LAWS, TyreState(4000.0, GEO.pressure, 0.008, 0.0, OMEGA,
                                                          r_road=float(q_k["r_road"])))
    np.testing.assert_allclose(ch_r, ch_k, rtol=0, atol=1e-5 * np.abs(ch_k).max())
    np.testing.assert_allclose(_brush_channels(15e6, r_road=float(q_k["r_road"])), ch_k, rtol=0,
                               atol=1e-5 * np.abs(ch_k).max())
    assert q_r["fx"] == pytest.approx(q_k["fx"], rel=1e-5)
    assert q_r["slip"] == pytest.approx(0.02, rel=1e-3)


def test_drive_and_brake_signs():
    drive = solve_state(GEO, RING, LAWS, TyreState(4000.0, GEO.pressure, 0.008, 0.01, OMEGA))[2]
    brake = solve_state(GEO, RING, LAWS, TyreState(4000.0, GEO.pressure, 0.008, -0.01, OMEGA))[2]
    assert drive["fx"] > 0.05 * 4000 and brake["fx"] < -0.05 * 4000  # SAE: κ > 0 drives forward
    assert drive["r_road"] < drive["r_free"] < brake["r_road"]  # driving: the road moves less per turn
    for q in (drive, brake):
        assert q["torque"] == pytest.approx(q["fx"] * q["axle_height"], rel=1e-12)  # T = Fx·H
        assert q["speed"] == pytest.approx(OMEGA * q["r_road"], rel=1e-12)  # V = Ω r_road
    # friction-limited: at a large slip the force saturates below μ Fz
    big = solve_state(GEO, RING, LAWS, TyreState(4000.0, GEO.pressure, 0.008, 0.5, OMEGA))[2]
    assert drive["fx"] < big["fx"] <= 1.0 * 4000 * 1.02


def test_slip_stiffness_of_a_rigid_carcass_brush():
    """Pacejka's brush on a rigid carcass: Fx = C κ at small slip, C = 2 c a² (c the tips' stiffness per unit road
    length, k_x·R/r_road; 2a the road length over which the tips stick, r_road·(φ_T − φ_L)); μ large: no sliding."""
    stiff = RingParams(rho_a=2.7, ei=1e3, kw=1e10, kv=1e10, damping_ratio=0.0, k_tread=19e6)
    laws = TyreLaws(k_x=15e6, friction=100.0, has_brush=True)
    solver = ContactSolver(n_grid=1024)
    lead, trail = (float(x) for x in patch_edges(solve_rolling_jit(stiff, GEO, OperatingPoint(60.0, 4000.0),
                                                                   solver=solver)))

    def q(kappa):
        return solve_state(GEO, stiff, laws, TyreState(4000.0, GEO.pressure, 0.008, kappa, 60.0), solver=solver)[2]

    k = 1e-3
    c_kappa = (q(k)["fx"] - q(-k)["fx"]) / (2 * k)
    r_road = q(0.0)["r_road"]
    a = 0.5 * r_road * (trail - lead)
    c_px = 15e6 * float(GEO.radius) / r_road
    assert c_kappa == pytest.approx(2 * c_px * a**2, rel=0.01)


@pytest.mark.slow
def test_gradients_against_finite_differences():
    """∂(Fx, r_free, H, channels)/∂(κ, ln p, d) by forward mode against central differences."""
    solver = ContactSolver(n_grid=256)
    geo, ring, laws = as_traced((GEO, RING, LAWS))

    @jax.jit
    def f(x):
        state = TyreState(4000.0, GEO.pressure * jnp.exp(x[1]), x[2], x[0], OMEGA)
        _, ch, q = state_solution(geo, ring, laws, state, solver=solver)
        return jnp.concatenate([jnp.stack([q.fx, 1e3 * q.r_free, 1e3 * q.axle_height]), ch[:, 120:136].ravel()])

    x0 = np.array([0.01, 0.1, 0.006])
    jac = np.asarray(jax.jacfwd(f)(x0))
    h = np.array([1e-4, 1e-4, 1e-6])
    for i in range(3):
        e = np.zeros(3)
        e[i] = h[i]
        fd = (np.asarray(f(x0 + e)) - np.asarray(f(x0 - e))) / (2 * h[i])
        scale = np.abs(fd).max()
        assert scale > 0
        np.testing.assert_allclose(jac[:, i], fd, rtol=0, atol=2e-3 * scale)


def test_tyre_file_state_keys_round_trip(tmp_path):
    src = tmp_path / "t.tyre.toml"
    src.write_text("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\ntread_depth_mm = 8.0\n"
                   "tread_density_kg_m3 = 1150.0\ntread_land_ratio = 0.65\n"
                   "[ring]\nkw_n_per_m2 = 1.294e6\nkx_n_per_m2 = 15e6\nfriction = 0.9\n"
                   "[ring.pressure]\nkw_share = 0.5\nkv_share = 0.3\n")
    tyre = read_tyre(src)
    laws = tyre.laws
    assert laws.has_tread_depth and laws.has_brush
    assert (laws.tread_depth_ref, laws.tread_density, laws.land_ratio, laws.k_x, laws.friction, laws.kw_share,
            laws.kv_share, laws.k_tread_share) == (0.008, 1150.0, 0.65, 15e6, 0.9, 0.5, 0.3, 0.0)
    out = write_tyre(tyre, tmp_path / "u.tyre.toml")
    assert read_tyre(out).laws == laws
    assert read_tyre(out).ring_values == tyre.ring_values


@pytest.mark.parametrize("text, match", [
    ("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\ntread_depth_mm = 80.0\n", "tread_depth_mm"),
    ("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\ntread_depth_mm = 25.0\n", "not below"),
    ("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\ntread_land_ratio = 1.5\n", "tread_land_ratio"),
    ("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n[ring]\nkx_n_per_m2 = -1\n", "kx_n_per_m2"),
    ("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n[ring]\nfriction = 'high'\n", "friction"),
    ("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n[ring.pressure]\nkw_share = 1.5\n", "kw_share"),
    ("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n[ring.pressure]\nkw_shar = 0.5\n",
     "did you mean 'kw_share'"),
    ("[tyre]\nradius_m = 0.296\nwidth_m = 0.152\npressure_bar = 2.2\n[ring]\npressure = 3\n", "ring.pressure"),
])
def test_tyre_file_state_keys_refused(tmp_path, text, match):
    path = tmp_path / "bad.tyre.toml"
    path.write_text(text)
    with pytest.raises(InputError, match=match) as info:
        read_tyre(path)
    assert "bad.tyre.toml" in str(info.value)


def test_condition_keys_torque_and_tread_depth(tmp_path):
    from ringfit.io.conditions import check_stated
    from ringfit.io.profiles import validate_condition

    cond = validate_condition({"speed_kmh": 60.0, "torque_nm": -250.0, "tread_depth_mm": 6.5})
    assert cond["torque_nm"] == -250.0 and cond["tread_depth_mm"] == 6.5
    with pytest.raises(InputError, match="torque_nm"):
        validate_condition({"speed_kmh": 60.0, "torque_nm": 3e6})
    with pytest.raises(InputError, match="tread_depth_mm"):
        validate_condition({"speed_kmh": 60.0, "tread_depth_mm": -1.0})

    class Item:  # a mode table's stated condition at another pressure
        condition = {"pressure_bar": 2.6}
        source = "m.modes.csv"

    with pytest.raises(InputError, match="pressure_bar = 2.6"):
        check_stated(Item(), GEO, source="m.modes.csv", other_pressure="refuse")
    _, notes = check_stated(Item(), GEO, source="m.modes.csv", other_pressure="refuse", pressure_law=True)
    assert notes == []
    assert BAR == 1e5


def test_the_lever_brush_is_iterated_to_its_fixed_point():
    """The brush's loads move the patch they are read on: the state model iterates them (BRUSH_PASSES relaxed
    steps). At a 2 % drive and brake slip its reading and Fx agree with twenty passes to 1e-4 and 1e-5, where the single
    step of the default ProfileModel is percent-level off (the size of the error the state model must not carry)."""
    import dataclasses

    import jax

    from ringfit.params import TyreLaws, table9
    from ringfit.physics.contact import ContactSolver
    from ringfit.physics.profile import ProfileModel
    from ringfit.physics.state import BRUSH_PASSES, TyreState, state_solution

    g, r = table9()
    laws = TyreLaws(k_x=15e6, friction=1.0, has_brush=True)
    solver = ContactSolver(n_grid=256, window_deg=35.0)

    def run(state, passes):
        # state_profile raises the passes to at least BRUSH_PASSES: reach below it by replacing afterwards
        model = ProfileModel(hook_passes=passes, hook_relaxation=0.85 if passes > 1 else 1.0)
        return jax.jit(lambda s: state_solution(g, r, laws, s, model=model, solver=solver))(state)

    for slip in (0.02, -0.02):
        st = TyreState(load=4000.0, pressure=float(g.pressure), tread_depth=0.008, slip=slip, omega=2 * np.pi * 9.0)
        _, ch6, q6 = run(st, BRUSH_PASSES)
        _, ch20, q20 = run(st, 20)
        scale = float(np.sqrt(np.mean(np.asarray(ch20[0]) ** 2)))
        assert float(np.max(np.abs(np.asarray(ch6) - np.asarray(ch20)))) < 1e-4 * scale
        assert abs(float(q6.fx) - float(q20.fx)) < 1e-5 * abs(float(q20.fx))
        one = ProfileModel()  # the gap diagnosis's single step, for scale: not converged
        from ringfit.physics.profile import rolling_passes
        from ringfit.physics.state import state_profile
        m, rs, gs = state_profile(g, r, laws, st)
        m1 = dataclasses.replace(m, hook_passes=1, hook_relaxation=1.0)
        from ringfit.physics.operating import FlatRoad, OperatingPoint
        _, _, ch1 = jax.jit(lambda: rolling_passes(m1, m1.ring(rs), gs, OperatingPoint(st.omega, st.load, FlatRoad()),
                                                   solver))()
        assert float(np.sqrt(np.mean((np.asarray(ch1[0]) - np.asarray(ch20[0])) ** 2))) > 5e-3 * scale
