"""Rolling sensor signals against docs/physics.md §7, χ = 1 speed independence, Ω² scaling, convergence in harmonics."""

import numpy as np
import pytest

from ringfit.params import table9
from ringfit.physics.contact import ContactSolver, solve_rolling_jit
from ringfit.physics.operating import OperatingPoint
from ringfit.physics.rolling import NoDamping, RingModel
from ringfit.physics.sensor import SensorModel, sensor_signals_jit

GEOMETRY, RING = table9()
OMEGA_30 = 26.88  # 30 km/h at R_e = 0.31 m
G = 9.81
RAW = SensorModel(remove_mean=False)  # §7 values: e = 0, no g, no high-pass, mean kept


def readings(omega, M=2048, model=RingModel(), ring=RING, sensor=RAW):
    sol = solve_rolling_jit(ring, GEOMETRY, OperatingPoint(omega, 4000.0), model=model, solver=ContactSolver(n_grid=M))
    radial, tangential = sensor_signals_jit(sol, GEOMETRY, sensor)
    return sol, np.asarray(radial), np.asarray(tangential)


def side_max(phi_deg, x, lo, hi):
    sel = (phi_deg > lo) & (phi_deg < hi)
    i = np.argmax(np.where(sel, x, -np.inf))
    return x[i], phi_deg[i]


def test_radial_signal_matches_physics_section_7():
    sol, radial, _ = readings(OMEGA_30)
    phi = np.degrees(np.asarray(sol.phi))
    M = phi.size
    assert radial[M // 2] / G == pytest.approx(5.04, rel=0.005)
    lead, at_lead = side_max(phi, radial / G, -40, 0)
    trail, at_trail = side_max(phi, radial / G, 0, 40)
    assert lead == pytest.approx(28.49, rel=0.005) and abs(at_lead + 15.3) < 0.2
    assert trail == pytest.approx(27.75, rel=0.005) and abs(at_trail - 15.5) < 0.2
    assert radial[0] / G == pytest.approx(21.72, rel=0.005)  # φ = −180°
    assert OMEGA_30**2 * GEOMETRY.radius / G == pytest.approx(21.80, rel=0.001)


def test_undamped_radial_maxima_are_symmetric():
    sol, radial, _ = readings(OMEGA_30, model=RingModel(damping=NoDamping()))
    phi = np.degrees(np.asarray(sol.phi))
    lead, _ = side_max(phi, radial / G, -40, 0)
    trail, _ = side_max(phi, radial / G, 0, 40)
    assert lead == pytest.approx(28.12, rel=0.005) and trail == pytest.approx(lead, rel=1e-9)


def test_chi_one_shape_is_speed_independent_and_accelerations_scale_with_omega_squared():
    s0, _, _ = readings(0.0, M=512)
    s1, r1, t1 = readings(OMEGA_30, M=512)
    s2, r2, t2 = readings(2 * OMEGA_30, M=512)
    np.testing.assert_allclose(np.asarray(s1.w), np.asarray(s0.w), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(s2.v), np.asarray(s0.v), rtol=0, atol=1e-12)
    np.testing.assert_allclose(r2, 4 * r1, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(t2, 4 * t1, rtol=1e-10, atol=1e-9)


def test_chi_below_one_breaks_speed_independence():
    """Control for the test above: with χ = 0.5 the shape does change with speed."""
    ring = RING.replace(chi=0.5)
    s1, _, _ = readings(OMEGA_30, M=512, ring=ring)
    s2, _, _ = readings(3 * OMEGA_30, M=512, ring=ring)
    assert np.max(np.abs(np.asarray(s2.w) - np.asarray(s1.w))) > 1e-5


@pytest.mark.slow
def test_convergence_in_number_of_harmonics():
    """§4.5: sensor signals at M = 512 within 0.1 % of M = 8192 (RMS over the revolution, each
    channel relative to its own RMS), M = 1024 within 0.02 %; displacements converged by M = 256."""
    ref, r_ref, t_ref = readings(OMEGA_30, M=8192)

    def rms(x):
        return np.sqrt(np.mean(x**2))

    errors = {}
    for M in (256, 512, 1024):
        sol, r, t = readings(OMEGA_30, M=M)
        step = 8192 // M  # the coarse grid is a subset of the fine one
        errors[M] = max(rms(r - r_ref[::step]) / rms(r_ref), rms(t - t_ref[::step]) / rms(t_ref))
        if M == 256:
            w_ref = np.asarray(ref.w)[::step]
            assert np.max(np.abs(np.asarray(sol.w) - w_ref)) < 1e-3 * np.max(np.abs(w_ref))
    assert errors[512] < 1e-3
    assert errors[1024] < 2e-4
    assert errors[1024] < errors[512] < errors[256]
