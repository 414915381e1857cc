"""The tyre's state — load, inflation pressure, tread depth, drive/brake slip, wheel speed — in the one forward
model (docs/physics.md §13).

The tyre file's ring and geometry hold at its reference pressure p_ref and tread depth d_ref; the laws of
:class:`~ringfit.params.TyreLaws` carry them to another state:

- :func:`state_tyre` — pressure p (the pretension p·b·R and the pressure-proportional shares of k_w, k_v,
  k_trd) and tread depth d (τ, k_trd, k_x, ρA) → the ``(TyreGeometry, RingParams, k_x)`` at the state;
- :func:`state_profile` — the ``(ProfileModel, RingParams, TyreGeometry)`` that
  :func:`ringfit.physics.profile.profile_channels` reads at a state: the ring and geometry above, and the lever
  brush (:class:`ringfit.physics.contact.BrushShearLoad`) at the state's road length per radian (slip κ or
  r_road given, not free rolling) when the tyre has a brush;
- :func:`state_solution` — one state solved (pure JAX): the contact solutions, the sensor channels and
  :class:`StateQuantities` (Fx, drive torque, r_free, r_road, κ, axle height H, speed V = Ω·r_road, patch);
- :func:`solve_state` — the same, compiled once per model structure, from Python numbers.

Nothing here is a second forward model: the channels are :func:`ringfit.physics.profile.rolling_passes`'s.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ringfit.params import RingParams, TyreGeometry, TyreLaws
from ringfit.physics.contact import BrushShearLoad, ContactSolver, RollingSolution, as_traced, contact_length
from ringfit.physics.operating import FlatRoad, OperatingPoint
from ringfit.physics.profile import ProfileModel, rolling_passes, spectral_stage, full_band


#: Fixed-point passes of the lever brush and their relaxation (docs/physics.md §13): the brush's loads move the
#: patch they are computed on, so one step (what ``ProfileModel`` does by default) leaves the radial reading 2–5 %
#: (RMS) from the converged state at a 2 % drive/brake slip on the Table 9 tyre (k_x = 15 MN/m², 4 kN) — a load
#: error of 3–5 % — and plain steps alternate (ratio ≈ −0.28); relaxed by 0.85, six passes agree with twenty to
#: 1e-5 in Fx and 1e-4 of the reading (tests/test_state_physics.py).
BRUSH_PASSES = 6
BRUSH_RELAXATION = 0.85


class TyreState(eqx.Module):
    """A state of the tyre (docs/physics.md §13).

    - ``load``: Fz [N]; ``pressure``: inflation (gauge) pressure p [Pa]; ``tread_depth``: d [m].
    - ``slip``: longitudinal slip ratio κ = r_free/r_road − 1 (SAE: > 0 driving, < 0 braking).
    - ``omega``: Ω [rad/s] (the wheel's rotation rate).
    - ``r_road``: the road length per radian of wheel rotation, V/Ω [m], given instead of ``slip`` (None:
      from ``slip``).
    """

    load: float
    pressure: float
    tread_depth: float
    slip: float = 0.0
    omega: float = 0.0
    r_road: object = None


class StateQuantities(eqx.Module):
    """What a state means at the wheel (docs/physics.md §13), scalars [SI].

    ``fx`` Fx [N] (the tips' net force on the tyre along travel, driving +); ``torque`` T = Fx·H [N m]
    (drive +); ``r_free`` and ``r_road`` [m] (free-rolling and actual road length per radian); ``slip`` κ;
    ``axle_height`` H [m]; ``speed`` V = Ω·r_road [m/s]; ``deflection`` R_out − H [m]; ``patch_length``
    [m] (along the outer radius); ``outer_radius`` R + τ(d) [m]. Without a brush r_free = r_road = R_out − δ/3
    (docs/physics.md §4.3) and Fx = 0.
    """

    fx: jax.Array
    torque: jax.Array
    r_free: jax.Array
    r_road: jax.Array
    slip: jax.Array
    axle_height: jax.Array
    speed: jax.Array
    deflection: jax.Array
    patch_length: jax.Array
    outer_radius: jax.Array


def state_tyre(geometry: TyreGeometry, ring: RingParams, laws: TyreLaws, pressure, tread_depth):
    """The reference tyre carried to pressure p [Pa] and tread depth d [m] (docs/physics.md §13.1, §13.3).

    Pressure: the geometry's p (so P = p·b/R and T0 = p·b·R), ``k(p) = k·[1 − s + s·p/p_ref]`` for k_w, k_v and
    k_trd with their shares s. Tread depth (only with ``laws.has_tread_depth``; else d is ignored):
    ``τ(d) = τ_ref + (d − d_ref)``, ``k_trd(d) = k_trd·τ_ref/τ(d)``, ``k_x(d) = k_x·τ_ref/τ(d)``,
    ``ρA(d) = ρA + ρ_t·b·λ·(d − d_ref)``. At p_ref and d_ref every value is the file's, exactly.

    **Returns:** ``(geometry, ring, k_x)`` at the state (jit-, vmap- and grad-compatible).
    """
    ratio = pressure / geometry.pressure

    def scaled(value, share):
        return value * (1.0 - share + share * ratio)

    kw = scaled(ring.kw, laws.kw_share)
    kv = scaled(ring.kv, laws.kv_share)
    k_tread = scaled(ring.k_tread, laws.k_tread_share)
    k_x = laws.k_x
    tau = geometry.tread_thickness
    rho_a = ring.rho_a
    if laws.has_tread_depth:
        change = tread_depth - laws.tread_depth_ref
        tau_d = geometry.tread_thickness + change
        stiffening = geometry.tread_thickness / tau_d
        k_tread = k_tread * stiffening
        k_x = k_x * stiffening
        rho_a = ring.rho_a + laws.tread_density * geometry.width * laws.land_ratio * change
        tau = tau_d
    geometry = TyreGeometry(geometry.radius, geometry.width, pressure, tau, geometry.tread_rib_width,
                            name=geometry.name)
    return geometry, ring.replace(kw=kw, kv=kv, k_tread=k_tread, rho_a=rho_a), k_x


def state_profile(geometry: TyreGeometry, ring: RingParams, laws: TyreLaws, state: TyreState, *,
                  model: ProfileModel = ProfileModel()):
    """``(model, ring, geometry)`` at ``state`` for :func:`ringfit.physics.profile.profile_channels` (§13).

    ``model`` gets the lever brush (``BrushShearLoad(k_x(d), μ, lever=True)`` at ``state.r_road`` or
    ``state.slip``) when ``laws.has_brush``; the ring and geometry are :func:`state_tyre`'s.
    """
    geometry, ring, k_x = state_tyre(geometry, ring, laws, state.pressure, state.tread_depth)
    if laws.has_brush:
        if state.r_road is not None:
            brush = BrushShearLoad(k_x, laws.friction, lever=True, r_road=state.r_road)
        else:
            brush = BrushShearLoad(k_x, laws.friction, lever=True, slip=state.slip)
        model = dataclasses.replace(model.with_load_hook(brush), hook_passes=max(model.hook_passes, BRUSH_PASSES),
                                    hook_relaxation=BRUSH_RELAXATION)
    return model, ring, geometry


def _brush(model: ProfileModel):
    hooks = [h for h in model.load_hooks if isinstance(h, BrushShearLoad)]
    return hooks[-1] if hooks else None


def state_solution(geometry: TyreGeometry, ring: RingParams, laws: TyreLaws, state: TyreState, *,
                   model: ProfileModel = ProfileModel(), solver: ContactSolver = ContactSolver(), road=FlatRoad(),
                   offset=0.0) -> tuple[RollingSolution, jax.Array, StateQuantities]:
    """One state solved (pure JAX; jit, vmap and grad): ``(solution, channels (2, M), quantities)``.

    The channels are :func:`ringfit.physics.profile.rolling_passes`' (then the model's channel filters and the
    angle ``offset`` [rad], as :func:`~ringfit.physics.profile.profile_channels`); the quantities read the brush's
    tips on the pass its last loads were computed from (at the fixed point, :data:`BRUSH_PASSES`, the solution).
    """
    model, ring_s, geometry_s = state_profile(geometry, ring, laws, state, model=model)
    ring_s = model.ring(ring_s)
    omega = jnp.asarray(state.omega, dtype=jnp.float64)
    first, sol, channels = rolling_passes(model, ring_s, geometry_s, OperatingPoint(omega, state.load, road), solver)
    channels = spectral_stage(model, channels[None], ring_s, geometry_s, omega[None], full_band(1, solver.n_grid),
                              offset)[0]
    brush = _brush(model)
    outer = geometry_s.outer_radius
    if brush is None:
        r_free = r_road = outer - sol.deflection / 3.0
        fx = jnp.zeros(())
        slip = jnp.zeros(())
    else:
        tips = brush.tips(first, ring_s, geometry_s)
        r_free, r_road = tips.r_free, tips.r_road
        fx = tips.fx(first, geometry_s)
        slip = r_free / r_road - 1.0
    H = sol.axle_height
    quantities = StateQuantities(fx=fx, torque=fx * H, r_free=r_free, r_road=r_road, slip=slip, axle_height=H,
                                 speed=omega * r_road, deflection=sol.deflection, patch_length=contact_length(sol),
                                 outer_radius=outer)
    return sol, channels, quantities


@eqx.filter_jit
def _solve_state(geometry, ring, laws, state, model, solver, road, offset):
    return state_solution(geometry, ring, laws, state, model=model, solver=solver, road=road, offset=offset)


def solve_state(geometry: TyreGeometry, ring: RingParams, laws: TyreLaws, state: TyreState, *,
                model: ProfileModel = ProfileModel(), solver: ContactSolver = ContactSolver(), road=FlatRoad(),
                offset: float = 0.0):
    """:func:`state_solution` compiled once per model structure (Python floats passed as arrays).

    **Returns:** ``(solution, channels (2, M) as NumPy, quantities as a dict of floats)``.
    """
    sol, channels, q = _solve_state(*as_traced((geometry, ring, laws, state, model)), solver, as_traced(road),
                                    np.float64(offset))
    return sol, np.asarray(channels), {k: float(getattr(q, k)) for k in QUANTITY_NAMES}


#: Fields of :class:`StateQuantities`, in order.
QUANTITY_NAMES = ("fx", "torque", "r_free", "r_road", "slip", "axle_height", "speed", "deflection", "patch_length",
                  "outer_radius")

__all__ = ["TyreState", "StateQuantities", "QUANTITY_NAMES", "state_tyre", "state_profile", "state_solution",
           "solve_state"]
