"""Per-harmonic response of the steadily rolling ring (docs/physics.md §4.1–4.2).

In the axle frame the rolling ring's deformation is stationary. With
``w = Σ W_n e^{inφ}``, ``v = Σ V_n e^{inφ}`` and loads ``q_w = Σ Q_n e^{inφ}``,
``q_v = Σ S_n e^{inφ}`` every harmonic decouples:

    D_n [W_n, V_n]ᵀ = [Q_n, S_n]ᵀ,
    D_n = K_n^c + (EA/R² − ρAΩ²) E_n + (1−χ) ρAΩ² F_n + Σ (damping and extra terms).

``K_n^c`` is the elastic part without EA (bending, pressure, foundation), taken
from :func:`ringfit.physics.natural.extensible_stiffness_matrix` in the complex
basis, so eq. 18 / §2.2 live in one place. The **inextensible** ring (default)
is the reduction of the same ``D_n`` onto the constraint ``w + v′ = 0``
(``V_n = (i/n) W_n``): ``d_n = uᴴ D_n u`` with ``u = [1, i/n]ᵀ``; the EA part
vanishes on ``u`` and ``uᴴE_n u = 0`` (no speed dependence for χ = 1).

Composition: everything that modifies the operator is an
:class:`AbstractOperatorTerm` (a callable returning a complex ``(…, 2, 2)``
addition to ``D_n``). Damping is one such term (:class:`Hysteretic` — the
default, η = 2ζ — or :class:`Viscous`); effects of the gap diagnosis add
further terms through :attr:`RingModel.terms` without copying this module.

Shapes: ``n`` is an array of harmonic numbers (float, any shape); operators
have shape ``n.shape + (2, 2)`` (rows/cols radial, tangential), complex128.
Stiffnesses are per unit length of ring [N/m²]; Ω in rad/s.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.natural import extensible_stiffness_matrix

#: Number of grid points / 2 × harmonics used by default: M = 512 (|n| ≤ 255, Nyquist zeroed)
#: is within 0.1 % of M = 8192 for the sensor signals (docs/physics.md §4.5; checked in
#: tests/test_rolling_verification.py).
DEFAULT_GRID = 512

# complex-basis pattern of the real-basis K_n (w ∝ e^{inφ}: off-diagonals ±i·k12)
_COMPLEX_BASIS = np.array([[1.0, 1.0j], [-1.0j, 1.0]], dtype=np.complex128)  # a constant: no JAX op at import


def harmonic_numbers(n_grid: int):
    """Harmonic numbers n = 0 … M/2 of a real field sampled on M grid points (rfft order), float64, shape ``(M//2+1,)``."""
    return jnp.arange(n_grid // 2 + 1, dtype=jnp.float64)


def nyquist_mask(n_grid: int):
    """1.0 for every rfft harmonic except the Nyquist one (zeroed, docs/physics.md §4.5), shape ``(M//2+1,)``."""
    m = jnp.ones(n_grid // 2 + 1)
    return m.at[-1].set(0.0) if n_grid % 2 == 0 else m


def elastic_stiffness(ring: RingParams, geometry: TyreGeometry, n):
    """K_n^c without the membrane term [N/m²], complex, shape ``n.shape + (2, 2)`` (docs/physics.md §4.2).

    Bending, pressure (follower) and foundation terms of the §2.2 matrix in
    the complex basis ``e^{inφ}``; undamped (damping is a separate term).
    """
    K = extensible_stiffness_matrix(ring.replace(ea=0.0), geometry, n)
    return K.astype(jnp.complex128) * _COMPLEX_BASIS


def membrane_matrix(n):
    """E_n = [[1, in], [−in, n²]] (dimensionless), shape ``n.shape + (2, 2)`` (docs/physics.md §4.2).

    Multiplies EA/R² (membrane stiffness) and −ρAΩ² (transport inertia).
    """
    n = jnp.asarray(n, dtype=jnp.float64)
    one = jnp.ones_like(n)
    return jnp.stack(
        [jnp.stack([one + 0j, 1j * n], -1), jnp.stack([-1j * n, n**2 + 0j], -1)], -2
    )


def centrifugal_matrix(n):
    """F_n = [[−n², −in], [in, −1]] (dimensionless), shape ``n.shape + (2, 2)`` (docs/physics.md §4.2).

    Multiplies (1 − χ) ρAΩ², the centrifugal load not carried as belt tension.
    """
    n = jnp.asarray(n, dtype=jnp.float64)
    one = jnp.ones_like(n)
    return jnp.stack(
        [jnp.stack([-(n**2) + 0j, -1j * n], -1), jnp.stack([1j * n, -one + 0j], -1)], -2
    )


class AbstractOperatorTerm(eqx.Module):
    """An addition to the per-harmonic operator D_n (damping, or a gap-diagnosis effect)."""

    @abc.abstractmethod
    def __call__(self, ring: RingParams, geometry: TyreGeometry, n, omega):
        """ΔD_n [N/m²], complex, shape ``n.shape + (2, 2)``; ``n`` float harmonic numbers, ``omega`` Ω [rad/s]."""


class Hysteretic(AbstractOperatorTerm):
    """Hysteretic (structural) damping: ``iη s_n K_n^c`` with s_n = sign(n) (docs/physics.md §4.2).

    Multiplies EI, k_w, k_v and P by (1 + iη s_n); EA stays real. ``loss_factor``
    η defaults (``None``) to ``2 ζ`` from ``ring.damping_ratio``, which gives every
    flexural mode the damping ratio ζ. Independent of speed.
    """

    loss_factor: float | None = None

    def __call__(self, ring, geometry, n, omega):
        eta = 2.0 * ring.damping_ratio if self.loss_factor is None else self.loss_factor
        return 1j * eta * jnp.sign(n)[..., None, None] * elastic_stiffness(ring, geometry, n)


class Viscous(AbstractOperatorTerm):
    """Viscous damping in the material frame: ``diag(i nΩ c_w, i nΩ c_v)`` (docs/physics.md §4.2).

    The material sees harmonic n at frequency nΩ, so the loss grows with speed
    (unlike :class:`Hysteretic`). ``c_w``, ``c_v`` [N s/m²] per unit length.
    """

    c_w: float
    c_v: float = 0.0

    def __call__(self, ring, geometry, n, omega):
        n = jnp.asarray(n, dtype=jnp.float64)
        z = jnp.zeros_like(n) + 0j
        return jnp.stack(
            [jnp.stack([1j * n * omega * self.c_w, z], -1), jnp.stack([z, 1j * n * omega * self.c_v], -1)], -2
        )


class NoDamping(AbstractOperatorTerm):
    """No damping (ΔD_n = 0)."""

    def __call__(self, ring, geometry, n, omega):
        return jnp.zeros(jnp.shape(n) + (2, 2), dtype=jnp.complex128)


class RingModel(eqx.Module):
    """Which ring form and which operator terms (docs/physics.md §4.2).

    **Fields:**

    - ``extensible`` (static): ``False`` (default) = inextensible reduction
      ``d_n``; ``True`` = full 2×2 ``D_n`` with ``ring.ea`` (must be finite).
    - ``damping``: an :class:`AbstractOperatorTerm`; default :class:`Hysteretic`.
    - ``terms``: further operator terms added to ``D_n`` (gap-diagnosis effects).
    """

    extensible: bool = eqx.field(static=True, default=False)
    damping: AbstractOperatorTerm = Hysteretic()
    terms: tuple = ()


def ring_operator(ring: RingParams, geometry: TyreGeometry, n, omega, model: RingModel = RingModel()):
    """D_n of the steadily rolling ring [N/m²], complex, shape ``n.shape + (2, 2)`` (docs/physics.md §4.2).

    ``D_n = K_n^c + (EA/R² − ρAΩ²)E_n + (1−χ)ρAΩ²F_n + damping + terms``; the EA
    part is included only for ``model.extensible``. ``D_{−n} = conj(D_n)``.

    **Arguments:** ``n`` — harmonic numbers (float array); ``omega`` — Ω [rad/s].
    """
    n = jnp.asarray(n, dtype=jnp.float64)
    R = geometry.radius
    inertia = ring.rho_a * omega**2
    membrane = (ring.ea / R**2 if model.extensible else 0.0) - inertia
    D = (
        elastic_stiffness(ring, geometry, n)
        + membrane * membrane_matrix(n)
        + (1.0 - ring.chi) * inertia * centrifugal_matrix(n)
        + model.damping(ring, geometry, n, omega)
    )
    for term in model.terms:
        D = D + term(ring, geometry, n, omega)
    return D


def inextensible_vector(n):
    """u_n = [1, i/n] with V_n = (i/n) W_n, shape ``n.shape + (2,)`` (docs/physics.md §4.2); n = 0 gives [0, 0]."""
    n = jnp.asarray(n, dtype=jnp.float64)
    nz = n != 0
    inv = jnp.where(nz, 1.0 / jnp.where(nz, n, 1.0), 0.0)
    return jnp.stack([nz.astype(jnp.complex128), 1j * inv], -1)


def reduced_operator(D, n):
    """Inextensible operator ``d_n = uᴴ D_n u`` [N/m²], complex, shape ``n.shape`` (docs/physics.md §4.2).

    For the Table 9 ring with hysteretic damping this is
    ``[EI(n²−1)²/R⁴ + P(n²−1) + k_w + k_v/n²](1+iη s_n) − (1−χ)ρAΩ²(n²−1)²/n²``.
    Meaningless at n = 0 (W_0 = 0 there).
    """
    u = inextensible_vector(n)
    return jnp.einsum("...i,...ij,...j->...", jnp.conj(u), D, u)


def receptance(ring: RingParams, geometry: TyreGeometry, n, omega, model: RingModel = RingModel()):
    """Per-harmonic receptance G_n with ``[W_n, V_n] = G_n [Q_n, S_n]`` [m²/N], shape ``n.shape + (2, 2)``.

    Extensible: ``G_n = D_n⁻¹``. Inextensible (docs/physics.md §4.2):
    ``G_n = u uᴴ / d_n`` for n ≠ 0 and ``G_0 = diag(0, 1/D_0[1,1])``
    (W_0 = 0, V_0 = S_0/(k_v − (1−χ)ρAΩ²)). The radial receptance of §4.4 is
    ``C_n = G_n[0, 0]``.
    """
    n = jnp.asarray(n, dtype=jnp.float64)
    D = ring_operator(ring, geometry, n, omega, model)
    if model.extensible:
        det = D[..., 0, 0] * D[..., 1, 1] - D[..., 0, 1] * D[..., 1, 0]
        adj = jnp.stack(
            [jnp.stack([D[..., 1, 1], -D[..., 0, 1]], -1), jnp.stack([-D[..., 1, 0], D[..., 0, 0]], -1)], -2
        )
        return adj / det[..., None, None]
    u = inextensible_vector(n)
    nz = n != 0
    d = jnp.where(nz, reduced_operator(D, n), 1.0)
    G = u[..., :, None] * jnp.conj(u)[..., None, :] / d[..., None, None]
    g0 = jnp.where(nz, 0.0, 1.0 / D[..., 1, 1])
    return G.at[..., 1, 1].add(g0)


def harmonic_response(G, Q, S):
    """``[W, V] = G [Q, S]`` for every harmonic; ``Q``, ``S`` shape ``n.shape`` (any consistent spectra), returns ``(W, V)``."""
    W = G[..., 0, 0] * Q + G[..., 0, 1] * S
    V = G[..., 1, 0] * Q + G[..., 1, 1] * S
    return W, V


def harmonic_basis(k, extensible: bool):
    """Per-harmonic basis ``b_k`` with ``(W_k, V_k) = b_k q_k``, complex ``k.shape + (2, d)``.

    Inextensible (d = 1): ``u_k = [1, i/k]``, ``u_0 = [0, 1]`` (docs/physics.md §4.2);
    extensible (d = 2): the identity.
    """
    k = jnp.asarray(k, dtype=jnp.float64)
    if extensible:
        return jnp.broadcast_to(jnp.eye(2, dtype=jnp.complex128), k.shape + (2, 2))
    u = inextensible_vector(k)
    u0 = jnp.array([0.0, 1.0], dtype=jnp.complex128)
    return jnp.where((k == 0)[..., None], u0, u)[..., None]


__all__ = [
    "DEFAULT_GRID", "harmonic_numbers", "nyquist_mask", "elastic_stiffness", "membrane_matrix",
    "centrifugal_matrix", "AbstractOperatorTerm", "Hysteretic", "Viscous", "NoDamping", "RingModel",
    "ring_operator", "inextensible_vector", "harmonic_basis", "reduced_operator", "receptance", "harmonic_response",
]
