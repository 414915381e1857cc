"""Sensor layers (docs/physics.md §4.6, §5): identities, gravity, tilt, offset, high-pass, angle shift."""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.params import table9
from ringfit.physics.contact import ContactSolver, solve_rolling_jit
from ringfit.physics.operating import OperatingPoint
from ringfit.physics.rolling import harmonic_numbers
from ringfit.physics.sensor import (
    STANDARD_GRAVITY,
    SensorModel,
    iepe_highpass,
    remove_revolution_mean,
    sensor_signals_jit,
    shift_angle,
)

GEOMETRY, RING = table9()
OMEGA_30 = 26.88
M = 2048


@pytest.fixture(scope="module")
def sol():
    return solve_rolling_jit(RING, GEOMETRY, OperatingPoint(OMEGA_30, 4000.0), solver=ContactSolver(n_grid=M))


def read(sol, **kw):
    r, t = sensor_signals_jit(sol, GEOMETRY, SensorModel(remove_mean=False, **kw))
    return np.asarray(r), np.asarray(t)


def test_tilting_sensor_on_inextensible_ring_reads_no_tangential(sol):
    """§5 identity: γ = 1, e = 0, inextensible ⇒ s_tan = g sin(φ − ψ) only (zero without gravity)."""
    _, t = read(sol, tilt_gain=1.0)
    assert np.max(np.abs(t)) < 1e-9 * OMEGA_30**2 * GEOMETRY.radius
    _, t_fixed = read(sol)  # the baseline γ = 0 is NOT zero near the patch (§7)
    assert np.max(np.abs(t_fixed)) > 1.0 * STANDARD_GRAVITY


def test_radial_channel_maps_belt_curvature(sol):
    """§5 identity: s_rad = Ω²R²κ, κ = 1/R − (w + w″)/R² (e = 0, inextensible, no g)."""
    r, _ = read(sol)
    R = GEOMETRY.radius
    w = np.asarray(sol.w)
    n = np.arange(M // 2 + 1)
    w2 = np.fft.irfft(-(n**2) * np.fft.rfft(w), M)  # spectral w″, independent of the model's spectra
    kappa = 1 / R - (w + w2) / R**2
    np.testing.assert_allclose(r, OMEGA_30**2 * R**2 * kappa, atol=1e-8 * OMEGA_30**2 * R)


def test_gravity_layer_adds_the_turning_one_g(sol):
    r0, t0 = read(sol)
    r1, t1 = read(sol, gravity=STANDARD_GRAVITY)
    phi = np.asarray(sol.phi)
    np.testing.assert_allclose(r1 - r0, STANDARD_GRAVITY * np.cos(phi), atol=1e-10)  # radial inward +: +g at the bottom
    np.testing.assert_allclose(t1 - t0, STANDARD_GRAVITY * np.sin(phi), atol=1e-10)


def test_offset_sensor_reads_tangential_doublet(sol):
    """§6 sensor_tilt: e = 6 mm, γ = 1 at 30 km/h: +3.7 g at −10.2°, −3.6 g at +9.8° (§6 figures, two digits)."""
    _, t = read(sol, offset=0.006, tilt_gain=1.0)
    phi = np.degrees(np.asarray(sol.phi))
    g = STANDARD_GRAVITY
    i, j = np.argmax(t), np.argmin(t)
    assert 3.7 <= t[i] / g < 3.8 and abs(phi[i] + 10.2) < 0.2
    assert -3.7 < t[j] / g <= -3.6 and abs(phi[j] - 9.8) < 0.2
    # and it is the doublet Ω² e (w‴ + w′)/R of §6
    n = np.arange(M // 2 + 1)
    W = np.fft.rfft(np.asarray(sol.w))
    doublet = OMEGA_30**2 * 0.006 * np.fft.irfft(((1j * n) ** 3 + 1j * n) * W, M) / GEOMETRY.radius
    np.testing.assert_allclose(t, doublet, atol=1e-7 * g)


@pytest.mark.parametrize("f_rot,f_c,gain,lead_deg", [(0.713, 0.3, 0.922, 22.8), (0.713, 1.0, 0.581, 54.5),
                                                     (1.426, 0.3, 0.979, 11.9), (1.426, 1.0, 0.819, 35.0)])
def test_highpass_gain_and_phase_match_section_7(f_rot, f_c, gain, lead_deg):
    phi = -np.pi + 2 * np.pi * np.arange(256) / 256
    out = np.asarray(iepe_highpass(jnp.asarray(np.cos(phi) + 3.0), 2 * np.pi * f_rot, f_c))
    c = np.sum(out * np.exp(-1j * phi)) * 2 / phi.size  # out = |c| cos(φ + arg c)
    assert abs(c) == pytest.approx(gain, abs=0.002)
    assert math.degrees(np.angle(c)) == pytest.approx(lead_deg, abs=0.15)
    assert abs(np.mean(out)) < 1e-12  # DC removed exactly


def test_highpass_off_is_identity_and_mean_removal():
    x = jnp.asarray(np.random.default_rng(0).normal(size=128))
    np.testing.assert_allclose(np.asarray(iepe_highpass(x, 10.0, 0.0)), np.asarray(x), atol=1e-12)
    assert abs(float(jnp.mean(remove_revolution_mean(x + 5.0)))) < 1e-12


def test_shift_angle_is_a_band_limited_translation():
    M_ = 128
    phi = -np.pi + 2 * np.pi * np.arange(M_) / M_
    x = np.cos(3 * phi) + 0.5 * np.sin(7 * phi + 0.3)
    d = 0.0123
    y = np.asarray(shift_angle(jnp.asarray(x), d))
    np.testing.assert_allclose(y, np.cos(3 * (phi + d)) + 0.5 * np.sin(7 * (phi + d) + 0.3), atol=1e-12)


def test_baseline_sensor_removes_each_channels_mean(sol):
    r, t = sensor_signals_jit(sol, GEOMETRY)
    assert abs(float(jnp.mean(r))) < 1e-9 and abs(float(jnp.mean(t))) < 1e-9
    r_raw, _ = read(sol)
    np.testing.assert_allclose(np.asarray(r), r_raw - r_raw.mean(), atol=1e-9)
    assert harmonic_numbers(M).shape == (M // 2 + 1,)
