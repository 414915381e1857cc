"""The wheel on its suspension: rim, hub and fixture as one rigid body on the fixture's springs (docs/physics.md §6 ``wheel_suspension``).

Every other model of ringfit fixes the rim in space. Here the rim (with hub and
fixture) is a rigid body of mass ``m_w`` and polar inertia ``I_w`` held by the
fixture's vertical, fore-aft and torsional springs (compliances ``c_z``, ``c_x``,
``c_θ``; compliance 0 = rigid = the rim-fixed model) and dampers. The sidewall
springs k_w, k_v act on the displacement of the belt *relative to the rim*, so

- a rim translation loads only the ring's n = 1 harmonic (the belt's rigid
  translation): belt mass ``m_b = 2πRρA`` (:func:`ringfit.physics.natural.ring_modal_mass`
  at n = 1), sidewall translation stiffness ``K_1 = πR(k_w + k_v)``;
- a rim rotation loads only n = 0 (the belt's rigid rotation) through k_v:
  belt inertia ``I_b = 2πR³ρA``, sidewall torsion stiffness ``K_0 = 2πR³k_v``.

Three forms, one physics (docs/physics.md §6):

- :func:`coupled_angular_frequency` — the two-body closed form: one ring
  coordinate (mass m, stiffness to ground ``m ω_r²`` of which ``K_s`` is the
  sidewall to the rim) and the body on its support; the root that continues the
  ring's mode. Used by the diagnosis on top of whatever earlier effects predicted.
- :func:`loaded_wheel_angular_frequencies` — the loaded standing ring of
  :mod:`ringfit.physics.loaded` bordered by the body's vertical DOF (cos-type
  shapes) and fore-aft DOF (sin-type shapes): the n = 1 pair splits.
- :func:`border_hill` — the body's three DOFs added to the Hill matrices of the
  rolling, loaded ring (:mod:`ringfit.physics.rolling_modes`, fixed frame).

All functions are pure JAX; the wheel's fields may be traced.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from ringfit.io.modes import (  # noqa: F401  (the sidecar's defaults, docs/formats.md §2; re-exported)
    DEFAULT_STIFFNESS_N_M, DEFAULT_TORSION_N_M_RAD, DEFAULT_WHEEL_INERTIA_KG_M2, DEFAULT_WHEEL_MASS_KG)
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.loaded import DEFAULT_HARMONICS, eigen_angular_frequencies, loaded_matrices
from ringfit.physics.rolling import harmonic_basis

#: Smallest compliance used where a stiffness must stay finite (Hill's Cholesky factor) [m/N].
_MIN_COMPLIANCE = 1e-15


class Wheel(eqx.Module):
    """The rigid body the ring's sidewall springs are attached to (docs/physics.md §6 ``wheel_suspension``).

    **Fields** (SI, may be traced): ``mass`` m_w [kg]; ``inertia`` I_w [kg m²];
    ``compliance_vertical``, ``compliance_fore_aft`` 1/k_z, 1/k_x [m/N];
    ``compliance_torsion`` 1/k_θ [rad/(N m)] (0 = rigid: the rim-fixed model);
    ``damping_vertical``, ``damping_fore_aft`` [N s/m], ``damping_torsion`` [N m s/rad].
    """

    mass: jax.Array
    inertia: jax.Array
    compliance_vertical: jax.Array
    compliance_fore_aft: jax.Array
    compliance_torsion: jax.Array
    damping_vertical: jax.Array = 0.0
    damping_fore_aft: jax.Array = 0.0
    damping_torsion: jax.Array = 0.0

    @classmethod
    def from_stiffness(cls, mass, inertia, k_vertical, k_fore_aft, k_torsion,
                       c_vertical=0.0, c_fore_aft=0.0, c_torsion=0.0) -> "Wheel":
        """From stiffnesses [N/m, N/m, N m/rad] (``inf`` = rigid, 0 = free)."""
        def comp(k):
            k = jnp.asarray(k, dtype=jnp.float64)
            return jnp.where(jnp.isinf(k), 0.0, 1.0 / k)

        f = lambda x: jnp.asarray(x, dtype=jnp.float64)  # noqa: E731
        return cls(f(mass), f(inertia), comp(k_vertical), comp(k_fore_aft), comp(k_torsion),
                   f(c_vertical), f(c_fore_aft), f(c_torsion))


def belt_translation(ring: RingParams, geometry: TyreGeometry):
    """``(m_b, K_1)``: belt mass 2πRρA [kg] and sidewall translation stiffness πR(k_w + k_v) [N/m] (§6)."""
    R = geometry.radius
    return 2.0 * jnp.pi * R * ring.rho_a, jnp.pi * R * (ring.kw + ring.kv)


def belt_torsion(ring: RingParams, geometry: TyreGeometry):
    """``(I_b, K_0)``: belt inertia 2πR³ρA [kg m²] and sidewall torsion stiffness 2πR³k_v [N m/rad] (§6)."""
    R3 = geometry.radius**3
    return 2.0 * jnp.pi * R3 * ring.rho_a, 2.0 * jnp.pi * R3 * ring.kv


def coupled_angular_frequency(omega_ring, ring_mass, sidewall, body_mass, compliance, damping=0.0):
    """The ring-dominated root of the ring coordinate + body pair [rad/s] and its added damping ratio (§6).

    Two coordinates: the ring's (mass m, stiffness to ground ``K_r = m ω_r²``, of which
    ``K_s`` is the sidewall to the body) and the body's (mass M on a support of compliance
    c = 1/k). With λ = ω²:

        m M λ² − [K_r M + m(k + K_s)] λ + K_r(k + K_s) − K_s² = 0.

    The root kept is the ring's mode: the one that puts the smaller share of its potential
    energy into the support spring (a stiff support: the lower root, the rim nearly still; a
    soft one: the upper root, belt against rim on the sidewall, while the lower root is the
    whole wheel bouncing on its support; at k = 0 the lower root is the rigid motion). At
    c = 0 (rigid support) ω_r is returned unchanged, bit for bit; at k = 0 and K_r = K_s
    (free-free, no ground) the upper root is ``K_s(1/m + 1/M)``.

    The support's damper d adds, to first order, ``ζ = d y²/(2ω(m + M y²))`` with the body's
    amplitude ``y = K_s/(K_s + k − Mλ)`` per unit ring amplitude.

    **Arguments:** broadcast together; ``compliance`` ≥ 0 [m/N or rad/(N m)].

    **Returns:** ``(omega, zeta_added)``.
    """
    omega_ring = jnp.asarray(omega_ring, dtype=jnp.float64)
    c = jnp.asarray(compliance, dtype=jnp.float64)
    on = c > 0
    k = 1.0 / jnp.where(on, c, 1.0)
    m, M, Ks = ring_mass, body_mass, sidewall
    Kr = m * omega_ring * omega_ring
    B = Kr * M + m * (k + Ks)
    C = Kr * (k + Ks) - Ks * Ks
    root = jnp.sqrt(jnp.clip(B * B - 4.0 * m * M * C, 0.0))
    lower = 2.0 * C / (B + root)
    upper = (B + root) / (2.0 * m * M)
    Kg = jnp.clip(Kr - Ks, 0.0)

    def body_amplitude(lam):
        return Ks / (Ks + k - M * lam)

    def support_share(lam):  # share of the potential energy in the support spring
        y = body_amplitude(lam)
        e = k * y * y
        return e / (e + Ks * (1.0 - y) ** 2 + Kg)

    lam = jnp.where(support_share(lower) < support_share(upper), lower, upper)
    lam_safe = jnp.clip(lam, 1e-30)
    om = jnp.sqrt(lam_safe)
    y = body_amplitude(lam_safe)
    zeta = damping * y * y / (2.0 * om * (m + M * y * y))
    return jnp.where(on, om, omega_ring), jnp.where(on, zeta, 0.0)


def _bordered_roots(mass, K, body_mass, compliance, sidewall):
    """Eigenfrequencies of the loaded basis bordered by one body coordinate on harmonic n = 1 (index 0).

    **Returns:** ``(N,)`` ring-dominated roots [rad/s], ascending (the body-dominated root removed).
    """
    c = jnp.where(compliance > 0, compliance, _MIN_COMPLIANCE)
    nb = mass.shape[0]
    Kb = jnp.zeros((nb + 1, nb + 1), dtype=jnp.float64)
    Kb = Kb.at[:nb, :nb].set(K)
    Kb = Kb.at[0, nb].set(-sidewall).at[nb, 0].set(-sidewall).at[nb, nb].set(sidewall + 1.0 / c)
    Mb = jnp.concatenate([mass, jnp.reshape(body_mass, (1,))])
    s = 1.0 / jnp.sqrt(Mb)
    lam, vec = jnp.linalg.eigh(Kb * s[:, None] * s[None, :])
    share = vec[nb] ** 2  # the body's share of each mass-normalised mode
    j = jnp.argmax(share)
    idx = jnp.arange(nb)
    keep = jnp.where(idx < j, lam[idx], lam[jnp.minimum(idx + 1, nb)])
    return jnp.sqrt(jnp.clip(keep, 0.0))


def loaded_wheel_angular_frequencies(ring: RingParams, geometry: TyreGeometry, half_angle, wheel: Wheel,
                                     n_max: int = DEFAULT_HARMONICS, k_tread=None):
    """Loaded standing tyre on the wheel's suspension [rad/s] (docs/physics.md §6 ``wheel_suspension``).

    The matrices of :func:`ringfit.physics.loaded.loaded_matrices` bordered by the body: its
    vertical coordinate Z couples to the cos-type n = 1 amplitude (``K[1, Z] = −K_1``,
    ``K[Z, Z] = K_1 + k_z``, ``M[Z] = m_w``), its fore-aft coordinate X to the sin-type one
    (k_x). Torsion is not in this basis (n ≥ 1): :func:`coupled_angular_frequency` with
    :func:`belt_torsion` gives the n = 0 mode.

    **Returns:** ``(cos_type, sin_type)``, each ``(N,)``, as
    :func:`ringfit.physics.loaded.loaded_angular_frequencies` (the body's own mode left
    out); a rigid direction (compliance 0) gives that function's values.
    """
    mass, k_cos, k_sin = loaded_matrices(ring, geometry, half_angle, n_max, k_tread)
    _, K1 = belt_translation(ring, geometry)

    def one(K, c):  # rigid: loaded_angular_frequencies' own solve, bit for bit its values
        return jnp.where(c > 0, _bordered_roots(mass, K, wheel.mass, c, K1), eigen_angular_frequencies(mass, K))

    return one(k_cos, wheel.compliance_vertical), one(k_sin, wheel.compliance_fore_aft)


def border_hill(M, G, K, E, k_of_dof, ring: RingParams, geometry: TyreGeometry, wheel: Wheel, harmonics: int,
                extensible: bool = False):
    """The Hill matrices of the rolling ring (:func:`ringfit.physics.rolling_modes.gyroscopic_matrices`) with the body added.

    Per unit length of ring (energies over 2πR), fixed frame. Three body coordinates:
    ``p₊ = (a − ib)/2``, ``p₋ = (a + ib)/2`` — the rim translation (a toward the patch
    centre, the vertical; b along α = 90°, fore-aft) in the harmonics k = +1, −1 of the
    ring's translation — and ``p₀ = Rβ`` (rim rotation β at the belt's radius, k = 0).
    The sidewall springs act on ``c_k − p_k``: with ``e_k = [1, i/k]`` (``[0, 1]`` at k = 0; the inextensible
    ``u_k`` of :func:`ringfit.physics.rolling.harmonic_basis`) the ring–body block is ``−b_kᴴ diag(k_w, k_v) e_k``, the body's own
    ``e_kᴴ diag(k_w, k_v) e_k`` (k_w + k_v; k_v at k = 0). Body mass ``m_w/(πR)`` on p±,
    ``I_w/(2πR³)`` on p₀; support ``[[k_z + k_x, k_z − k_x], [k_z − k_x, k_z + k_x]]/(2πR)``
    on (p₊, p₋) (an anisotropic support couples +1 and −1, as the patch does),
    ``k_θ/(2πR³)`` on p₀. No gyroscopic term on the body (a planar translation and a small
    rotation of a spinning axisymmetric body). Dampers in ``C`` (same layout).

    **Returns:** ``(M, G, K, E, C, k_of_dof)`` of size dof + 3.
    """
    R = geometry.radius
    d = 2 if extensible else 1
    dof = (2 * harmonics + 1) * d

    def grow(A):
        return jnp.zeros((dof + 3, dof + 3), dtype=jnp.complex128).at[:dof, :dof].set(A)

    found = jnp.diag(jnp.array([1.0, 0.0], dtype=jnp.complex128) * ring.kw
                     + jnp.array([0.0, 1.0], dtype=jnp.complex128) * ring.kv)
    Kb = grow(K)
    for col, kk in enumerate((1, -1, 0)):
        h = kk + harmonics
        b = harmonic_basis(jnp.asarray(float(kk)), extensible)  # (2, d): the ring's dofs at k = +1, −1, 0
        ek = harmonic_basis(jnp.asarray(float(kk)), False)[:, 0]  # the body's rigid shape e_k = u_k
        block = -(jnp.conj(b.T) @ found @ ek)  # (d,)
        rows = h * d + jnp.arange(d)
        Kb = Kb.at[rows, dof + col].set(block).at[dof + col, rows].set(jnp.conj(block))
        Kb = Kb.at[dof + col, dof + col].add(jnp.real(jnp.conj(ek) @ found @ ek))

    def comp(c):
        return jnp.where(c > 0, c, _MIN_COMPLIANCE)

    kz, kx = 1.0 / comp(wheel.compliance_vertical), 1.0 / comp(wheel.compliance_fore_aft)
    kth = 1.0 / comp(wheel.compliance_torsion)
    two_pi_r = 2.0 * jnp.pi * R
    support = jnp.array([[kz + kx, kz - kx], [kz - kx, kz + kx]]) / two_pi_r
    Kb = Kb.at[dof:dof + 2, dof:dof + 2].add(support).at[dof + 2, dof + 2].add(kth / (two_pi_r * R * R))
    Cb = jnp.zeros((dof + 3, dof + 3), dtype=jnp.complex128)
    cz, cx = wheel.damping_vertical, wheel.damping_fore_aft
    Cb = Cb.at[dof:dof + 2, dof:dof + 2].set(jnp.array([[cz + cx, cz - cx], [cz - cx, cz + cx]]) / two_pi_r)
    Cb = Cb.at[dof + 2, dof + 2].set(wheel.damping_torsion / (two_pi_r * R * R))
    body_mass = jnp.array([wheel.mass / (jnp.pi * R), wheel.mass / (jnp.pi * R), wheel.inertia / (two_pi_r * R * R)])
    Mb = grow(M).at[dof + jnp.arange(3), dof + jnp.arange(3)].set(body_mass.astype(jnp.complex128))
    kd = jnp.concatenate([k_of_dof, jnp.array([1.0, -1.0, 0.0])])
    return Mb, grow(G), Kb, grow(E), Cb, kd


__all__ = [
    "Wheel", "DEFAULT_WHEEL_MASS_KG", "DEFAULT_WHEEL_INERTIA_KG_M2", "DEFAULT_STIFFNESS_N_M",
    "DEFAULT_TORSION_N_M_RAD", "belt_translation", "belt_torsion", "coupled_angular_frequency",
    "loaded_wheel_angular_frequencies", "border_hill",
]
