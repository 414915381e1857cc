"""Modes of the rolling, loaded ring (docs/physics.md §3.7): limits, convergence, an independent discretisation, gradients."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg

from ringfit.params import table9
from ringfit.physics.loaded import loaded_natural_frequencies
from ringfit.physics.natural import fixed_frame_frequencies, natural_frequencies, rotating_natural_frequencies
from ringfit.physics.operating import Drum, OperatingPoint
from ringfit.physics.rolling_modes import (
    ContactArc,
    campbell_modes_jit,
    campbell_modes_traced,
    contact_arc,
    material_acceleration,
    rolling_modes,
    rolling_modes_jit,
    sensor_lines,
)

OMEGA_50 = 43.95  # rad/s, 50 km/h at R_out (docs/physics.md §7)
HALF_ANGLE = math.radians(11.69)  # docs/physics.md §7 ground-contact extension


@pytest.fixture(scope="module")
def tyre():
    return table9()


def test_no_contact_is_eq26_and_eq25(tyre):
    g, r = tyre
    K = 16
    m = rolling_modes_jit(r, g, OMEGA_50, ContactArc.none(), harmonics=K)
    f = np.asarray(m.freq_hz)
    n = np.arange(0, K + 1.0)
    fixed = np.asarray(fixed_frame_frequencies(r, g, n, OMEGA_50))  # (K+1, 2) signed, eq. 26
    rot = np.asarray(rotating_natural_frequencies(r, g, n, OMEGA_50))  # eq. 25
    expected = np.sort(np.concatenate([np.abs(fixed[1:]).ravel(), [abs(fixed[0, 0])]]))
    np.testing.assert_allclose(f, expected, rtol=1e-11)
    # docs/physics.md §7 backward waves at 50 km/h: n=2 111.74, n=5 162.71, n=8 237.06 Hz
    order, travel = np.asarray(m.order), np.asarray(m.travel)
    for nn, val in ((2, 111.74), (5, 162.71), (8, 237.06)):
        i = np.flatnonzero((order == nn) & (travel > 1e6))
        assert i.size == 1 and f[i[0]] == pytest.approx(val, abs=0.01)
    # each mode is one travelling wave: backward (k = +n) at eq. 26's ω_n1 − nΩ, forward (k = −n) at |ω_n2 − nΩ|
    lines, wr, _ = (np.asarray(x) for x in sensor_lines(m))
    k = np.asarray(m.k)
    for i in range(len(f)):
        if order[i] == 0:
            continue
        j = int(np.nanargmax(wr[i]))
        nn = order[i]
        assert abs(k[j]) == nn and wr[i, j] == pytest.approx(1.0, abs=1e-12)
        backward = travel[i] > 0
        assert k[j] == (nn if backward else -nn)
        # the co-rotating sensor sees ω + kΩ = eq. 25 (ω_n1 > 0 backward; |ω_n2| forward)
        assert abs(lines[i, j]) == pytest.approx(abs(rot[nn, 0 if backward else 1]), rel=1e-11)
        assert m.symmetry[i] == pytest.approx(0.5, abs=1e-9)


def test_standing_loaded_limit_is_ground_contact(tyre):
    g, r = tyre
    N = 16
    m = rolling_modes_jit(r, g, 0.0, ContactArc.symmetric(HALF_ANGLE, r.k_tread), harmonics=N)
    cos_t, sin_t = (np.asarray(x) for x in loaded_natural_frequencies(r, g, HALF_ANGLE, n_max=N))
    f0 = float(natural_frequencies(r, g, 0.0))  # the decoupled n = 0 mode (rigid rotation)
    np.testing.assert_allclose(np.asarray(m.freq_hz), np.sort(np.concatenate([cos_t, sin_t, [f0]])), rtol=1e-10)
    # cos-type modes are contact-symmetric (extr), sin-type antisymmetric (0)
    sym = np.asarray(m.symmetry)
    f = np.asarray(m.freq_hz)
    for fc in cos_t[:8]:
        assert sym[np.argmin(np.abs(f - fc))] == pytest.approx(1.0, abs=1e-9)
    for fs in sin_t[:8]:
        assert sym[np.argmin(np.abs(f - fs))] == pytest.approx(0.0, abs=1e-9)


def test_converges_in_basis_size(tyre):
    g, r = tyre
    op = OperatingPoint(80 / 3.6 / 0.312, 4000.0)
    arc, sol = eqx.filter_jit(contact_arc)(r, g, op)
    assert bool(sol.ok)
    ref = rolling_modes_jit(r, g, op.omega, arc, harmonics=64)
    fr, nr = np.asarray(ref.freq_hz), np.asarray(ref.order)
    worst = {}
    for K in (16, 32):
        m = rolling_modes_jit(r, g, op.omega, arc, harmonics=K)
        f, n = np.asarray(m.freq_hz), np.asarray(m.order)
        err = []
        for i in np.flatnonzero(n <= 15):
            c = np.flatnonzero(nr == n[i])
            err.append(np.min(np.abs(fr[c] - f[i])) / f[i])
        assert len(err) >= 30
        worst[K] = max(err)
    assert worst[32] < 1e-4  # the default basis (DEFAULT_HARMONICS = 32); measured 7e-5 against K = 64 and K = 200
    assert worst[32] < 0.5 * worst[16]


def _fd_modes(ring, geometry, omega, lead_cells, trail_cells, points):
    """Independent check: the §3.7 PDEs by 4th-order periodic finite differences in α, numpy/scipy only.

    Unknown v_j on the grid (inextensible: w = −v′); the tension multiplier is eliminated by virtual
    work, δw·(R) + δv·(T) = 0 with δw = −D1 δv, i.e. (T) + D1 (R) = 0 (D1 skew). The contact is
    k_trd on the cells ``lead_cells … trail_cells − 1`` (edges at cell boundaries).
    """
    h = 2 * np.pi / points

    def circ(stencil):
        c = np.zeros(points)
        for off, val in stencil.items():
            c[off % points] += val
        return scipy.linalg.circulant(c).T

    D1 = circ({-2: 1 / 12, -1: -2 / 3, 1: 2 / 3, 2: -1 / 12}) / h
    D2 = circ({-2: -1 / 12, -1: 4 / 3, 0: -5 / 2, 1: 4 / 3, 2: -1 / 12}) / h**2
    D3 = circ({-3: 1 / 8, -2: -1, -1: 13 / 8, 1: -13 / 8, 2: 1, 3: -1 / 8}) / h**3
    D4 = circ({-3: -1 / 6, -2: 2, -1: -13 / 2, 0: 28 / 3, 1: -13 / 2, 2: 2, 3: -1 / 6}) / h**4
    I = np.eye(points)
    R = float(geometry.radius)
    rho, b4, P = float(ring.rho_a), float(ring.ei) / R**4, float(geometry.hoop_pressure_stiffness)
    kw, kv, chi, O = float(ring.kw), float(ring.kv), float(ring.chi), float(omega)
    cells = np.arange(points)
    kc = np.where((cells >= lead_cells % points) | (cells < trail_cells), float(ring.k_tread), 0.0) \
        if lead_cells < 0 else np.where((cells >= lead_cells) & (cells < trail_cells), float(ring.k_tread), 0.0)
    W = -D1  # w = W v
    # (R) and (T) as (λ², λ, 1) coefficient matrices acting on v
    R2, R1 = rho * W, rho * (2 * O * D1 @ W - 2 * O * I)
    R0 = (rho * (O**2 * D2 @ W - 2 * O**2 * D1 - O**2 * W) + b4 * (D4 @ W - D3) - P * (D2 @ W + W)
          - chi * rho * O**2 * (D2 @ W - D1) + kw * W + np.diag(kc) @ W)
    T2, T1 = rho * I, rho * (2 * O * D1 + 2 * O * W)
    T0 = (rho * (O**2 * D2 + 2 * O**2 * D1 @ W - O**2 * I) + b4 * (D3 @ W - D2)
          + chi * rho * O**2 * (I - D1 @ W) + kv * I)
    A2, A1, A0 = T2 + D1 @ R2, T1 + D1 @ R1, T0 + D1 @ R0
    Z = np.zeros_like(I)
    lam, vec = scipy.linalg.eig(np.block([[Z, I], [-A0, -A1]]), np.block([[I, Z], [Z, A2]]))
    # keep resolved modes: a central-difference grid also has spurious modes near its Nyquist order
    # (there D1 → 0, so they look like low orders); drop shapes with most content above order points/6
    spec = np.abs(np.fft.fft(vec[:points], axis=0)) ** 2
    order = np.minimum(np.arange(points), points - np.arange(points))
    smooth = spec[order <= points // 6].sum(0) > 0.5 * spec.sum(0)
    keep = (lam.imag > 0) & smooth
    return np.sort(lam.imag[keep]) / (2 * np.pi)


@pytest.mark.parametrize("omega", [0.0, 35.0])
def test_agrees_with_finite_differences(tyre, omega):
    g, r = tyre
    points = 240
    lead, trail = -8, 7  # contact on cells −8…6 of 1.5°: α from −12.75° to +9.75° (asymmetric, as when rolling)
    f_fd = _fd_modes(r, g, omega, lead, trail, points)
    h = 2 * np.pi / points
    # cell j covers [α_j − h/2, α_j + h/2] around the grid point α_j = j h
    arc = ContactArc(jnp.asarray((lead - 0.5) * h), jnp.asarray((trail - 0.5) * h), r.k_tread)
    m = rolling_modes_jit(r, g, omega, arc, harmonics=64)
    f = np.asarray(m.freq_hz)
    low = f[f < 320.0]
    assert low.size >= 14
    np.testing.assert_allclose(f_fd[: low.size], low, rtol=5e-4)  # measured 1.5e-4 (7e-5 with 360 points)


def test_gradient_of_an_eigenfrequency_matches_finite_differences(tyre):
    g, r = tyre

    def freq(params, load, speed):
        ei, kw, kt = params
        ring = r.replace(ei=ei, kw=kw, k_tread=kt)
        op = OperatingPoint(speed, load, Drum(diameter=jnp.asarray(1.2192)))
        arc, _ = contact_arc(ring, g, op)
        return rolling_modes(ring, g, speed, arc, harmonics=16).angular_frequency[9]

    both = jax.jit(jax.value_and_grad(freq, argnums=(0, 1, 2)))

    def f(*a):
        return float(both(*a)[0])

    x = (jnp.asarray(0.9426), jnp.asarray(1.294e6), jnp.asarray(19e6))
    load, speed = jnp.asarray(4000.0), jnp.asarray(35.0)
    value, grads = both(x, load, speed)
    for i in range(3):
        step = 1e-4 * float(x[i])
        up = tuple(v + step if j == i else v for j, v in enumerate(x))
        dn = tuple(v - step if j == i else v for j, v in enumerate(x))
        fd = (f(up, load, speed) - f(dn, load, speed)) / (2 * step)
        assert float(grads[0][i]) == pytest.approx(fd, rel=1e-4, abs=1e-12 * abs(float(value)))
    for k, step in enumerate((1.0, 1e-3)):
        a = (x, load + step, speed) if k == 0 else (x, load, speed + step)
        b = (x, load - step, speed) if k == 0 else (x, load, speed - step)
        fd = (f(*a) - f(*b)) / (2 * step)
        assert float(grads[1 + k]) == pytest.approx(fd, rel=1e-4)
    assert abs(float(grads[1])) > 0 and abs(float(grads[2])) > 0  # load and speed matter


def test_campbell_compiles_once_and_agrees_with_single_solves(tyre):
    g, r = tyre
    drum = Drum(diameter=1.2192)
    speeds = np.array([0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0])  # as ringfit.gap.campbell pads them (8)
    before = eqx.debug.get_num_traces(campbell_modes_traced)
    cm = campbell_modes_jit(r, g, 4000.0, speeds, drum, harmonics=32, contact=True)
    cm2 = campbell_modes_jit(r.replace(ei=1.0), g, 3500.0, speeds + 5.0, drum, harmonics=32, contact=True)
    assert eqx.debug.get_num_traces(campbell_modes_traced) - before <= 1  # 0 if another test compiled it
    assert bool(np.all(cm.ok)) and bool(np.all(cm2.ok))
    # the standing deflection sets R_e = R_out − δ/3, and the patch is that of the contact solve at each speed
    om = np.asarray(cm.omega)
    assert om[2] == pytest.approx(20 / 3.6 / float(cm.rolling_radius))
    assert float(cm.rolling_radius) == pytest.approx(float(g.outer_radius) - float(cm.deflection[0]) / 3)
    arc, sol = eqx.filter_jit(contact_arc)(r, g, OperatingPoint(om[6], 4000.0, drum))
    assert float(arc.leading) == pytest.approx(float(cm.leading[6]), abs=1e-12)
    single = rolling_modes_jit(r, g, om[6], arc, harmonics=32)
    np.testing.assert_allclose(np.asarray(cm.modes.freq_hz[6]), np.asarray(single.freq_hz), rtol=1e-10)


def test_rotation_mixes_contact_symmetric_and_antisymmetric(tyre):
    g, r = tyre
    arc = ContactArc.symmetric(HALF_ANGLE, r.k_tread)
    m0 = rolling_modes_jit(r, g, 0.0, arc, harmonics=16)
    m1 = rolling_modes_jit(r, g, 35.0, arc, harmonics=16)
    s0, s1 = np.asarray(m0.symmetry)[1:12], np.asarray(m1.symmetry)[1:12]
    assert np.all((s0 < 1e-9) | (s0 > 1 - 1e-9))  # standing: pure extr / 0
    assert np.sum((s1 > 0.1) & (s1 < 0.9)) >= 9  # rolling: mixed (all but n = 1's pair, split most by the patch)
    assert np.all(np.abs(np.asarray(m0.travel)[1:12]) == pytest.approx(1.0))
    # an accelerometer weights harmonic k by (ω + kΩ)²: backward content is emphasised
    A, _ = material_acceleration(m1)
    k, w, om = np.asarray(m1.k), np.asarray(m1.angular_frequency), 35.0
    np.testing.assert_allclose(np.abs(np.asarray(A)), (w[:, None] + k[None, :] * om) ** 2 * np.abs(np.asarray(m1.radial)))


def test_damping_is_the_ring_ratio_when_standing(tyre):
    g, r = tyre
    m = rolling_modes_jit(r, g, 0.0, ContactArc.none(), harmonics=16)
    np.testing.assert_allclose(np.asarray(m.damping_ratio), float(r.damping_ratio), rtol=1e-10)
