"""Contact solve (docs/physics.md §4.3–4.4): §7 numbers, an independent finite-difference discretisation, gradients."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ringfit.params import table9
from ringfit.physics.contact import (
    ContactSolver,
    contact_length,
    patch_edges,
    solve_rolling,
    solve_rolling_jit,
)
from ringfit.physics.operating import Drum, FlatRoad, OperatingPoint
from ringfit.physics.rolling import NoDamping, RingModel, Viscous
from ringfit.physics.sensor import sensor_signals

GEOMETRY, RING = table9()
OMEGA_30 = 26.88  # 30 km/h at R_e = 0.31 m (docs/physics.md §7)
FZ = 4000.0
M_REF = 2048  # the §7 prototype's grid


def rel(a, b):
    return abs(float(a) - b) / abs(b)


@pytest.fixture(scope="module")
def flat():
    return solve_rolling_jit(RING, GEOMETRY, OperatingPoint(OMEGA_30, FZ), solver=ContactSolver(n_grid=M_REF))


def grid_extent_deg(sol):
    """Outermost grid points with p > 0 (how the §7 prototype reports the patch)."""
    phi = np.degrees(np.asarray(sol.phi))[np.asarray(sol.pressure) > 0]
    return phi.min(), phi.max()


def test_flat_road_matches_physics_section_7(flat):
    assert bool(flat.ok)
    assert rel(flat.deflection * 1e3, 12.74) < 0.005
    lead, trail = grid_extent_deg(flat)
    step = 360.0 / M_REF
    assert abs(lead - (-11.95)) < step and abs(trail - 11.43) < step
    assert rel(contact_length(flat) * 1e3, 129.0) < 0.005
    assert rel(jnp.max(flat.pressure), 4.565e4) < 0.005
    assert rel(flat.w[M_REF // 2] * 1e3, -10.34) < 0.005
    assert rel(flat.fx, 21.6) < 0.01
    assert rel(flat.fz, FZ) < 1e-10  # load imposed exactly


def test_undamped_patch_is_symmetric_with_no_rolling_resistance():
    sol = solve_rolling_jit(RING, GEOMETRY, OperatingPoint(OMEGA_30, FZ), model=RingModel(damping=NoDamping()),
                            solver=ContactSolver(n_grid=M_REF))
    assert rel(sol.deflection * 1e3, 12.75) < 0.005
    lead, trail = grid_extent_deg(sol)
    assert abs(lead + 11.60) < 0.2 and abs(trail - 11.60) < 0.2
    assert abs(float(sol.fx)) < 1e-6 * FZ
    p = np.asarray(sol.pressure)
    np.testing.assert_allclose(p[1:], p[1:][::-1], atol=1e-6 * p.max())  # φ_j ↔ −φ_j


def test_drum_matches_physics_section_7():
    sol = solve_rolling_jit(RING, GEOMETRY, OperatingPoint(OMEGA_30, FZ, Drum(1.2192)),
                            solver=ContactSolver(n_grid=M_REF))
    assert bool(sol.ok)
    assert rel(sol.deflection * 1e3, 13.86) < 0.005
    assert rel(contact_length(sol) * 1e3, 106.0) < 0.01
    assert rel(sol.fz, FZ) < 1e-9
    # the same tyre on a flat road deflects less and has a longer patch
    flat = solve_rolling_jit(RING, GEOMETRY, OperatingPoint(OMEGA_30, FZ), solver=ContactSolver(n_grid=M_REF))
    assert flat.deflection < sol.deflection and contact_length(flat) > contact_length(sol)


@pytest.mark.parametrize("damping", ["hysteretic", "viscous"])
def test_damping_shifts_pressure_forward_and_resists_rolling(damping):
    """docs/physics.md §4.2: either damping form gives a forward-shifted pressure and a rearward Fx."""
    model = RingModel() if damping == "hysteretic" else RingModel(damping=Viscous(c_w=3000.0, c_v=3000.0))
    sol = solve_rolling_jit(RING, GEOMETRY, OperatingPoint(OMEGA_30, FZ), model=model)
    p, phi = np.asarray(sol.pressure), np.asarray(sol.phi)
    centroid = np.sum(p * phi) / np.sum(p)
    assert centroid < 0  # the leading side (φ < 0) carries more
    assert float(sol.fx) > 0  # rearward: resists rolling
    lead, trail = patch_edges(sol)
    assert -lead > trail


def test_no_contact_outside_patch_and_complementarity(flat):
    p = np.asarray(flat.pressure)
    delta = np.asarray(flat.penetration)
    assert np.all(p >= 0)
    inside = p > 0
    np.testing.assert_allclose(p[inside], RING.k_tread * delta[inside], rtol=1e-9)
    assert np.all(delta[~inside] <= 1e-12)


def test_small_window_is_reported():
    sol = solve_rolling_jit(RING, GEOMETRY, OperatingPoint(OMEGA_30, FZ), solver=ContactSolver(window_deg=8.0))
    assert not bool(sol.window_ok)


def test_a_strict_window_gives_nan_for_a_clipped_patch_and_the_same_solution_otherwise():
    """strict_window (identify's posterior, docs/physics.md §12.3): a patch the window clips is NaN, not a wrong
    answer; a patch inside is the wide window's solution to rounding. The patch of 4 kN spans ~±12°."""
    op = OperatingPoint(OMEGA_30, FZ)
    clipped = solve_rolling_jit(RING, GEOMETRY, op, solver=ContactSolver(window_deg=8.0, strict_window=True))
    assert math.isnan(float(clipped.axle_height)) and np.all(np.isnan(np.asarray(clipped.w)))
    wide = solve_rolling_jit(RING, GEOMETRY, op, solver=ContactSolver())
    lo, hi = grid_extent_deg(wide)
    narrow = solve_rolling_jit(RING, GEOMETRY, op, solver=ContactSolver(window_deg=float(1.2 * max(-lo, hi) + 1.0),
                                                                        strict_window=True))
    assert bool(narrow.window_ok) and narrow.pressure.shape == wide.pressure.shape
    assert float(narrow.axle_height) == pytest.approx(float(wide.axle_height), rel=1e-13, abs=1e-14)
    np.testing.assert_allclose(narrow.pressure, wide.pressure, rtol=0, atol=1e-9 * float(np.max(wide.pressure)))
    np.testing.assert_allclose(narrow.w, wide.w, rtol=0, atol=1e-12 * float(np.max(np.abs(wide.w))) + 1e-18)


def test_a_start_from_a_nearby_patch_takes_fewer_iterations_to_the_same_solution():
    """start_compliance (identify's posterior): the active set started at the patch a nearby solution had (its
    extent a: deflection (R+τ)(1 − cos a), here read off the solution at 4 kN and used at 3.6 kN) reaches the
    same solution as the fixed 1 cm start in fewer iterations."""
    ref = solve_rolling_jit(RING, GEOMETRY, OperatingPoint(OMEGA_30, FZ), solver=ContactSolver())
    lo, hi = grid_extent_deg(ref)
    a = math.radians(max(-lo, hi))
    compliance = float(GEOMETRY.outer_radius) * (1.0 - math.cos(a)) / FZ
    op = OperatingPoint(OMEGA_30, 0.9 * FZ)
    plain = solve_rolling_jit(RING, GEOMETRY, op, solver=ContactSolver())
    started = solve_rolling_jit(RING, GEOMETRY, op, solver=ContactSolver(start_compliance=compliance))
    assert bool(plain.converged) and bool(started.converged)
    assert int(started.iterations) < int(plain.iterations)
    assert float(started.axle_height) == pytest.approx(float(plain.axle_height), rel=1e-13)
    np.testing.assert_allclose(started.pressure, plain.pressure, rtol=0, atol=1e-9 * float(np.max(plain.pressure)))


@pytest.mark.parametrize("road", [FlatRoad(), Drum(diameter=2.0)], ids=["flat", "drum"])
def test_the_solve_without_its_derivative_step_is_the_same_solution(road):
    """differentiable=False returns the iteration's last solve instead of one more at the frozen set: the same
    solution to rounding (the set repeated and H settled), on a flat road (the gap linear in H) and on a drum
    (the gap linearised at H per step)."""
    op = OperatingPoint(OMEGA_30, FZ, road)
    a = solve_rolling_jit(RING, GEOMETRY, op, solver=ContactSolver())
    b = solve_rolling_jit(RING, GEOMETRY, op, solver=ContactSolver(differentiable=False))
    assert bool(a.converged) and bool(b.converged)
    assert float(b.axle_height) == pytest.approx(float(a.axle_height), rel=1e-12)
    scale = float(np.max(a.pressure))
    np.testing.assert_allclose(b.pressure, a.pressure, rtol=0, atol=1e-7 * scale)
    np.testing.assert_allclose(b.fz, a.fz, rtol=1e-9)


# ----------------------------------------------------------------------------- independent discretisation


def periodic_fd(n, h):
    """4th-order central finite-difference matrices d/dφ … d⁴/dφ⁴ on a periodic grid (sparse)."""

    def stencil(coeffs, scale):
        rows = np.concatenate([np.arange(n)] * len(coeffs))
        cols = np.concatenate([(np.arange(n) + k) % n for k in coeffs])
        vals = np.concatenate([np.full(n, c / scale) for c in coeffs.values()])
        return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))

    d1 = stencil({-2: 1, -1: -8, 1: 8, 2: -1}, 12 * h)
    d2 = stencil({-2: -1, -1: 16, 0: -30, 1: 16, 2: -1}, 12 * h**2)
    d3 = stencil({-3: 1, -2: -8, -1: 13, 1: -13, 2: 8, 3: -1}, 8 * h**3)
    d4 = stencil({-3: -1, -2: 12, -1: -39, 0: 56, 1: -39, 2: 12, 3: -1}, 6 * h**4)
    return d1, d2, d3, d4


def fd_contact(n, omega, c_w, ea=1.0e8, window_deg=35.0):
    """§4.1 steady equations (χ = 1, membrane penalty EA, viscous c_w) by finite differences in φ,
    with the §4.3 contact law and Fz imposed, solved by a plain active-set loop. Independent of ringfit."""
    R, b, p0, tau = 0.296, 0.152, 2.2e5, 0.020
    rho_a, ei, kw, kv, ktrd = 2.715, 0.9426, 1.294e6, 1.161e6, 19e6
    P = p0 * b / R
    h = 2 * np.pi / n
    phi = -np.pi + h * np.arange(n)
    d1, d2, d3, d4 = periodic_fd(n, h)
    eye = sp.identity(n)
    m = ea / R**2 - rho_a * omega**2
    b4 = ei / R**4
    Lww = b4 * d4 + m * eye - P * (d2 + eye) + kw * eye + omega * c_w * d1
    Lwv = -b4 * d3 + m * d1
    Lvw = b4 * d3 - m * d1
    Lvv = -b4 * d2 - m * d2 + kv * eye
    L = sp.bmat([[Lww, Lwv], [Lvw, Lvv]]).tocsc()
    lu = spla.splu(L)
    win = np.flatnonzero(np.abs(phi) <= math.radians(window_deg))
    rhs = np.zeros((2 * n, win.size))
    rhs[win, np.arange(win.size)] = -1.0  # q_w = −p: unit pressure at each window node
    resp = lu.solve(rhs)[:n]  # w response at every node to unit p at window node j
    A = resp[win]  # w_i = Σ_j A_ij p_j
    phik = phi[win]
    active = np.abs(phik) < 0.2
    for _ in range(50):
        k_idx = np.flatnonzero(active)
        # p_A − k A_AA p_A + k H/cos φ = k (R+τ);  R h Σ cos φ p = Fz
        sysm = np.zeros((k_idx.size + 1, k_idx.size + 1))
        sysm[:-1, :-1] = np.eye(k_idx.size) - ktrd * A[np.ix_(k_idx, k_idx)]
        sysm[:-1, -1] = ktrd / np.cos(phik[k_idx])
        sysm[-1, :-1] = R * h * np.cos(phik[k_idx])
        x = np.linalg.solve(sysm, np.append(np.full(k_idx.size, ktrd * (R + tau)), FZ))
        p = np.zeros(win.size)
        p[k_idx] = x[:-1]
        H = x[-1]
        delta = R + tau + A @ p - H / np.cos(phik)
        new = delta > 0
        if np.array_equal(new, active):
            break
        active = new
    w = resp @ p
    return dict(deflection=R + tau - H, p_max=p.max(), w0=w[n // 2], fx=-R * h * np.sum(p * np.sin(phik)),
                extent=(np.degrees(phik[active].min()), np.degrees(phik[active].max())), phi=phi, w=w)


def test_independent_finite_difference_discretisation_agrees():
    """4th-order FD in angle of the §4.1 equations with the same contact law, to 1 %."""
    n = 4096
    c_w = 3000.0
    fd = fd_contact(n, OMEGA_30, c_w)
    sol = solve_rolling_jit(RING.replace(damping_ratio=0.0), GEOMETRY, OperatingPoint(OMEGA_30, FZ),
                            model=RingModel(damping=Viscous(c_w=c_w)), solver=ContactSolver(n_grid=n))
    assert rel(sol.deflection, fd["deflection"]) < 0.01
    assert rel(jnp.max(sol.pressure), fd["p_max"]) < 0.01
    assert rel(sol.w[n // 2], fd["w0"]) < 0.01
    assert rel(sol.fx, fd["fx"]) < 0.01 and fd["fx"] > 0
    lead, trail = grid_extent_deg(sol)
    assert abs(lead - fd["extent"][0]) <= 360.0 / n + 1e-9 and abs(trail - fd["extent"][1]) <= 360.0 / n + 1e-9
    w = np.asarray(sol.w)
    assert np.max(np.abs(w - fd["w"])) < 0.01 * np.max(np.abs(fd["w"]))


# ----------------------------------------------------------------------------- gradients


def scalar_output(theta):
    """A scalar that depends on every kind of parameter: ring, tread, load, speed, drum."""
    k_tread, ei, kw, zeta, load, omega, drum = theta
    ring = RING.replace(k_tread=k_tread, ei=ei, kw=kw, damping_ratio=zeta)
    sol = solve_rolling(ring, GEOMETRY, OperatingPoint(omega, load, Drum(drum)))
    radial, tangential = sensor_signals(sol, GEOMETRY)
    return (jnp.sum(radial**2) * 1e-6 + jnp.sum(tangential**2) * 1e-5 + sol.fx + 1e3 * sol.deflection
            + 1e-3 * jnp.max(sol.pressure))


def test_gradient_matches_finite_differences():
    theta = jnp.array([19e6, 0.9426, 1.294e6, 0.025, 4000.0, 26.88, 1.2192])
    value_and_grad = jax.jit(jax.value_and_grad(scalar_output))  # one compilation serves the FD values too
    grad = np.asarray(value_and_grad(theta)[1])

    def f(x):
        return float(value_and_grad(x)[0])

    for i in range(theta.size):
        h = 1e-6 * float(theta[i])
        fd = (f(theta.at[i].add(h)) - f(theta.at[i].add(-h))) / (2 * h)
        assert grad[i] == pytest.approx(fd, rel=2e-4, abs=1e-9 * abs(fd) + 1e-12), f"parameter {i}"
