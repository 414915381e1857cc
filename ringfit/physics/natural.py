"""Natural frequencies of Gong's flexible ring (docs/physics.md §2–3).

Pure JAX functions of (:class:`~ringfit.params.RingParams`,
:class:`~ringfit.params.TyreGeometry`, n, ...). ``n`` may be a scalar or an
array of any shape (ints or floats); results have the same shape (the
extensible model adds a trailing axis of 2 branches). Frequencies are in Hz,
rotation speeds Ω in rad/s.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ringfit._cache import jit
from ringfit.params import RingParams, TyreGeometry

TWO_PI = 2.0 * jnp.pi


def modal_stiffness(ring: RingParams, geometry: TyreGeometry, n):
    """Numerator of eq. 18 [N/m²]: ``EI/R⁴ n²(n²−1)² + (p0b/R) n²(n²−1) + k_w n² + k_v``.

    docs/physics.md §2.1 (seed eq. 18). Equals ``n² d_n`` with d_n of §2.1.
    """
    n2 = jnp.asarray(n, dtype=jnp.float64) ** 2
    R = geometry.radius
    return (
        ring.ei / R**4 * n2 * (n2 - 1.0) ** 2
        + geometry.hoop_pressure_stiffness * n2 * (n2 - 1.0)
        + ring.kw * n2
        + ring.kv
    )


def modal_mass(ring: RingParams, n):
    """Denominator of eq. 18 [kg/m]: ``ρA (1 + n²)`` (docs/physics.md §2.1).

    A mass per unit length scaled by n²; the mass of one standing mode in kg is
    :func:`ring_modal_mass`.
    """
    n2 = jnp.asarray(n, dtype=jnp.float64) ** 2
    return ring.rho_a * (1.0 + n2)


def ring_modal_mass(ring: RingParams, geometry: TyreGeometry, n):
    """Generalised mass of one standing mode of the inextensible ring [kg] (docs/physics.md §2.1, §6).

    For the shape ``w = cos nθ`` (unit radial amplitude, ``v = sin nθ / n`` so
    that ``w + v′ = 0``) the kinetic energy ``½∫ρA(ẇ² + v̇²) R dθ`` gives
    ``M_n = πRρA(1 + 1/n²)`` for n ≥ 1, i.e. ``πR · modal_mass / n²``; for
    n = 0 (rigid rotation, unit tangential amplitude) ``M_0 = 2πRρA``, the
    ring's mass. It is the M of the ``ground_contact`` and ``sensor_mass``
    effects (§6) and of the synthetic impact and cleat responses.

    **Arguments:** ``n`` — circumferential index ≥ 0, scalar or array.

    **Returns:** M_n [kg], shape of ``n``.
    """
    n2 = jnp.asarray(n, dtype=jnp.float64) ** 2
    rotation = n2 == 0.0
    per_harmonic = jnp.pi * geometry.radius * modal_mass(ring, n) / jnp.where(rotation, 1.0, n2)
    return jnp.where(rotation, 2.0 * jnp.pi * geometry.radius * ring.rho_a, per_harmonic)


def natural_angular_frequencies(ring: RingParams, geometry: TyreGeometry, n):
    """Static inextensible ring, ω_n [rad/s] (docs/physics.md §2.1, seed eq. 18)."""
    return jnp.sqrt(modal_stiffness(ring, geometry, n) / modal_mass(ring, n))


def natural_frequencies(ring: RingParams, geometry: TyreGeometry, n):
    """Static inextensible ring, f_n = ω_n / 2π [Hz] (docs/physics.md §2.1, seed eq. 18).

    **Arguments:** ``n`` — circumferential index, scalar or array (n = 0 is
    rigid rotation, n = 1 rigid translation).

    **Returns:** frequencies [Hz], shape of ``n``.

    Examples
    --------
    The source study's Table 9 ring reproduces its Table 10 (107.0, 119.8, 140.0 Hz):

    >>> import numpy as np
    >>> from ringfit.params import table9
    >>> from ringfit.physics.natural import natural_frequencies
    >>> geometry, ring = table9()
    >>> np.round(natural_frequencies(ring, geometry, np.array([1, 2, 3])), 2).tolist()
    [107.02, 119.84, 140.01]
    """
    return natural_angular_frequencies(ring, geometry, n) / TWO_PI


def extensible_stiffness_matrix(ring: RingParams, geometry: TyreGeometry, n):
    """K_n of the extensible ring [N/m²], shape ``n.shape + (2, 2)`` (docs/physics.md §2.2).

    Real basis ``w = W cos nθ``, ``v = V sin nθ``; rows/cols (radial, tangential).
    """
    n = jnp.asarray(n, dtype=jnp.float64)
    R = geometry.radius
    b4 = ring.ei / R**4
    m2 = ring.ea / R**2
    P = geometry.hoop_pressure_stiffness
    k11 = b4 * n**4 + m2 + ring.kw + P * (n**2 - 1.0)
    k12 = b4 * n**3 + m2 * n
    k22 = b4 * n**2 + m2 * n**2 + ring.kv
    return jnp.stack([jnp.stack([k11, k12], -1), jnp.stack([k12, k22], -1)], -2)


def extensible_natural_frequencies(ring: RingParams, geometry: TyreGeometry, n):
    """Extensible ring, both branches per n [Hz], shape ``n.shape + (2,)`` (docs/physics.md §2.2).

    Solves ``det(K_n − ρA ω² I) = 0``. Branches are sorted ascending: for
    EA ≳ 1e5 N index 0 is the flexural (radial-dominant) branch, which tends to
    eq. 18 as EA → ∞, and index 1 the tangential-dominant (membrane) branch.
    Needs a finite ``ring.ea``.
    """
    K = extensible_stiffness_matrix(ring, geometry, n)
    lam = jnp.linalg.eigvalsh(K) / ring.rho_a  # ascending ω²
    return jnp.sqrt(jnp.clip(lam, 0.0)) / TWO_PI


def extensible_flexural_shift(ring: RingParams, geometry: TyreGeometry, n, compliance):
    """``ω²_flexural(EA) − ω²_eq18`` [rad²/s²] of the extensible ring, in compliance form (docs/physics.md §2.2).

    The §2.2 matrix is ``K_n = K⁰_n + (EA/R²) e eᵀ`` with ``K⁰_n`` the matrix at
    EA = 0 (:func:`extensible_stiffness_matrix`) and ``e = (1, n)`` (the
    membrane strain ``w + v′``). With the compliance ``c = R²/EA`` and
    ``u = (n, −1)`` (``uᵀe = 0``: the inextensible shapes), ``det(K_n − λI) = 0``
    times c is ``c·det(K⁰ − λI) + uᵀ(K⁰ − λI)u = 0``, whose root near
    ``λ₀ = uᵀK⁰u/(n² + 1) = ρAω²_eq18`` is ``λ₀ + δ`` with

        c δ² − [c(A + B) + n² + 1] δ + c(AB − K⁰₁₂²) = 0,   A = K⁰₁₁ − λ₀,  B = K⁰₂₂ − λ₀

    (the smaller root, written without cancellation). It is exactly 0 at
    ``compliance = 0`` (EA = ∞), smooth there (slope ``(AB − K⁰₁₂²)/(n² + 1)``
    per unit c), and equals the flexural branch of
    :func:`extensible_natural_frequencies` for any finite EA.

    **Arguments:** ``n`` — circumferential index, scalar or array;
    ``compliance`` — 1/EA [1/N] (≥ 0), broadcast with ``n``.

    **Returns:** ``δ/ρA`` [rad²/s²], shape of ``n`` broadcast with ``compliance``.
    """
    n = jnp.asarray(n, dtype=jnp.float64)
    K0 = extensible_stiffness_matrix(ring.replace(ea=0.0), geometry, n)
    k11, k12, k22 = K0[..., 0, 0], K0[..., 0, 1], K0[..., 1, 1]
    n2p1 = n**2 + 1.0
    lam0 = (n**2 * k11 - 2.0 * n * k12 + k22) / n2p1  # uᵀK⁰u / uᵀu = n² d_n/(n²+1), eq. 18 times ρA
    c = jnp.asarray(compliance, dtype=jnp.float64) * geometry.radius**2
    a, b = k11 - lam0, k22 - lam0
    lin = c * (a + b) + n2p1
    const = c * (a * b - k12**2)
    disc = jnp.sqrt(jnp.clip(lin**2 - 4.0 * c * const, 0.0))
    return 2.0 * const / (lin + disc) / ring.rho_a


def rotating_from_static(omega_static, n, omega):
    """Eq. 25 given the static ω_fn [rad/s]: co-rotating ω_n1, ω_n2 [rad/s], shape ``+ (2,)`` (docs/physics.md §3.2).

    ``ω_n1,2 = 2nΩ/(n²+1) ± √(ω_fn² + n²(n²−1)²Ω²/(n²+1)²)``; index 0 is
    ω_n1 > 0 (backward wave), index 1 is ω_n2 < 0 (forward wave), convention
    ``w ∝ exp(i(nθ + ωt))``. Taking ω_fn as an argument lets models that change
    the static frequency (ground contact, cavity, ...) add rotation on top.
    """
    n = jnp.asarray(n, dtype=jnp.float64)
    omega = jnp.asarray(omega, dtype=jnp.float64)
    n2p1 = n**2 + 1.0
    shift = 2.0 * n * omega / n2p1
    root = jnp.sqrt(omega_static**2 + (n * (n**2 - 1.0) * omega / n2p1) ** 2)
    return jnp.stack([shift + root, shift - root], -1)


def rotating_natural_frequencies(ring: RingParams, geometry: TyreGeometry, n, omega):
    """Rotating ring seen by a co-rotating observer [Hz], shape ``n.shape + (2,)`` (docs/physics.md §3.2, seed eq. 25).

    Eq. 25 (:func:`rotating_from_static`) on the static ω_fn of eq. 18: index 0
    is ω_n1 > 0 (backward wave), index 1 is ω_n2 < 0 (forward wave). Exact for
    χ = 1, EA → ∞.

    **Arguments:** ``omega`` — wheel speed Ω [rad/s], broadcast with ``n``.
    """
    wf = natural_angular_frequencies(ring, geometry, n)
    return rotating_from_static(wf, n, omega) / TWO_PI


def fixed_frame_frequencies(ring: RingParams, geometry: TyreGeometry, n, omega):
    """Rotating ring seen by a fixed observer (Doppler) [Hz], shape ``n.shape + (2,)`` (docs/physics.md §3.3, seed eq. 26).

    ``ω_fixed = ω_nk − nΩ`` applied to both waves of
    :func:`rotating_natural_frequencies` (signed; index 0 backward, 1 forward).
    """
    n = jnp.asarray(n, dtype=jnp.float64)
    omega = jnp.asarray(omega, dtype=jnp.float64)
    rot = rotating_natural_frequencies(ring, geometry, n, omega)
    return rot - (n * omega / TWO_PI)[..., None]


#: Speed of sound in the cavity air [m/s] (docs/physics.md §3.6).
SOUND_SPEED = 343.0
#: The source study's cavity length L_c [m] (docs/physics.md §1, §3.6).
CAVITY_LENGTH = 1.568
#: Atmospheric pressure [Pa]; the cavity air is at p0 + P_ATM.
P_ATM = 101325.0


def cavity_frequency(n=1, sound_speed: float = SOUND_SPEED, cavity_length: float = CAVITY_LENGTH):
    """Acoustic cavity resonance ``f_n = n c / L_c`` [Hz] (docs/physics.md §3.6, seed eq. 22)."""
    return jnp.asarray(n, dtype=jnp.float64) * sound_speed / cavity_length


def cavity_coupling(ring: RingParams, geometry: TyreGeometry, n, inverse_area):
    """Coupling ``k = b²ρ0c²/(A_c m)`` [rad²/s²] of ring harmonic n with the cavity air (docs/physics.md §6 cavity_mode).

    ``m = ρA(n² + 1)/n²`` is the ring's mass per unit length in harmonic n
    (:func:`ring_modal_mass` / πR) and ``ρ0 = 1.2 (p0 + p_atm)/p_atm`` the cavity
    air's density [kg/m³].

    **Arguments:** ``n`` ≥ 1, scalar or array; ``inverse_area`` — 1/A_c [1/m²].

    **Returns:** k, shape of ``n`` broadcast with ``inverse_area``.
    """
    rho0 = 1.2 * (geometry.pressure + P_ATM) / P_ATM
    m = ring_modal_mass(ring, geometry, n) / (jnp.pi * geometry.radius)
    return geometry.width**2 * rho0 * SOUND_SPEED**2 * inverse_area / m


def cavity_coupled_shift(omega_structural, omega_acoustic, coupling):
    """``ω² − ω₀²`` [rad²/s²] of the structural mode coupled with the cavity air (docs/physics.md §6 cavity_mode).

    The structural root of the two-mode pencil, ω² = ω₀² + δ with
    ``δ² − [(ω_a² − ω₀²) + k] δ − k ω₀² = 0``, the root that vanishes with k
    (written without cancellation): exactly 0 at k = 0.

    **Arguments:** ``omega_structural`` ω₀ and ``omega_acoustic`` ω_a,n = n·2πf_cav
    [rad/s]; ``coupling`` k from :func:`cavity_coupling`. Broadcast together.
    """
    x0 = omega_structural * omega_structural
    B = omega_acoustic**2 - x0 + coupling
    sgn = jnp.where(B >= 0, 1.0, -1.0)
    return -2.0 * coupling * x0 / (B + sgn * jnp.sqrt(B * B + 4.0 * coupling * x0))


def critical_speed(ring: RingParams, geometry: TyreGeometry, n_max: int = 60):
    """Critical speed ``Ω_c = min_n ω_n / n`` over n = 1…n_max (docs/physics.md §3.4, seed eq. 29).

    **Returns:** ``(omega_c, n_c)`` — Ω_c [rad/s] and the minimising n (int array).
    The simple resonance condition: χ = 0, no Coriolis (see §3.4).
    """
    n = jnp.arange(1, n_max + 1, dtype=jnp.float64)
    ratio = natural_angular_frequencies(ring, geometry, n) / n
    i = jnp.argmin(ratio)
    return ratio[i], (i + 1).astype(jnp.int64)


#: jitted versions for calls from NumPy code (the fitters build their own jit regions): one compiled program
#: per argument shape, where an eager call compiles each of its array operations separately (~1 s of a cold
#: process for eq. 18's first evaluation, against ~0.2 s for the program).
natural_frequencies_jit = jit(natural_frequencies)
modal_stiffness_jit = jit(modal_stiffness)
cavity_frequency_jit = jit(cavity_frequency)
