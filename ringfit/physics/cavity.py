"""The air cavity of the loaded tyre: the contact flat splits the first acoustic mode (docs/physics.md §3.6, §6 ``cavity_mode``).

The cavity is a loop of air whose cross-section the contact flat narrows. Webster's equation on that loop, by
Rayleigh's quotient to first order, splits the first acoustic pair by the cos 2θ coefficient W_2 of the belt's
static deflection over the cavity height h_c: ``ω²_vertical = ω_a²(1 − W_2/h_c)``, ``ω²_fore-aft = ω_a²(1 +
W_2/h_c)``; rolling, the air turns with the tyre and the fixed-frame lines are ``ω_a ± √(Ω² + g²)``. The
derivation, the load law and the seed tyre's numbers are in docs/physics.md §6 (*the loaded cavity*); the
finite-volume check of Webster's equation is ``tests/test_cavity.py``. Pure JAX.

Example (the seed tyre at its rated load, standing on a flat road)::

    from ringfit.data import path
    from ringfit.io.tyre import read_tyre
    from ringfit.physics.cavity import loaded_cavity_frequencies
    tyre = read_tyre(path("table9.tyre.toml"))
    fore_aft, vertical, w2_h = loaded_cavity_frequencies(tyre.ring, tyre.geometry, 6570.0)
    # 214.5 Hz, 222.9 Hz (a split of 8.4 Hz), W_2/h_c = -0.0385
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
