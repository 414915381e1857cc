"""Natural-frequency models against docs/physics.md §7 and the source study's tables."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ringfit  # noqa: F401
from ringfit.demo import read_table10
from ringfit.params import table9
from ringfit.physics import natural as N

GEO, RING = table9()
TAB10 = read_table10()


def test_eq18_reproduces_table10_within_0p05_hz():
    f = np.asarray(N.natural_frequencies(RING, GEO, TAB10["n"]))
    np.testing.assert_allclose(f, TAB10["simulated_hz"], atol=0.05)


def test_eq18_physics_md_values_n0_to_10():
    expected = [104.08, 107.02, 119.84, 140.01, 164.69, 192.31, 222.03, 253.41, 286.20, 320.30, 355.66]
    np.testing.assert_allclose(N.natural_frequencies(RING, GEO, np.arange(11)), expected, atol=0.006)


def test_n0_is_rigid_rotation_and_n1_rigid_translation():
    # ω0² = kv/ρA ; n = 1: d_1 = kw + kv, ω1² = (kw + kv)/(2ρA) — EI and p0 drop out.
    f0 = np.sqrt(RING.kv / RING.rho_a) / (2 * np.pi)
    f1 = np.sqrt((RING.kw + RING.kv) / (2 * RING.rho_a)) / (2 * np.pi)
    assert float(N.natural_frequencies(RING, GEO, 0)) == pytest.approx(f0, rel=1e-12)
    assert float(N.natural_frequencies(RING.replace(ei=123.0), GEO, 1)) == pytest.approx(f1, rel=1e-12)
    # translation stiffness πR(kw + kv) = 2.283e6 N/m (docs/physics.md §7)
    assert np.pi * GEO.radius * (RING.kw + RING.kv) == pytest.approx(2.283e6, rel=1e-3)


def test_extensible_tends_to_inextensible():
    n = np.arange(1, 10)
    inext = np.asarray(N.natural_frequencies(RING, GEO, n))
    prev = np.inf
    for ea in (1e5, 1e6, 1e8, 1e12):
        flex = np.asarray(N.extensible_natural_frequencies(RING.replace(ea=ea), GEO, n))[:, 0]
        gap = np.max(np.abs(flex - inext))
        assert gap < prev
        prev = gap
    assert prev < 1e-6
    # docs/physics.md §2.2 sensitivity: within 0.3 Hz at EA = 1e5 N, 0.03 Hz at 1e6 N
    for ea, tol in ((1e5, 0.32), (1e6, 0.03)):  # "≈0.3 Hz" at 1e5 N
        flex = np.asarray(N.extensible_natural_frequencies(RING.replace(ea=ea), GEO, n))[:, 0]
        assert np.max(np.abs(flex - inext)) < tol


def test_ring_modal_mass_is_the_kinetic_energy_of_the_mode():
    # independent: M_n = ∫ ρA (w² + v²) R dθ over one revolution for w = cos nθ, v = sin nθ / n (w + v′ = 0),
    # and the rigid rotation v = 1 (n = 0); docs/physics.md §1: ring mass 2πRρA = 5.049 kg.
    theta = np.linspace(0.0, 2 * np.pi, 4097)[:-1]
    R, rho_a = float(GEO.radius), float(RING.rho_a)
    for n in (1, 2, 3, 7):
        w, v = np.cos(n * theta), np.sin(n * theta) / n
        expect = rho_a * R * np.mean(w**2 + v**2) * 2 * np.pi
        assert float(N.ring_modal_mass(RING, GEO, n)) == pytest.approx(expect, rel=1e-12)
    assert float(N.ring_modal_mass(RING, GEO, 0)) == pytest.approx(5.049, abs=5e-4)
    # eq. 18 is K_n / M_n with K_n = πR d_n (the loaded-tyre basis, docs/physics.md §6)
    n = np.arange(1, 8)
    d_n = np.asarray(N.modal_stiffness(RING, GEO, n)) / n**2
    omega = 2 * np.pi * np.asarray(N.natural_frequencies(RING, GEO, n))
    np.testing.assert_allclose(np.pi * R * d_n / np.asarray(N.ring_modal_mass(RING, GEO, n)), omega**2, rtol=1e-12)


def test_extensible_flexural_shift_is_the_2x2_eigenproblem():
    n = np.arange(1, 10)
    omega18 = 2 * np.pi * np.asarray(N.natural_frequencies(RING, GEO, n))
    for ea in (2e4, 1e5, 1e6):
        flex = 2 * np.pi * np.asarray(N.extensible_natural_frequencies(RING.replace(ea=ea), GEO, n))[:, 0]
        shift = np.asarray(N.extensible_flexural_shift(RING, GEO, n, 1.0 / ea))
        np.testing.assert_allclose(omega18**2 + shift, flex**2, rtol=1e-10)
    # inextensible: exactly nothing, and the slope there matches a finite difference of the eigen-solve
    assert np.all(np.asarray(N.extensible_flexural_shift(RING, GEO, n, 0.0)) == 0.0)
    slope = np.asarray(jax.vmap(jax.grad(lambda m, c: N.extensible_flexural_shift(RING, GEO, m, c), argnums=1),
                                in_axes=(0, None))(jnp.asarray(n, float), 0.0))
    ea = 1e9
    flex = 2 * np.pi * np.asarray(N.extensible_natural_frequencies(RING.replace(ea=ea), GEO, n))[:, 0]
    np.testing.assert_allclose(slope, (flex**2 - omega18**2) * ea, rtol=1e-3)
    assert np.all(slope < 0)  # a finite EA lowers the flexural modes


def test_extensible_tangential_branch_values():
    f = np.asarray(N.extensible_natural_frequencies(RING.replace(ea=1e6), GEO, np.arange(4)))[:, 1]
    np.testing.assert_allclose(f, [342.8, 473.7, 737.7, 1037.6], atol=0.06)
    f = np.asarray(N.extensible_natural_frequencies(RING.replace(ea=1e5), GEO, np.arange(4)))[:, 1]
    np.testing.assert_allclose(f, [147, 181, 255, 344], atol=0.6)


def test_eq25_rotating_frame_values():
    f = np.asarray(N.rotating_natural_frequencies(RING, GEO, np.array([2, 5, 8]), 43.95))
    np.testing.assert_allclose(f[:, 0], [125.73, 197.69, 293.02], atol=0.006)
    np.testing.assert_allclose(f[:, 1], [-114.54, -192.31, -289.57], atol=0.006)
    # splitting |ω_n1| − |ω_n2| = 4nΩ/(n²+1)
    n = np.array([2.0, 5.0, 8.0])
    np.testing.assert_allclose(np.abs(f[:, 0]) - np.abs(f[:, 1]), 4 * n * 43.95 / (n**2 + 1) / (2 * np.pi), rtol=1e-12)


def test_eq26_fixed_frame_values():
    f = np.asarray(N.fixed_frame_frequencies(RING, GEO, np.array([2, 5, 8]), 43.95))
    np.testing.assert_allclose(f[:, 0], [111.74, 162.71, 237.06], atol=0.01)


def test_omega_zero_limits():
    n = np.arange(0, 11)
    wf = np.asarray(N.natural_frequencies(RING, GEO, n))
    rot = np.asarray(N.rotating_natural_frequencies(RING, GEO, n, 0.0))
    np.testing.assert_allclose(rot[:, 0], wf, rtol=1e-14)
    np.testing.assert_allclose(rot[:, 1], -wf, rtol=1e-14)
    np.testing.assert_allclose(np.asarray(N.fixed_frame_frequencies(RING, GEO, n, 0.0))[:, 0], wf, rtol=1e-14)


def test_chi1_backward_wave_fixed_frame_stays_positive():
    # docs/physics.md §3.3: no standing wave for χ = 1 at any speed
    omega = np.linspace(0, 600, 61)
    f = np.asarray(N.fixed_frame_frequencies(RING, GEO, np.arange(2, 30)[:, None], omega[None, :]))[..., 0]
    assert np.all(f > 0)


def test_rotating_eq25_matches_gyroscopic_eigen_solve():
    """Independent check: 2×2 gyroscopic eigenproblem of §3.1 (χ = 1, EA large) in the complex basis."""
    omega, R, P = 43.95, GEO.radius, float(GEO.hoop_pressure_stiffness)
    ea, m = 1e12, RING.rho_a
    for n in (2, 5, 8):
        b = RING.ei / R**4
        K = np.array([[b * n**4 + ea / R**2 + RING.kw + P * (n**2 - 1), 1j * (b * n**3 + ea * n / R**2)],
                      [-1j * (b * n**3 + ea * n / R**2), b * n**2 + ea * n**2 / R**2 + RING.kv]])
        # centrifugal (−Ω²) and hoop tension χρAΩ² terms of §3.1 for e^{i(nθ+ωt)}
        chi = 1.0
        Kc = K + m * omega**2 * np.array([[-1 + chi * n**2, 1j * chi * n], [-1j * chi * n, -1 + chi]])
        G = np.array([[0, -2 * m * omega], [2 * m * omega, 0]])  # Coriolis: ρA(−2Ωv̇, +2Ωẇ)
        # (−ω² M + iω G + K) x = 0 with λ = iω: (λ² M + λ G + K) x = 0 -> companion linearisation
        M = m * np.eye(2)
        A = np.block([[np.zeros((2, 2)), np.eye(2)], [-np.linalg.solve(M, Kc), -np.linalg.solve(M, G)]])
        lam = np.linalg.eigvals(A)  # λ = iω
        w = np.sort((lam / 1j).real / (2 * np.pi))
        ref = np.asarray(N.rotating_natural_frequencies(RING, GEO, n, omega))
        # the two flexural roots (small |ω|) must match eq. 25 to 1e-3 Hz
        flex = w[np.argsort(np.abs(w))[:2]]
        np.testing.assert_allclose(np.sort(flex), np.sort(ref), atol=1e-3)


def test_critical_speed_and_cavity():
    wc, nc = N.critical_speed(RING, GEO)
    assert float(wc) == pytest.approx(223.47, abs=0.01)
    assert int(nc) == 10
    assert float(wc) * (GEO.radius + 0.020) * 3.6 == pytest.approx(254, abs=0.5)
    assert float(N.cavity_frequency()) == pytest.approx(218.75, abs=1e-9)


def test_gradient_matches_finite_differences():
    n = np.arange(1, 10)

    def f(logp):
        ring = RING.replace(rho_a=jnp.exp(logp[0]), ei=jnp.exp(logp[1]), kw=jnp.exp(logp[2]), kv=jnp.exp(logp[3]))
        return N.natural_frequencies(ring, GEO, n)

    x = np.log(np.array([RING.rho_a, RING.ei, RING.kw, RING.kv]))
    J = np.asarray(jax.jacfwd(f)(x))
    h = 1e-6
    Jfd = np.stack([(np.asarray(f(x + h * e)) - np.asarray(f(x - h * e))) / (2 * h) for e in np.eye(4)], 1)
    np.testing.assert_allclose(J, Jfd, rtol=1e-6, atol=1e-9)
