"""The wheel on its suspension (docs/physics.md §6 ``wheel_suspension``): limits, an independent lumped
discretisation, the bordered loaded ring against Hill's method, the sidecar and the diagnosis effect."""

import math

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from ringfit.errors import InputError
from ringfit.gap import effects as lib
from ringfit.gap.modal_conditions import wheel_row
from ringfit.gap.modal_rows import ModalRows
from ringfit.io.modes import wheel_of
from ringfit.params import table9
from ringfit.physics import wheel as W
from ringfit.physics.loaded import loaded_angular_frequencies
from ringfit.physics.natural import natural_angular_frequencies
from ringfit.physics.rolling_modes import ContactArc, rolling_modes

TWO_PI = 2.0 * math.pi


def _lumped(ring, geometry, mass, inertia, kz, kx, kt, nodes=48):
    """Independent lumped model: ``nodes`` point masses ρA·R·dθ on a circle, each tied to a rigid hub by a
    radial spring k_w·R·dθ and a tangential one k_v·R·dθ, neighbours by stiff axial links (the belt);
    the hub (mass, inertia) on springs kz (vertical), kx (fore-aft), kt (torsion). Cartesian coordinates,
    one dense generalised eigenproblem. Returns every natural frequency [Hz], ascending."""
    R = geometry.radius
    dth = TWO_PI / nodes
    th = np.arange(nodes) * dth
    ndof = 2 * nodes + 3  # (x, y) per node, hub x, y, rotation
    K = np.zeros((ndof, ndof))
    Mm = np.zeros(ndof)
    Mm[: 2 * nodes] = ring.rho_a * R * dth
    Mm[2 * nodes:] = [mass, mass, inertia]
    hub = 2 * nodes

    def add(vec, k):  # spring of stiffness k on the relative coordinate vec·u
        K[:] += k * np.outer(vec, vec)

    for i, t in enumerate(th):
        er, et = np.array([math.cos(t), math.sin(t)]), np.array([-math.sin(t), math.cos(t)])
        for e, k in ((er, ring.kw * R * dth), (et, ring.kv * R * dth)):
            v = np.zeros(ndof)
            v[2 * i: 2 * i + 2] = e
            v[hub: hub + 2] = -e
            if e is et:
                v[hub + 2] = -R  # the hub's rotation moves the spring's root tangentially by Rβ
            add(v, k)
        j = (i + 1) % nodes  # axial link to the next node (a stiff belt: 1e3 × the foundation)
        d = np.array([math.cos(th[j]) - math.cos(t), math.sin(th[j]) - math.sin(t)])
        d /= np.linalg.norm(d)
        v = np.zeros(ndof)
        v[2 * j: 2 * j + 2], v[2 * i: 2 * i + 2] = d, -d
        add(v, 1e3 * ring.kw * R * dth)
    # hub supports: y is vertical, x fore-aft
    K[hub + 1, hub + 1] += kz
    K[hub, hub] += kx
    K[hub + 2, hub + 2] += kt
    lam = scipy.linalg.eigh(K, np.diag(Mm), eigvals_only=True)
    return np.sqrt(np.clip(lam, 0, None)) / TWO_PI


def test_free_free_closed_form_and_rigid_limit():
    g, r = table9()
    m_b, K1 = W.belt_translation(r, g)
    I_b, K0 = W.belt_torsion(r, g)
    w1 = natural_angular_frequencies(r, g, 1.0)
    w0 = natural_angular_frequencies(r, g, 0.0)
    assert float(K1) == pytest.approx(2.283e6, rel=1e-3)  # docs/physics.md §7
    # zero stiffness (free-free wheel): ω² = K(1/m_b + 1/m_w), docs/physics.md §6
    for mw in (5.0, 20.0, 60.0):
        o, _ = W.coupled_angular_frequency(w1, m_b, K1, mw, 1e12)
        assert float(o) == pytest.approx(math.sqrt(K1 * (1 / m_b + 1 / mw)), rel=1e-6)
        o, _ = W.coupled_angular_frequency(w0, I_b, K0, 0.5, 1e12)
        assert float(o) == pytest.approx(math.sqrt(K0 * (1 / I_b + 1 / 0.5)), rel=1e-6)
    # rigid fixture: exactly the rim-fixed ring; very stiff: within 1e-6
    o, z = W.coupled_angular_frequency(w1, m_b, K1, 20.0, 0.0)
    assert float(o) == float(w1) and float(z) == 0.0
    o, _ = W.coupled_angular_frequency(w1, m_b, K1, 20.0, 1e-13)
    assert float(o) == pytest.approx(float(w1), rel=1e-6)


@pytest.mark.parametrize("kz,kx,kt", [(2e5, 1e6, 1e5), (3e4, 3e4, 2e3), (5e6, 1e5, 1e6)])
def test_two_body_root_matches_lumped_discretisation(kz, kx, kt):
    g, r = table9()
    mass, inertia = 25.0, 0.7
    lumped = _lumped(r, g, mass, inertia, kz, kx, kt)
    m_b, K1 = W.belt_translation(r, g)
    I_b, K0 = W.belt_torsion(r, g)
    w1 = natural_angular_frequencies(r, g, 1.0)
    w0 = natural_angular_frequencies(r, g, 0.0)
    pred = [W.coupled_angular_frequency(w1, m_b, K1, mass, 1 / kz)[0],
            W.coupled_angular_frequency(w1, m_b, K1, mass, 1 / kx)[0],
            W.coupled_angular_frequency(w0, I_b, K0, inertia, 1 / kt)[0]]
    for p in pred:
        f = float(p) / TWO_PI
        nearest = lumped[np.argmin(np.abs(lumped - f))]
        assert abs(nearest - f) / f < 1e-3, (f, nearest)


@pytest.mark.slow  # > 10 s: CI runs it with -m slow (issue 24 item 3)
def test_bordered_loaded_ring_rigid_limit_and_hill_at_rest():
    g, r = table9()
    a = math.radians(11.69)
    nb = 12
    c0, s0 = loaded_angular_frequencies(r, g, a, nb)
    rigid = W.Wheel.from_stiffness(20.0, 0.6, math.inf, math.inf, math.inf)
    c1, s1 = W.loaded_wheel_angular_frequencies(r, g, a, rigid, nb)
    assert np.array_equal(np.asarray(c0), np.asarray(c1)) and np.array_equal(np.asarray(s0), np.asarray(s1))
    stiff = W.Wheel.from_stiffness(20.0, 0.6, 1e13, 1e13, 1e13)
    c2, s2 = W.loaded_wheel_angular_frequencies(r, g, a, stiff, nb)
    np.testing.assert_allclose(np.asarray(c2), np.asarray(c0), rtol=1e-6)
    # a real suspension: the bordered real basis against Hill's complex basis at Ω = 0 (another discretisation
    # of the same ring: complex harmonics −K…K, the body as p±, Rβ)
    wheel = W.Wheel.from_stiffness(20.0, 0.6, 2e5, 1e6, 1e5)
    c3, s3 = W.loaded_wheel_angular_frequencies(r, g, a, wheel, nb)
    hill = np.sort(np.asarray(rolling_modes(r, g, 0.0, ContactArc.symmetric(a, r.k_tread), harmonics=nb,
                                            wheel=wheel).angular_frequency))
    for f in (c3[0], s3[0], c3[1], s3[1]):
        assert np.min(np.abs(hill - float(f))) / float(f) < 1e-3
    # the n = 1 pair splits under load, and differs from the rim-fixed pair
    assert abs(float(c3[0] - s3[0])) / TWO_PI > 0.3
    assert abs(float(c3[0] - c0[0])) / TWO_PI > 1.0
    # the body's own (bounce) mode is below the ring's modes and absent from the returned ring modes
    assert np.all(np.asarray(c3) > 2 * TWO_PI * 20)


# ~13 s (the Hill model with the wheel, compiled for this test alone); the two-body root against the
# lumped model stays in the default run
@pytest.mark.slow
def test_hill_free_ring_with_wheel_matches_lumped():
    g, r = table9()
    wheel = W.Wheel.from_stiffness(25.0, 0.7, 2e5, 1e6, 1e5)
    modes = rolling_modes(r, g, 0.0, ContactArc.none(), harmonics=3, wheel=wheel)
    order = np.asarray(modes.order)
    hill = np.asarray(modes.freq_hz)[order <= 1]  # the bending-free modes the lumped model also has
    assert hill.size == 6  # three body-dominated modes, the n = 0 mode and the n = 1 pair
    lumped = _lumped(r, g, 25.0, 0.7, 2e5, 1e6, 1e5)
    for f in hill:
        assert np.min(np.abs(lumped - f)) / f < 1e-3, f


def test_sidecar_fixture_keys():
    assert wheel_of({}) is None and wheel_of({"fixture": "bolted"}) is None
    w = wheel_of({"fixture": "suspension", "wheel_mass_kg": 30, "suspension_stiffness_n_m": [1e5, 4e5]})
    assert (w["mass"], w["k_vertical"], w["k_fore_aft"]) == (30.0, 1e5, 4e5)
    assert set(w["defaults"]) == {"wheel_inertia_kg_m2", "suspension_torsion_n_m_rad"}
    w = wheel_of({"fixture": "suspension", "suspension_stiffness_n_m": 2e5})
    assert w["k_vertical"] == w["k_fore_aft"] == 2e5
    with pytest.raises(InputError, match="'fixture'"):
        wheel_of({"fixture": "clamped"}, source="t.modes.json")
    with pytest.raises(InputError, match="wheel_mass_kg.*needs 'fixture'"):
        wheel_of({"wheel_mass_kg": 20}, source="t.modes.json")
    with pytest.raises(InputError, match="suspension_stiffness_n_m"):
        wheel_of({"fixture": "suspension", "suspension_stiffness_n_m": [1, 2, 3]})
    with pytest.raises(InputError, match="wheel_mass_kg"):
        wheel_of({"fixture": "suspension", "wheel_mass_kg": -1})
    assert wheel_row({}) == [0.0] * 9


def _rows(n, contact, wheel, patch=0.0, freq=None, is_freq=None):
    m = len(n)
    return ModalRows(
        n=jnp.asarray(n, dtype=jnp.float64), is_freq=jnp.asarray(is_freq if is_freq is not None else [1.0] * m),
        contact=jnp.asarray(contact, dtype=jnp.int32), spin=jnp.zeros(m), branch=jnp.zeros(m),
        fixed_frame=jnp.zeros(m), cavity_hz=jnp.asarray(218.75), reference=jnp.zeros(m),
        patch=jnp.where(jnp.asarray(contact) > 0, patch, 0.0),
        freq_hz=jnp.asarray(freq if freq is not None else [110.0] * m), table=jnp.zeros(m, dtype=jnp.int32),
        table_patch=jnp.asarray([patch]), wheel=jnp.asarray([wheel] * m),
        contact_tables=(0,) if patch > 0 else ())


def test_effect_null_bolted_and_computed():
    g, r = table9()
    e = lib.get("wheel_suspension")
    cond = {"fixture": "suspension", "wheel_mass_kg": 20, "wheel_inertia_kg_m2": 0.6,
            "suspension_stiffness_n_m": [2e5, 1e6], "suspension_torsion_n_m_rad": 1e5}
    wrow = wheel_row(cond)
    n = [0.0, 1.0, 1.0, 2.0, 5.0]
    rows = _rows(n, [0, 0, 0, 0, 0], wrow, freq=[104.0, 119.9, 121.0, 120.0, 190.0])
    omega = natural_angular_frequencies(r, g, rows.n)
    zeta = jnp.full_like(omega, 0.02)
    o0, z0 = e.modal(jnp.asarray([0.0]), omega, zeta, rows, r, g)
    assert np.array_equal(np.asarray(o0), np.asarray(omega)) and np.array_equal(np.asarray(z0), np.asarray(zeta))
    bolted = _rows(n, [0] * 5, wheel_row({}))
    ob, _ = e.modal(jnp.asarray([1.0]), omega, zeta, bolted, r, g)
    assert np.array_equal(np.asarray(ob), np.asarray(omega))
    assert not np.any(e.modal_mask(bolted)) and list(e.modal_mask(rows)) == [True, True, True, False, False]
    o1, _ = e.modal(jnp.asarray([1.0]), omega, zeta, rows, r, g)
    o1 = np.asarray(o1)
    m_b, K1 = W.belt_translation(r, g)
    I_b, K0 = W.belt_torsion(r, g)
    vz = float(W.coupled_angular_frequency(omega[1], m_b, K1, 20.0, 1 / 2e5)[0])
    vx = float(W.coupled_angular_frequency(omega[1], m_b, K1, 20.0, 1 / 1e6)[0])
    tor = float(W.coupled_angular_frequency(omega[0], I_b, K0, 0.6, 1 / 1e5)[0])
    # untagged n = 1 rows take the nearer line; higher n never move
    assert o1[0] == pytest.approx(tor, rel=1e-12)
    assert o1[1] == pytest.approx(vz, rel=1e-12) and o1[2] == pytest.approx(vx, rel=1e-12)
    assert np.array_equal(o1[3:], np.asarray(omega)[3:])


def test_effect_on_loaded_rows_with_ground_contact_is_the_bordered_model():
    g, r = table9()
    a = math.radians(11.69)
    cond = {"fixture": "suspension", "wheel_mass_kg": 20, "suspension_stiffness_n_m": [2e5, 1e6]}
    rows = _rows([1.0, 1.0, 2.0, 2.0], [1, 2, 1, 2], wheel_row(cond), patch=a)
    omega = natural_angular_frequencies(r, g, rows.n)
    zeta = jnp.zeros_like(omega)
    e = lib.get("wheel_suspension")
    assert list(e.modal_mask(rows)) == [True] * 4
    o, _ = lib.get("ground_contact").modal(jnp.asarray([1.0]), omega, zeta, rows, r, g)
    o, _ = e.modal(jnp.asarray([1.0]), o, zeta, rows, r, g)
    w = W.Wheel.from_stiffness(20.0, 0.6, 2e5, 1e6, 1e5)
    c, s = W.loaded_wheel_angular_frequencies(r, g, a, w)  # 40 harmonics: the effect's 20 agree to 0.01 Hz
    expect = np.array([c[0], s[0], c[1], s[1]]) / TWO_PI
    np.testing.assert_allclose(np.asarray(o) / TWO_PI, expect, atol=0.01)


def test_support_damping_adds_to_damping_rows():
    g, r = table9()
    cond = {"fixture": "suspension", "wheel_mass_kg": 20, "suspension_stiffness_n_m": 2e5,
            "suspension_damping_n_s_m": 2000.0}
    rows = _rows([1.0], [1], wheel_row(cond), freq=[120.0], is_freq=[0.0])
    omega = jnp.asarray([TWO_PI * 120.0])
    o, z = lib.get("wheel_suspension").modal(jnp.asarray([1.0]), omega, jnp.asarray([0.02]), rows, r, g)
    assert float(o[0]) == float(omega[0]) and float(z[0]) > 0.02


@pytest.mark.slow  # end to end, > 7 s: CI runs it with -m slow (issue 24 item 3)
def test_blind_case_from_the_lumped_model_is_recovered(tmp_path):
    """A case whose suspended table's n ≤ 1 truth comes from the lumped discretisation of
    :func:`ringfit.synth.cases.lumped_wheel_modes` (not the effect's two-body root): the diagnosis names
    wheel_suspension, and the fitted compliance scale's interval holds 1 (the fixture as stated)."""
    from ringfit.gap import diagnose
    from ringfit.synth.cases import make_case

    label = make_case(tmp_path / "c", "wheel_suspension", seed=1005)
    d = diagnose(tmp_path / "c", progress=False)
    assert d.verdict["effect"] == "wheel_suspension", d.verdict
    fitted = [c for c in d.content["candidates"] if c["effect"] == "wheel_suspension" and c["variant"] == "fitted"]
    p = fitted[0]["params"]["compliance_scale"]
    assert p["lo"] < 1.0 < p["hi"]
    assert label.magnitude["wheel_mass_kg"] > 0


def test_lumped_truth_matches_the_two_body_root():
    from ringfit.synth.cases import lumped_wheel_modes

    g, r = table9()
    truth = lumped_wheel_modes(r, g, 35.0, 0.9, 5e4, 3e6, 3e4)
    m_b, K1 = W.belt_translation(r, g)
    I_b, K0 = W.belt_torsion(r, g)
    w1, w0 = natural_angular_frequencies(r, g, 1.0), natural_angular_frequencies(r, g, 0.0)
    assert truth["vertical"] == pytest.approx(float(W.coupled_angular_frequency(w1, m_b, K1, 35.0, 1 / 5e4)[0]) / TWO_PI,
                                              rel=1e-3)
    assert truth["fore_aft"] == pytest.approx(float(W.coupled_angular_frequency(w1, m_b, K1, 35.0, 1 / 3e6)[0]) / TWO_PI,
                                              rel=1e-3)
    assert truth["torsion"] == pytest.approx(float(W.coupled_angular_frequency(w0, I_b, K0, 0.9, 1 / 3e4)[0]) / TWO_PI,
                                             rel=1e-3)


@pytest.mark.slow  # end to end, > 7 s: CI runs it with -m slow (issue 24 item 3)
def test_campbell_diagram_with_the_wheel_at_rest_is_the_bordered_loaded_ring():
    """`campbell_diagram(..., wheel=)` (Hill's complex basis, the patch of the contact solve) at speed 0: its
    n = 1 branches are the bordered real-basis loaded ring's at the same patch."""
    from ringfit.physics.campbell import campbell_diagram

    g, r = table9()
    wheel = W.Wheel.from_stiffness(20.0, 0.6, 2e5, 1e6, 1e5)
    d = campbell_diagram(r, g, 4000.0, [0.0], n_max=4, harmonics=8, wheel=wheel)
    a = 0.5 * math.radians(float(d.trailing_deg[0] - d.leading_deg[0]))
    c, s = W.loaded_wheel_angular_frequencies(r, g, a, wheel, n_max=8)
    f = np.asarray(d.fixed_hz[0])
    for x in (float(c[0]), float(s[0])):
        assert np.min(np.abs(f - x / TWO_PI)) / (x / TWO_PI) < 2e-3
    rigid = campbell_diagram(r, g, 4000.0, [0.0], n_max=4, harmonics=8)
    assert d.branches >= rigid.branches + 2  # the body's modes
