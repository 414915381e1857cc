"""Modes of the loaded, standing tyre: tread springs in the patch as a local foundation (docs/physics.md §6 ``ground_contact``).

Linearised about the loaded static state, the radial tread springs inside
the contact patch ``|φ| < a`` act as an extra radial foundation ``k_trd`` on
that arc only. In the real basis of inextensible shapes (radial amplitude
``w = Σ A_n cos nφ + B_n sin nφ``, n = 1…N, ``v = w``-consistent so that
``w + v′ = 0``) the patch couples harmonics of the same parity:

    M = diag(π R ρA (1 + 1/n²))
    K = diag(π R d_n) + k_trd R ∫_{−a}^{a} Φ_i Φ_j dφ

with d_n of eq. 18 in per-harmonic form (docs/physics.md §2.1) and
``∫ cos iφ cos jφ = ½[S(i−j) + S(i+j)]``, ``∫ sin iφ sin jφ = ½[S(i−j) − S(i+j)]``,
``S(k) = ∫_{−a}^{a} cos kφ dφ = 2 a sinc(k a / π)``. The patch is symmetric
about φ = 0, so cosine and sine shapes do not couple: cosine-type modes are
the ``extr`` modes (``vert`` for n = 1; the patch is at their antinode),
sine-type modes the ``0`` modes (``hort`` for n = 1; a node at the patch).
The rim is fixed.

All functions are pure JAX; ``half_angle`` may be traced (it is a fitted
parameter of the gap diagnosis).
"""

from __future__ import annotations

import jax.numpy as jnp

from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.natural import modal_stiffness, ring_modal_mass

#: Harmonics kept in the loaded-mode basis: N = 40 reproduces the docs/physics.md §7
#: values to 0.05 Hz (N = 20 is within 0.2 Hz; checked in tests/test_loaded.py).
DEFAULT_HARMONICS = 40


def patch_overlap(half_angle, n_max: int = DEFAULT_HARMONICS):
    """Overlap integrals of the basis shapes over the patch ``|φ| < a`` [rad].

    **Arguments:** ``half_angle`` — contact half-angle a [rad] (scalar);
    ``n_max`` — number of harmonics N (static).

    **Returns:** ``(cc, ss)``, each ``(N, N)``: ``∫ cos iφ cos jφ dφ`` and
    ``∫ sin iφ sin jφ dφ`` over ``[−a, a]``, i, j = 1…N.
    """
    n = jnp.arange(1, n_max + 1, dtype=jnp.float64)
    i, j = n[:, None], n[None, :]
    a = jnp.asarray(half_angle, dtype=jnp.float64)

    def S(k):
        return 2.0 * a * jnp.sinc(k * a / jnp.pi)

    return 0.5 * (S(i - j) + S(i + j)), 0.5 * (S(i - j) - S(i + j))


#: Sine modes of the patch kept in :func:`tread_layer_overlap` (the layer weights g(s_k) fall as 3/s_k²).
LAYER_SINES = 256
#: Gauss–Legendre points over the patch for the projections of :func:`tread_layer_overlap`.
LAYER_QUADRATURE = 640


def layer_softening(s):
    """g(s) = 3(1 − tanh s / s)/s² (g(0) = 1): the stiffness of an incompressible tread rib of width B against a
    belt pattern of wavenumber κ along it, relative to a uniform compression, s = κB/2 (docs/physics.md §6
    ``ground_contact``, the tread layer). Series 1 − 2s²/5 + 17s⁴/105 − 62s⁶/945 below s = 0.05 (no cancellation)."""
    s = jnp.asarray(s, dtype=jnp.float64)
    small = s < 0.05
    t = jnp.where(small, 1.0, s)
    series = 1.0 - 0.4 * s**2 + (17.0 / 105.0) * s**4 - (62.0 / 945.0) * s**6
    return jnp.where(small, series, 3.0 * (1.0 - jnp.tanh(t) / t) / t**2)


def tread_layer_overlap(half_angle, radius, rib_width, n_max: int = DEFAULT_HARMONICS,
                        n_sines: int = LAYER_SINES, n_quad: int = LAYER_QUADRATURE):
    """Patch stiffness integrals of an incompressible tread of ribs of width B (docs/physics.md §6
    ``ground_contact``, the tread layer), in the units of :func:`patch_overlap` (k_trd R times these is [N/m]).

    The patch's arc ``x = Rφ ∈ [−L/2, L/2]`` (L = 2aR) is expanded in its Dirichlet sine modes
    ``s_k(x) = sin(kπ(x + L/2)/L)``; the rib's pressure vanishes at the patch's edges and at the rib's sides,
    and each sine mode is stiffened by ``k_trd g(s_k)``, s_k = kπB/(2L) (:func:`layer_softening`):

        K_ij / (k_trd R) = (2/(L R)) Σ_k g(s_k) c_ik c_jk,   c_ik = ∫ Φ_i(x/R) s_k(x) dx

    B → 0 gives :func:`patch_overlap` (Winkler, Parseval); a = 0 gives 0.

    **Returns:** ``(cc, ss)``, each ``(N, N)``, for cos iφ, cos jφ and sin iφ, sin jφ, i, j = 1…N.
    """
    import numpy as np

    a = jnp.asarray(half_angle, dtype=jnp.float64)
    L = 2.0 * a * radius
    Ls = jnp.where(L > 0, L, 1.0)
    xg, wg = np.polynomial.legendre.leggauss(n_quad)
    x, w = xg * Ls / 2.0, wg * Ls / 2.0
    k = jnp.arange(1, n_sines + 1, dtype=jnp.float64)
    sk = jnp.sin(k[:, None] * jnp.pi * (x[None, :] + Ls / 2.0) / Ls)  # (K, Q)
    n = jnp.arange(1, n_max + 1, dtype=jnp.float64)
    g = layer_softening(k * jnp.pi * rib_width / (2.0 * Ls))
    out = []
    for shape in (jnp.cos, jnp.sin):
        c = (shape(n[:, None] * x[None, :] / radius) * w) @ sk.T  # (N, K)
        out.append(jnp.where(L > 0, (2.0 / (Ls * radius)) * (c * g) @ c.T, 0.0))
    return out[0], out[1]


def loaded_angular_frequencies(
    ring: RingParams, geometry: TyreGeometry, half_angle, n_max: int = DEFAULT_HARMONICS, k_tread=None
):
    """Natural angular frequencies of the loaded standing tyre [rad/s] (docs/physics.md §6 ``ground_contact``).

    **Arguments:**

    - ``ring``, ``geometry``: the ring (``k_tread`` taken from ``ring`` unless given).
    - ``half_angle``: contact half-angle a [rad]; a = 0 gives eq. 18.
    - ``n_max``: basis size N (static).
    - ``k_tread``: radial tread stiffness k_trd [N/m²], overrides ``ring.k_tread``.

    **Returns:** ``(cos_type, sin_type)``, each shape ``(N,)``, ascending:
    the k-th entry is the mode that continues harmonic n = k + 1 of the free
    ring (``extr``/``vert`` and ``0``/``hort`` respectively).
    """
    mass, k_cos, k_sin = loaded_matrices(ring, geometry, half_angle, n_max, k_tread)
    return eigen_angular_frequencies(mass, k_cos), eigen_angular_frequencies(mass, k_sin)


def eigen_angular_frequencies(mass, stiffness):
    """``√λ`` [rad/s], ascending, of ``K φ = λ M φ`` with a diagonal ``mass`` ``(N,)`` and ``stiffness`` ``(N, N)``
    (symmetric scaling by ``1/√(M_i M_j)``; negative λ clipped to 0)."""
    scale = 1.0 / jnp.sqrt(mass[:, None] * mass[None, :])
    return jnp.sqrt(jnp.clip(jnp.linalg.eigvalsh(stiffness * scale), 0.0))


def loaded_matrices(ring: RingParams, geometry: TyreGeometry, half_angle, n_max: int = DEFAULT_HARMONICS,
                    k_tread=None):
    """Mass and stiffness of the loaded standing ring in the real basis (docs/physics.md §6 ``ground_contact``).

    **Returns:** ``(mass, k_cos, k_sin)``: ``mass`` ``(N,)`` the diagonal M_n [kg]; ``k_cos``,
    ``k_sin`` ``(N, N)`` [N/m] the stiffness of the cosine- and sine-type shapes, patch included.
    Harmonic n = 1 is the rigid translation of the belt (vertical for ``k_cos``, fore-aft for
    ``k_sin``): :mod:`ringfit.physics.wheel` borders these matrices with the wheel's body.
    """
    n = jnp.arange(1, n_max + 1, dtype=jnp.float64)
    R = geometry.radius
    kt = ring.k_tread if k_tread is None else k_tread
    # M_n = πRρA(1 + 1/n²) (natural.ring_modal_mass), K_n = πR d_n with n² d_n the numerator of eq. 18
    mass = ring_modal_mass(ring, geometry, n)
    stiff = jnp.pi * R * modal_stiffness(ring, geometry, n) / n**2
    cc, ss = patch_overlap(half_angle, n_max)
    rib = float(geometry.tread_rib_width)  # static (params.TyreGeometry): no layer is traced for B = 0
    if rib > 0:
        cc, ss = tread_layer_overlap(half_angle, R, rib, n_max)
    return mass, jnp.diag(stiff) + kt * R * cc, jnp.diag(stiff) + kt * R * ss


def loaded_natural_frequencies(
    ring: RingParams, geometry: TyreGeometry, half_angle, n_max: int = DEFAULT_HARMONICS, k_tread=None
):
    """As :func:`loaded_angular_frequencies`, in Hz: ``(cos_type, sin_type)``, each ``(N,)``."""
    c, s = loaded_angular_frequencies(ring, geometry, half_angle, n_max, k_tread)
    return c / (2.0 * jnp.pi), s / (2.0 * jnp.pi)


__all__ = ["DEFAULT_HARMONICS", "LAYER_SINES", "LAYER_QUADRATURE", "layer_softening", "tread_layer_overlap",
           "patch_overlap", "loaded_matrices", "eigen_angular_frequencies", "loaded_angular_frequencies",
           "loaded_natural_frequencies"]
