"""The air cavity of the loaded tyre: the contact flat splits the first acoustic mode (docs/physics.md §3.6, §6 ``cavity_mode``).

The cavity is a closed loop of length L_c = 2πR_c (eq. 22) whose cross-section
A(θ) changes slowly along it, so its pressure obeys Webster's equation
``(1/A)(A p′)′ + (ω/c)² p = 0`` (′ = d/ds, s = R_c θ). By Rayleigh's quotient
``ω² = c² ∫A p′² ds / ∫A p² ds``, a small change ``A = A_0 (1 + ε(θ))`` moves the
first pair (p = cos θ, sin θ; ω_a = c/R_c) by, to first order,

    δω²/ω_a² = (1/π) ∫ ε (sin²θ − cos²θ) dθ = −(1/π) ∫ ε cos 2θ dθ     (p = cos θ)
    δω²/ω_a² = +(1/π) ∫ ε cos 2θ dθ                                    (p = sin θ)

and the pair does not mix when ε is even about the patch centre (θ = 0): only
the cos 2θ part of the area change splits the pair, a uniform change moves
neither line. The belt's radial displacement w(θ) changes the cross-section by
``b·w`` over the belt width b of a section ``A_0 ≈ b·h_c`` (h_c = R − R_rim the
cavity height; with R_c the mid-height radius, ``h_c = 2(R − R_c)``), so
``ε = w/h_c`` and, with W_2 the cos 2θ coefficient of the static deflection
(``w = Σ W_n cos nθ + …``),

    ω²_cos = ω_a² (1 − W_2/h_c),    ω²_sin = ω_a² (1 + W_2/h_c).

The loaded tyre is flattened at θ = 0 (W_2 < 0): the cos line — pressure
antinodes at the patch and the top, its net force on the rim vertical — rises,
the sin line (net force fore-aft) falls. Split ``≈ f_a |W_2|/h_c``.

Rolling: the air turns with the tyre (Ω), so in the fixed frame the two waves
``e^{±iθ}`` sit at ω_a ± Ω before the flat couples them; the flat (fixed in space)
couples them with the half-split g = ω_a W_2/(2h_c), giving the fixed-frame lines
``ω_a ± √(Ω² + g²)`` (standing fore-aft / vertical at Ω = 0, travelling when Ω ≫ |g|).

Pure JAX.
"""

from __future__ import annotations

import jax.numpy as jnp

from ringfit.params import TyreGeometry
from ringfit.physics.natural import CAVITY_LENGTH, SOUND_SPEED


def cavity_height(geometry: TyreGeometry, cavity_length: float = CAVITY_LENGTH):
    """``h_c = 2(R − L_c/2π)`` [m]: belt radius minus rim radius, R_c = L_c/2π at mid-height (Table 9: 92.9 mm)."""
    return 2.0 * (geometry.radius - cavity_length / (2.0 * jnp.pi))


def deflection_cos2(solution):
    """W_2 [m]: the cos 2θ coefficient of the static radial deflection of a contact solution.

    ``solution`` is a :class:`ringfit.physics.contact.RollingSolution` (grid φ from the
    patch centre); ``W_2 = 2 Re(rfft(w)[2]) / M``.
    """
    M = solution.w.shape[-1]
    return 2.0 * jnp.real(solution.w_spectrum[..., 2]) / M


def static_cavity_split(ring, geometry: TyreGeometry, load_n, *, road=None, cavity_length: float = CAVITY_LENGTH):
    """W_2/h_c of the standing tyre at ``load_n`` [N]: :func:`deflection_cos2` of the static contact solve
    (Ω = 0, :func:`ringfit.physics.contact.solve_rolling_jit`; ``road`` None = flat) over :func:`cavity_height`."""
    from ringfit.physics.contact import ContactSolver, solve_rolling_jit
    from ringfit.physics.operating import FlatRoad, OperatingPoint

    sol = solve_rolling_jit(ring, geometry, OperatingPoint(0.0, load_n, road if road is not None else FlatRoad()),
                            solver=ContactSolver())
    return deflection_cos2(sol) / cavity_height(geometry, cavity_length)


def loaded_cavity_lines(omega_acoustic, w2_over_height, omega=0.0):
    """The first acoustic pair of the loaded, possibly rolling tyre in the fixed frame [rad/s].

    **Arguments:** ``omega_acoustic`` ω_a (unloaded, = 2π c/L_c); ``w2_over_height`` W_2/h_c
    (:func:`deflection_cos2`, :func:`cavity_height`); ``omega`` the wheel speed Ω [rad/s].
    Broadcast together.

    **Returns:** ``(fore_aft, vertical)``. At Ω = 0 exactly
    ``ω_a √(1 + W_2/h_c)`` and ``ω_a √(1 − W_2/h_c)`` (the sin and cos lines); with Ω the
    lower and upper of ``ω_a ± √(Ω² + g²)``, g = ω_a W_2/(2h_c), labelled by continuity
    (the vertical line is the upper one when W_2 < 0, a flattened patch).
    """
    wa = jnp.asarray(omega_acoustic, dtype=jnp.float64)
    e = jnp.asarray(w2_over_height, dtype=jnp.float64)
    om = jnp.asarray(omega, dtype=jnp.float64)
    sin_line = wa * jnp.sqrt(jnp.clip(1.0 + e, 0.0))
    cos_line = wa * jnp.sqrt(jnp.clip(1.0 - e, 0.0))
    g = 0.5 * wa * e
    root = jnp.sqrt(om * om + g * g)
    lower, upper = wa - root, wa + root
    spinning = om != 0
    fore_aft = jnp.where(spinning, jnp.where(e <= 0, lower, upper), sin_line)
    vertical = jnp.where(spinning, jnp.where(e <= 0, upper, lower), cos_line)
    return fore_aft, vertical


def loaded_cavity_frequencies(ring, geometry: TyreGeometry, load_n, omega=0.0, *, road=None,
                              sound_speed: float = SOUND_SPEED, cavity_length: float = CAVITY_LENGTH):
    """``(fore_aft, vertical)`` [Hz] of the loaded tyre's first acoustic pair (docs/physics.md §6 ``cavity_mode``).

    The static contact solve at ``load_n`` (Ω = 0, :func:`ringfit.physics.contact.solve_rolling`)
    gives W_2; then :func:`loaded_cavity_lines` at the wheel speed ``omega`` [rad/s].
    Also returns W_2/h_c: ``(fore_aft_hz, vertical_hz, w2_over_height)``.
    """
    e = static_cavity_split(ring, geometry, load_n, road=road, cavity_length=cavity_length)
    wa = 2.0 * jnp.pi * sound_speed / cavity_length
    fa, vt = loaded_cavity_lines(wa, e, omega)
    return fa / (2.0 * jnp.pi), vt / (2.0 * jnp.pi), e


__all__ = ["cavity_height", "deflection_cos2", "static_cavity_split", "loaded_cavity_lines", "loaded_cavity_frequencies"]
