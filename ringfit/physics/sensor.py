"""The co-rotating accelerometer on the inner liner, as composable layers (docs/physics.md §4.6, §5).

A material point passes the fixed-frame angle φ at time t = (φ − φ₀)/Ω; its
readings are functions of φ over one revolution. Each layer of §5 is one small
pure function; :func:`sensor_signals` chains them according to a
:class:`SensorModel`:

1. :func:`liner_point` — offset e inward: R_s = R − e, v_s = v + eψ (layer 1);
2. :func:`inertial_acceleration` — a_r, a_θ of the material point (layer 2, §4.6);
3. :func:`specific_force` — f = a − g⃗ (layer 3, gravity);
4. :func:`tilt_axes` — sensor axes turned by γψ, first order (layer 4);
5. :func:`iepe_highpass` — first-order AC coupling ``s/(s + 2πf_c)`` per revolution harmonic (layer 5);
6. :func:`shift_angle` — recorded angle → φ offset (sampling, layer 6);

plus :func:`remove_revolution_mean` (the baseline's per-revolution mean removal).

The baseline ``gong-rolling`` (§6) is ``SensorModel()``: e = 0, γ = 0, no
gravity, no high-pass, mean removed. Each gap-diagnosis effect switches a layer
on by setting a field (``tilt_gain``, ``offset``, ``gravity``, ``corner_hz``),
never by copying the chain.

Spectra are grid spectra (``rfft`` of an ``(M,)`` grid signal over φ_j =
−π + 2πj/M, harmonic k ↔ revolution harmonic k); accelerations in m/s².
Channels follow docs/formats.md §3: radial positive toward the wheel centre,
tangential positive along the sensor's direction of travel.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from ringfit.params import TyreGeometry
from ringfit.physics.contact import RollingSolution, as_traced
from ringfit.physics.rolling import harmonic_numbers

from ringfit.units import GRAVITY as STANDARD_GRAVITY  # noqa: E402  (the model's g, defined once)


def belt_slope(w_spectrum, v_spectrum, radius):
    """Belt slope ψ = (w′ − v)/R [rad] as a grid spectrum, shape of the inputs (docs/physics.md §5 layer 1)."""
    n = harmonic_numbers(2 * (w_spectrum.shape[-1] - 1))
    return (1j * n * w_spectrum - v_spectrum) / radius


def liner_point(w_spectrum, v_spectrum, radius, offset):
    """Point on the liner, offset e [m] inward (docs/physics.md §5 layer 1).

    **Returns:** ``(v_s spectrum, R_s)`` with v_s = v + eψ and R_s = R − e.
    """
    psi = belt_slope(w_spectrum, v_spectrum, radius)
    return v_spectrum + offset * psi, radius - offset


def inertial_acceleration(w_spectrum, vs_spectrum, omega, sensor_radius):
    """Inertial acceleration of the material point, grid spectra [m/s²] (docs/physics.md §4.6, §5 layer 2).

    ``a_r = Ω²(w″ − 2v_s′ − w) − Ω²R_s``, ``a_θ = Ω²(v_s″ + 2w′ − v_s)``;
    the centripetal −Ω²R_s sits in the mean (k = 0) harmonic.

    **Arguments:** spectra of shape ``(M//2+1,)``; ``omega`` Ω [rad/s]; ``sensor_radius`` R_s [m].
    **Returns:** ``(a_r, a_theta)`` spectra, outward / along rotation positive.
    """
    m_half = w_spectrum.shape[-1]
    M = 2 * (m_half - 1)
    n = harmonic_numbers(M)
    om2 = omega**2
    a_r = om2 * (-(n**2 + 1.0) * w_spectrum - 2j * n * vs_spectrum)
    a_t = om2 * (-(n**2 + 1.0) * vs_spectrum + 2j * n * w_spectrum)
    a_r = a_r.at[..., 0].add(-om2 * sensor_radius * M)  # rfft of a constant c is c·M at k = 0
    return a_r, a_t


def specific_force(a_r, a_t, phi, gravity):
    """What an accelerometer measures, f = a − g⃗ with g⃗ = −g ẑ (docs/physics.md §5 layer 3).

    ``f_r = a_r − g cos φ``, ``f_θ = a_θ + g sin φ`` on the grid; ``gravity`` g [m/s²] (0 = off).
    """
    return a_r - gravity * jnp.cos(phi), a_t + gravity * jnp.sin(phi)


def tilt_axes(f_r, f_t, psi, tilt_gain, omega, sensor_radius, phi, gravity):
    """Sensor channels with axes turned by γψ, first order (docs/physics.md §5 layer 4).

    ``s_rad = −f_r + γψ f_θ⁰``, ``s_tan = f_θ + γψ f_r⁰`` with the zeroth-order
    specific force ``f_r⁰ = −Ω²R_s − g cos φ``, ``f_θ⁰ = g sin φ``. γ = 0 gives
    the plain channels (radial inward +, tangential along travel +).

    **Returns:** ``(radial, tangential)`` grid signals [m/s²].
    """
    f_r0 = -(omega**2) * sensor_radius - gravity * jnp.cos(phi)
    f_t0 = gravity * jnp.sin(phi)
    return -f_r + tilt_gain * psi * f_t0, f_t + tilt_gain * psi * f_r0


def highpass_response(omega, corner_hz, n_harmonics: int, order: int = 1):
    """First-order high-pass ``H(ikΩ) = ikΩ/(ikΩ + 2πf_c)`` per revolution harmonic k, to the power ``order``.

    ``corner_hz`` f_c = 0 switches the filter off (gain 1, DC kept). Shape ``(n_harmonics,)``, complex.
    """
    k = jnp.arange(n_harmonics, dtype=jnp.float64)
    s = 1j * k * omega
    wc = 2.0 * jnp.pi * corner_hz
    H = jnp.where(k == 0, jnp.where(corner_hz > 0, 0.0, 1.0), s / jnp.where(k == 0, 1.0, s + wc))
    return H**order


def iepe_highpass(signal, omega, corner_hz, order: int = 1):
    """Apply the IEPE/DAQ AC coupling to a periodic grid signal (docs/physics.md §5 layer 5).

    The steady signal has period 2π/Ω, so revolution harmonic k is multiplied
    by ``H(ikΩ)`` (:func:`highpass_response`). ``signal`` shape ``(..., M)``.
    """
    M = signal.shape[-1]
    spec = jnp.fft.rfft(signal, axis=-1)
    return jnp.fft.irfft(spec * highpass_response(omega, corner_hz, M // 2 + 1, order), M, axis=-1)


def remove_revolution_mean(signal):
    """Subtract the per-revolution mean of a grid signal (shape ``(..., M)``), the baseline's shape comparison (§6)."""
    return signal - jnp.mean(signal, axis=-1, keepdims=True)


def shift_angle(signal, offset):
    """Band-limited shift: ``y(φ_j) = signal(φ_j + offset)`` [rad] (docs/physics.md §5 layer 6).

    If a recorded angle α maps to the model angle as φ = α + offset, the model
    sampled at the recorded angles (on the same grid) is ``shift_angle(model, offset)``.
    Exact for band-limited signals (Nyquist harmonic dropped); differentiable in
    ``offset``. ``signal`` shape ``(..., M)``.
    """
    M = signal.shape[-1]
    k = harmonic_numbers(M)
    spec = jnp.fft.rfft(signal, axis=-1) * jnp.exp(1j * k * offset)
    spec = spec.at[..., -1].set(0.0) if M % 2 == 0 else spec
    return jnp.fft.irfft(spec, M, axis=-1)


class SensorModel(eqx.Module):
    """The §5 layers switched on for one sensor (defaults = baseline ``gong-rolling``, §6).

    **Fields:**

    - ``offset``: e [m], sensor inward of the ring centreline (layer 1); 0 = on the centreline.
    - ``tilt_gain``: γ [-], axes turn by γψ (layer 4); 0 = fixed radial/tangential axes.
    - ``gravity``: g [m/s²] (layer 3); 0 = off, :data:`STANDARD_GRAVITY` = on.
    - ``corner_hz``: f_c [Hz] of the IEPE high-pass (layer 5); 0 = off.
    - ``highpass_order`` (static): stages of the high-pass (2 adds the DAQ's AC coupling).
    - ``remove_mean`` (static): subtract each channel's per-revolution mean (baseline: True).
    """

    offset: float = 0.0
    tilt_gain: float = 0.0
    gravity: float = 0.0
    corner_hz: float = 0.0
    highpass_order: int = eqx.field(static=True, default=1)
    remove_mean: bool = eqx.field(static=True, default=True)


def sensor_signals(solution: RollingSolution, geometry: TyreGeometry, sensor: SensorModel = SensorModel()):
    """Radial and tangential readings of the co-rotating sensor over one revolution (docs/physics.md §4.6, §5).

    **Arguments:** a :class:`~ringfit.physics.contact.RollingSolution` (grid φ_j,
    Ω), the geometry (R) and the :class:`SensorModel`.

    **Returns:** ``(radial, tangential)`` [m/s²], each shape ``(M,)`` on φ_j,
    docs/formats.md §3 signs (radial toward the wheel centre +, tangential along travel +).
    """
    R = geometry.radius
    omega = solution.omega
    phi = solution.phi
    M = phi.shape[-1]
    W, V = solution.w_spectrum, solution.v_spectrum
    vs, rs = liner_point(W, V, R, sensor.offset)
    a_r, a_t = inertial_acceleration(W, vs, omega, rs)
    f_r, f_t = specific_force(jnp.fft.irfft(a_r, M), jnp.fft.irfft(a_t, M), phi, sensor.gravity)
    psi = jnp.fft.irfft(belt_slope(W, V, R), M)
    radial, tangential = tilt_axes(f_r, f_t, psi, sensor.tilt_gain, omega, rs, phi, sensor.gravity)
    channels = jnp.stack([radial, tangential])
    channels = iepe_highpass(channels, omega, sensor.corner_hz, sensor.highpass_order)
    if sensor.remove_mean:
        channels = remove_revolution_mean(channels)
    return channels[0], channels[1]


_sensor_signals_compiled = eqx.filter_jit(sensor_signals)


def sensor_signals_jit(solution: RollingSolution, geometry: TyreGeometry, sensor: SensorModel = SensorModel()):
    """:func:`sensor_signals` compiled once per sensor structure (floats passed as arrays)."""
    geometry, sensor = as_traced((geometry, sensor))
    return _sensor_signals_compiled(solution, geometry, sensor)


__all__ = [
    "sensor_signals_jit", "STANDARD_GRAVITY", "belt_slope", "liner_point", "inertial_acceleration", "specific_force", "tilt_axes",
    "highpass_response", "iepe_highpass", "remove_revolution_mean", "shift_angle", "SensorModel",
    "sensor_signals",
]
