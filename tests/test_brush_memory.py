"""The brush with stick/slip memory (docs/physics.md §6 tread_shear, §13.2; Pacejka, *Tire and Vehicle Dynamics*,
§3.2): :func:`ringfit.physics.contact.brush_tip_forces` against closed forms and a plain loop written here."""

import math

import numpy as np
import pytest

import ringfit  # noqa: F401  (float64)
from ringfit.physics.contact import brush_tip_forces, free_rolling_radius


def _loop(D, s, k_x, lim, inside, r):
    """The memory brush walked tip by tip from the leading edge (independent of the code's scan): a tip sticks to
    its road point, its force follows the sticking force's change, and is held at ±μp while that is exceeded."""
    q = np.zeros(D.size)
    prev = None
    for j in range(D.size):
        if not inside[j]:
            prev = None
            continue
        stick = -k_x * (D[j] - r * s[j])
        trial = stick if prev is None else q[j - 1] + stick - prev
        q[j] = min(max(trial, -lim[j]), lim[j])
        prev = stick
    return q


def _parabolic(M=20001):
    """A rigid carcass (its base moves ρ per radian) on a parabolic pressure over s ∈ [0, S]."""
    S = 0.25
    s = np.linspace(-0.05, S + 0.05, M)
    inside = (s > 0) & (s < S)
    p0 = 2.0e5  # peak pressure [N/m]
    p = np.where(inside, 4 * p0 * (s / S) * (1 - s / S), 0.0)
    return s, inside, p, p0, S


@pytest.mark.parametrize("theta", [0.2, 0.5, 0.8, 1.3])
@pytest.mark.parametrize("memory", [True, False])
def test_parabolic_pressure_matches_pacejkas_closed_form(theta, memory):
    """Pacejka §3.2 (rigid carcass, parabolic pressure): with θ = c S/(4 μ p0) (c = k_x |ρ − r|, the sticking
    force's slope per radian, p0 the peak), the tips stick over s < S(1 − θ) and slide beyond, and
    Fx = μ Fz (1 − (1 − θ)³) for θ < 1, μ Fz (full sliding) beyond. On one hump memory and clip agree."""
    s, inside, p, p0, S = _parabolic()
    mu, k_x, rho = 0.8, 15e6, 0.30
    c = theta * 4 * mu * p0 / S
    r = rho - c / k_x  # road behind the base: driving, q_x < 0 (the road pushes the tips back)
    D = rho * np.where(inside, s, 0.0)
    ss = np.where(inside, s, 0.0)
    q = np.asarray(brush_tip_forces(D, ss, k_x, mu * p, inside, r, memory=memory))
    h = s[1] - s[0]
    fz = np.sum(p) * h
    fx = -np.sum(q) * h
    want = mu * fz * (1 - max(1 - theta, 0.0) ** 3)
    assert fz == pytest.approx(2 / 3 * p0 * S, rel=1e-6)
    assert fx == pytest.approx(want, rel=2e-4)
    sliding = inside & (np.abs(q) >= mu * p * (1 - 1e-12))
    first_slide = s[np.argmax(sliding)]
    assert first_slide == pytest.approx(S * max(1 - theta, 0.0), abs=2 * h)
    # the adhesion region sticks: q = −c s exactly
    stick = inside & (s < S * (1 - theta) - 2 * h)
    np.testing.assert_allclose(q[stick], -c * s[stick], rtol=1e-9)


def _two_humps(M=600):
    phi = np.linspace(-0.5, 0.5, M)
    inside = np.abs(phi) < 0.3
    x = (phi + 0.3) / 0.6
    p = np.where(inside, 1e5 * np.sin(np.pi * x) ** 2 * (0.4 + 6.0 * (x - 0.5) ** 2), 0.0)  # humps, a dip between
    s = np.where(inside, phi + 0.3, 0.0)
    D = 0.30 * s + 0.002 * np.sin(7 * s)
    return phi, inside, p, s, D


@pytest.mark.parametrize("r", [0.2985, 0.2995, 0.3010])
def test_two_humped_pressure_matches_the_plain_loop_and_differs_from_the_clip(r):
    """On a pressure with a dip between two humps the tips slide into the dip and stick again behind it from the
    force they slid with; the scan equals the loop above to roundoff, and the memoryless clip differs from it by
    a material part of the tip forces (the case discriminates)."""
    phi, inside, p, s, D = _two_humps()
    k_x, mu = 15e6, 1.0
    q = np.asarray(brush_tip_forces(D, s, k_x, mu * p, inside, r))
    ref = _loop(D, s, k_x, mu * p, inside, r)
    scale = np.max(np.abs(ref))
    np.testing.assert_allclose(q, ref, rtol=0, atol=1e-10 * scale)
    clip = np.asarray(brush_tip_forces(D, s, k_x, mu * p, inside, r, memory=False))
    assert np.max(np.abs(clip - ref)) > 0.05 * scale
    assert np.all(q[~inside] == 0.0)


def test_memory_free_rolling_radius_zeroes_the_torque_and_its_derivative_matches_finite_differences():
    """R_e of the memory brush: the loop's torque vanishes there (brentq on the loop, written here, agrees), and
    ∂R_e/∂k_x and ∂R_e/∂(a shift of D) match central differences of those roots."""
    import jax
    from scipy.optimize import brentq

    phi, inside, p, s, D = _two_humps()
    c = np.cos(phi)
    lim = 1.0 * p
    bump = np.where(inside, np.sin(3.0 * s), 0.0) * 1e-3

    def root(k_x, a):
        return brentq(lambda r: np.sum(_loop(D + a * bump, s, k_x, lim, inside, r) * c), 0.2, 0.4, xtol=1e-15)

    k0 = 15e6
    r_e = float(jax.jit(lambda k: free_rolling_radius(D, s, c, k, lim, inside, memory=True))(k0))
    assert r_e == pytest.approx(root(k0, 0.0), abs=1e-10)
    # sliding happens at that root, and the clip's root differs (memory matters in free rolling here)
    q = _loop(D, s, k0, lim, inside, r_e)
    assert np.any(inside & (np.abs(q) >= lim * (1 - 1e-12)))
    grad = jax.jit(jax.grad(lambda k, a: free_rolling_radius(D + a * bump, s, c, k, lim, inside, memory=True),
                            argnums=(0, 1)))(k0, 0.0)
    fd_k = (root(k0 * 1.001, 0.0) - root(k0 / 1.001, 0.0)) / (k0 * (1.001 - 1 / 1.001))
    fd_a = (root(k0, 1e-3) - root(k0, -1e-3)) / 2e-3
    assert abs(fd_a) > 1e-6 and abs(fd_k) > 0
    assert float(grad[0]) == pytest.approx(fd_k, rel=2e-3)
    assert float(grad[1]) == pytest.approx(fd_a, rel=2e-3)


def test_tip_force_gradient_matches_finite_differences():
    """∂Fx/∂r and ∂Fx/∂k_x of the memory brush (through the scan's clips) against central differences of the
    loop, at a drive with tips sliding into the dip and sticking again."""
    import jax

    phi, inside, p, s, D = _two_humps()
    lim = 1.0 * p

    def fx(k, r):
        return -jax.numpy.sum(brush_tip_forces(D, s, k, lim, inside, r))

    k0, r0 = 15e6, 0.2990
    g = jax.jit(jax.grad(fx, argnums=(0, 1)))(k0, r0)

    def fx_loop(k, r):
        return -np.sum(_loop(D, s, k, lim, inside, r))

    dr, dk = 1e-7, 1e3
    fd_r = (fx_loop(k0, r0 + dr) - fx_loop(k0, r0 - dr)) / (2 * dr)
    fd_k = (fx_loop(k0 + dk, r0) - fx_loop(k0 - dk, r0)) / (2 * dk)
    assert abs(fd_r) > 0 and abs(fd_k) > 0
    assert float(g[1]) == pytest.approx(fd_r, rel=1e-4)
    assert float(g[0]) == pytest.approx(fd_k, rel=1e-4)
    assert math.isfinite(float(g[0]))
