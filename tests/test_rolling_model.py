"""Per-harmonic ring operator of the rolling ring (docs/physics.md §4.1–4.2)."""

import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.params import table9
from ringfit.physics.natural import natural_frequencies
from ringfit.physics.rolling import (
    Hysteretic,
    NoDamping,
    RingModel,
    Viscous,
    receptance,
    reduced_operator,
    ring_operator,
)

GEOMETRY, RING = table9()
N = jnp.arange(1, 256, dtype=jnp.float64)


def d_closed_form(n, omega, chi, eta):
    """§4.2 inextensible d_n written out from docs/physics.md (Table 9 numbers typed in)."""
    R, P = 0.296, 2.2e5 * 0.152 / 0.296
    ei, kw, kv, rho_a = 0.9426, 1.294e6, 1.161e6, 2.715
    n2 = n**2
    elastic = ei * (n2 - 1) ** 2 / R**4 + P * (n2 - 1) + kw + kv / n2
    return elastic * (1 + 1j * eta * np.sign(n)) - (1 - chi) * rho_a * omega**2 * (n2 - 1) ** 2 / n2


@pytest.mark.parametrize("omega,chi", [(0.0, 1.0), (26.88, 1.0), (53.0, 0.6)])
def test_inextensible_operator_matches_closed_form(omega, chi):
    ring = RING.replace(chi=chi)
    d = reduced_operator(ring_operator(ring, GEOMETRY, N, omega), N)
    np.testing.assert_allclose(np.asarray(d), d_closed_form(np.asarray(N), omega, chi, 0.05), rtol=1e-12)


def test_static_undamped_operator_gives_eq18():
    """ω_n² = n² d_n / (ρA(n²+1)) at Ω = 0, η = 0 (docs/physics.md §2.1)."""
    d = reduced_operator(ring_operator(RING, GEOMETRY, N, 0.0, RingModel(damping=NoDamping())), N)
    omega_n = np.sqrt(np.asarray(N) ** 2 * np.real(np.asarray(d)) / (RING.rho_a * (np.asarray(N) ** 2 + 1)))
    np.testing.assert_allclose(omega_n / (2 * np.pi), np.asarray(natural_frequencies(RING, GEOMETRY, N)), rtol=1e-12)
    # §7 eq. 18 values n = 1, 2, 5
    np.testing.assert_allclose(omega_n[[0, 1, 4]] / (2 * np.pi), [107.02, 119.84, 192.31], atol=0.01)


@pytest.mark.parametrize("omega,chi", [(0.0, 1.0), (44.0, 1.0), (44.0, 0.5)])
def test_extensible_with_huge_ea_reproduces_inextensible(omega, chi):
    ring = RING.replace(ea=1e12, chi=chi)
    n = jnp.arange(0, 256, dtype=jnp.float64)
    g_ext = np.asarray(receptance(ring, GEOMETRY, n, omega, RingModel(extensible=True)))
    g_inx = np.asarray(receptance(ring, GEOMETRY, n, omega))
    scale = np.abs(g_inx[1:, 0, 0])
    for i, j in [(0, 0), (1, 0), (0, 1), (1, 1)]:
        err = np.abs(g_ext[1:, i, j] - g_inx[1:, i, j]) / scale
        assert err.max() < 1e-6, (i, j, err.max())
    assert abs(g_ext[0, 0, 0]) < 1e-6 * scale.max()  # W_0 → 0
    np.testing.assert_allclose(g_ext[0, 1, 1], g_inx[0, 1, 1], rtol=1e-9)  # V_0 = S_0/(k_v − (1−χ)ρAΩ²)
    np.testing.assert_allclose(np.real(1 / g_inx[0, 1, 1]), RING.kv - (1 - chi) * RING.rho_a * omega**2, rtol=1e-12)


def test_fields_are_real_by_construction():
    """D_{−n} = conj(D_n) for every term (hysteretic s_n, viscous nΩ, E_n, F_n)."""
    model = RingModel(extensible=True, terms=(Viscous(c_w=100.0, c_v=50.0),))
    ring = RING.replace(ea=1e6, chi=0.7)
    Dp = np.asarray(ring_operator(ring, GEOMETRY, N, 30.0, model))
    Dm = np.asarray(ring_operator(ring, GEOMETRY, -N, 30.0, model))
    np.testing.assert_allclose(Dm, np.conj(Dp), rtol=1e-13)


def test_viscous_term_projects_as_expected():
    """Inextensible projection of diag(i nΩ c_w, i nΩ c_v) is i nΩ (c_w + c_v/n²)."""
    omega = 20.0
    base = reduced_operator(ring_operator(RING, GEOMETRY, N, omega, RingModel(damping=NoDamping())), N)
    visc = reduced_operator(ring_operator(RING, GEOMETRY, N, omega, RingModel(damping=Viscous(300.0, 40.0))), N)
    np.testing.assert_allclose(np.asarray(visc - base), 1j * np.asarray(N) * omega * (300.0 + 40.0 / np.asarray(N) ** 2),
                               rtol=1e-9)


def test_hysteretic_loss_factor_gives_damping_ratio():
    """η = 2ζ: every flexural mode has Im(d_n)/Re(d_n) = 2ζ at Ω = 0 (docs/physics.md §7)."""
    d = np.asarray(reduced_operator(ring_operator(RING, GEOMETRY, N, 0.0), N))
    np.testing.assert_allclose(np.imag(d) / np.real(d) / 2, 0.025, rtol=1e-12)
    d2 = np.asarray(reduced_operator(ring_operator(RING, GEOMETRY, N, 0.0, RingModel(damping=Hysteretic(0.1))), N))
    np.testing.assert_allclose(np.imag(d2) / np.real(d2), 0.1, rtol=1e-12)
