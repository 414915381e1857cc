"""Contact of the rolling ring with a flat road or a drum through radial tread springs (docs/physics.md §4.3–4.4).

Radial, frictionless, unilateral tread springs between ring and road:
``δ(φ) = R + τ + w(φ) − s(φ)``, ``p(φ) = k_trd·max(δ, 0)``, ``q_w = −p``; the
load Fz = R∫p cos φ dφ is imposed and the axle height H is an unknown.

Algorithm (§4.4), jit- and vmap-compatible:

1. Radial receptance ``C_n = G_n[0,0]`` (:func:`ringfit.physics.rolling.receptance`),
   kernel ``c = IFFT(C)``; on a fixed **candidate window** |φ| ≤ ``window_deg``
   (K grid points, static) the dense circulant block ``C_KK``.
2. Active-set (semi-smooth) Newton with a mask over the window: bordered
   system in (p_A, H), ``A ← {δ > 0}``, until the set repeats (and, for a drum,
   H has settled); at most ``max_iter`` steps, in a ``lax.while_loop`` on
   stopped gradients.
3. One more bordered solve at the **frozen** active set with live parameters.
   Its derivative is the implicit-function-theorem derivative of the contact
   solution (exact wherever the active set is locally constant, i.e. almost
   everywhere), so ``jax.grad`` works with respect to every parameter
   (ring, geometry, load, speed, drum diameter).

Extra loads (e.g. tread shear of the gap diagnosis) enter as given grid loads
``extra_load = (q_w, q_v)`` [N/m] whose displacement is added to ``w``.
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ringfit._cache import jit
from ringfit.io.profiles import grid_angles_deg
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.operating import OperatingPoint
from ringfit.physics.rolling import (
    DEFAULT_GRID,
    RingModel,
    harmonic_numbers,
    harmonic_response,
    nyquist_mask,
    receptance,
)

#: Initial penetration guess of §4.4: H0 = R + τ − 0.01 m.
INITIAL_DEFLECTION = 0.01


class ContactSolver(eqx.Module):
    """Static settings of the contact solve (docs/physics.md §4.4–4.5).

    - ``n_grid``: M grid points over the revolution (harmonics |n| < M/2);
      default 512 (§4.5: sensor signals within 0.1 % of M = 8192).
    - ``window_deg``: half-width of the candidate window around φ = 0 [deg];
      the patch must lie strictly inside (checked: ``RollingSolution.window_ok``).
    - ``max_iter``: cap on active-set iterations (2–4 are typical).
    - ``strict_window``: a solution whose patch reaches the window's edge (``window_ok`` false) is NaN (axle
      height, pressure, displacements) instead of the window-clipped one — for a window narrowed to the patches
      a problem has (identify's posterior, docs/physics.md §12.3), where a clipped patch would be a wrong
      answer; NaN makes a log density −inf there.
    - ``differentiable``: False skips step 3 (the solve at the frozen set, whose only purpose is the derivative):
      the iteration's last solve is the answer (the same to rounding: the set repeated and H settled to 1e-9),
      one dense solve fewer of the 3–6, but **no derivative** (every parameter's is 0). For evaluations that
      are never differentiated (a sampler's log density, docs/physics.md §12.1).
    - ``start_compliance`` [m/N]: start the active set from the deflection Fz × this (0: the fixed
      :data:`INITIAL_DEFLECTION`); a value read off a solution near by (identify's posterior) starts the set at
      about its answer, two iterations instead of four or five. The answer is the same; only the path differs.
    """

    n_grid: int = eqx.field(static=True, default=DEFAULT_GRID)
    window_deg: float = eqx.field(static=True, default=35.0)
    max_iter: int = eqx.field(static=True, default=30)
    strict_window: bool = eqx.field(static=True, default=False)
    differentiable: bool = eqx.field(static=True, default=True)
    start_compliance: float = eqx.field(static=True, default=0.0)

    def grid(self):
        """φ_j = −π + 2πj/M [rad], shape ``(M,)``: the profile grid :func:`~ringfit.io.profiles.grid_angles_deg` in radians."""
        return jnp.asarray(np.radians(grid_angles_deg(self.n_grid)))

    def window(self) -> tuple[int, int]:
        """(first index, K) of the candidate window |φ_j| ≤ window_deg (static ints)."""
        M = self.n_grid
        half = int(math.floor(math.radians(self.window_deg) / (2.0 * math.pi / M)))
        return M // 2 - half, 2 * half + 1


class RollingSolution(eqx.Module):
    """Steady rolling state on the grid φ_j (docs/physics.md §4).

    **Fields** (SI; ``(M,)`` grid arrays, ``(M//2+1,)`` rfft spectra):

    - ``phi``: grid angles [rad]; ``omega``: Ω [rad/s]; ``load``: Fz [N].
    - ``pressure``: contact pressure p ≥ 0 [N/m] per unit ring length.
    - ``penetration``: δ [m] (negative outside the patch; −inf where the road is out of reach).
    - ``w``, ``v``: radial / tangential ring displacement [m].
    - ``w_spectrum``, ``v_spectrum``: ``rfft(w)``, ``rfft(v)`` (grid spectra, complex).
    - ``axle_height``: H [m] (above the road, or above the top of the drum).
    - ``outer_radius``: R + τ [m]; ``fx``: Fx = −R∫p sin φ dφ [N] (rearward +); ``fz``: R∫p cos φ dφ [N].
    - ``iterations``: active-set iterations; ``converged``: the set repeated;
      ``window_ok``: the patch lies strictly inside the candidate window.
    """

    phi: jax.Array
    omega: jax.Array
    load: jax.Array
    pressure: jax.Array
    penetration: jax.Array
    w: jax.Array
    v: jax.Array
    w_spectrum: jax.Array
    v_spectrum: jax.Array
    axle_height: jax.Array
    outer_radius: jax.Array
    fx: jax.Array
    fz: jax.Array
    iterations: jax.Array
    converged: jax.Array
    window_ok: jax.Array

    @property
    def deflection(self):
        """Vertical deflection R + τ − H [m]."""
        return self.outer_radius - self.axle_height

    @property
    def ok(self):
        """Converged with the patch inside the window (bool array)."""
        return self.converged & self.window_ok


def tread_pressure(penetration, k_tread):
    """Unilateral tread-spring law ``p = k_trd·max(δ, 0)`` [N/m] (docs/physics.md §4.3)."""
    return k_tread * jnp.maximum(penetration, 0.0)


def circulant_block(kernel, first: int, size: int):
    """Dense ``(size, size)`` block ``c[(i − j) mod M]`` of the circular convolution with ``kernel`` (shape ``(M,)``)."""
    idx = jnp.arange(first, first + size)
    return kernel[(idx[:, None] - idx[None, :]) % kernel.shape[0]]


def _bordered_solve(mask, h0, ckk, phi_k, w_ext_k, k_tread, outer_radius, load, radius, dphi, road):
    """Bordered active-set system of §4.4 at fixed ``mask``, road linearised at ``h0``.

    Rows in the set: ``p_j + k (C p)_j + k s'_j H = k (R+τ + w_ext_j − s_j + s'_j H0)``;
    rows outside: ``p_j = 0``; last row: ``R Δφ Σ cos φ_j p_j = Fz``.
    Returns ``(p_k, H)``.
    """
    s, ds = jax.jvp(lambda h: road.distance(phi_k, h), (h0,), (jnp.ones_like(h0),))
    m = mask.astype(jnp.float64)
    K = phi_k.shape[0]
    A = jnp.eye(K) + k_tread * m[:, None] * ckk
    col = k_tread * m * ds
    rhs = k_tread * m * (outer_radius + w_ext_k - jnp.where(mask, s, 0.0) + ds * h0)
    row = radius * dphi * jnp.cos(phi_k)
    top = jnp.concatenate([A, col[:, None]], axis=1)
    bottom = jnp.concatenate([row, jnp.zeros(1)])[None, :]
    x = jnp.linalg.solve(jnp.concatenate([top, bottom], axis=0), jnp.concatenate([rhs, load[None]]))
    return x[:K] * m, x[K]


def solve_rolling(
    ring: RingParams,
    geometry: TyreGeometry,
    operating: OperatingPoint,
    *,
    model: RingModel = RingModel(),
    solver: ContactSolver = ContactSolver(),
    extra_load=None,
) -> RollingSolution:
    """Steady rolling with tread-spring contact at imposed load (docs/physics.md §4.3–4.4).

    **Arguments:**

    - ``ring``, ``geometry``: ring parameters (``k_tread`` is the tread spring) and
      geometry (``tread_thickness`` τ).
    - ``operating``: Ω [rad/s], Fz [N] and the road (:mod:`ringfit.physics.operating`).
    - ``model``: ring form and operator terms (:class:`~ringfit.physics.rolling.RingModel`).
    - ``solver``: grid size, candidate window, iteration cap (static).
    - ``extra_load``: optional ``(q_w, q_v)`` grid loads [N/m], shape ``(M,)`` each, added to the contact load.

    **Returns:** :class:`RollingSolution`. jit-, vmap- and grad-compatible
    (gradients by implicit differentiation at the converged active set).
    """
    M = solver.n_grid
    phi = solver.grid()
    dphi = 2.0 * jnp.pi / M
    R = geometry.radius
    outer = geometry.outer_radius
    omega = jnp.asarray(operating.omega, dtype=jnp.float64)
    load = jnp.asarray(operating.load, dtype=jnp.float64)
    road = operating.road
    k = ring.k_tread

    n = harmonic_numbers(M)
    G = receptance(ring, geometry, n, omega, model) * nyquist_mask(M)[:, None, None].astype(jnp.complex128)
    kernel = jnp.fft.irfft(G[:, 0, 0], M)  # c = IFFT(C): w = -c ⊛ p
    first, K = solver.window()
    ckk = circulant_block(kernel, first, K)
    phi_k = phi[first : first + K]

    if extra_load is None:
        q_ext = s_ext = jnp.zeros(M // 2 + 1, dtype=jnp.complex128)
    else:
        q_ext, s_ext = (jnp.fft.rfft(jnp.asarray(q, dtype=jnp.float64)) for q in extra_load)
    w_ext_spec, v_ext_spec = harmonic_response(G, q_ext, s_ext)
    w_ext = jnp.fft.irfft(w_ext_spec, M)
    w_ext_k = w_ext[first : first + K]

    # --- active-set iteration on stopped gradients --------------------------------
    sg = jax.lax.stop_gradient
    fixed = (sg(ckk), phi_k, sg(w_ext_k), sg(k), sg(outer), sg(load), sg(R), dphi, sg(road))
    h_init = sg(outer) - (INITIAL_DEFLECTION if solver.start_compliance <= 0 else solver.start_compliance * sg(load))
    mask0 = jnp.abs(phi_k) < jnp.arccos(jnp.clip(h_init / sg(outer), -1.0, 1.0))

    def penetration_k(p, h, args):
        ckk_, phi_k_, w_ext_k_, _, outer_, *_, road_ = args
        return outer_ + w_ext_k_ - ckk_ @ p - road_.distance(phi_k_, h)

    def body(state):
        mask, h, _, it, _ = state
        p, h_new = _bordered_solve(mask, h, *fixed)
        delta = penetration_k(p, h_new, fixed)
        new = delta > 0.0
        new = jnp.where(jnp.any(new), new, mask)
        done = jnp.all(new == mask) & (jnp.abs(h_new - h) < 1e-12 + 1e-9 * jnp.abs(h))
        return new, h_new, p, it + 1, done

    def cond(state):
        return (~state[4]) & (state[3] < solver.max_iter)

    p0 = jnp.zeros(K)
    mask, h_conv, p_conv, iters, done = jax.lax.while_loop(
        cond, body, (mask0, h_init, p0, jnp.asarray(0), jnp.asarray(False))
    )

    # --- differentiable solve at the frozen active set ----------------------------
    if solver.differentiable:
        p_k, H = _bordered_solve(mask, sg(h_conv), ckk, phi_k, w_ext_k, k, outer, load, R, dphi, road)
    else:  # the last iteration's solve (ContactSolver.differentiable)
        p_k, H = p_conv, h_conv
    window_ok = ~(mask[0] | mask[-1])
    if solver.strict_window:  # a patch clipped by the window is no answer: NaN downstream (ContactSolver)
        p_k, H = jnp.where(window_ok, p_k, jnp.nan), jnp.where(window_ok, H, jnp.nan)
    pressure = jnp.zeros(M).at[first : first + K].set(p_k)
    q_spec = jnp.fft.rfft(-pressure) + q_ext
    W, V = harmonic_response(G, q_spec, s_ext)
    w = jnp.fft.irfft(W, M)
    v = jnp.fft.irfft(V, M)
    s_full = road.distance(phi, H)
    reach = jnp.isfinite(s_full)
    penetration = jnp.where(reach, outer + w - jnp.where(reach, s_full, 0.0), -jnp.inf)
    fx = -R * dphi * jnp.sum(pressure * jnp.sin(phi))
    fz = R * dphi * jnp.sum(pressure * jnp.cos(phi))
    return RollingSolution(
        phi=phi, omega=omega, load=load, pressure=pressure, penetration=penetration, w=w, v=v,
        w_spectrum=W, v_spectrum=V, axle_height=H, outer_radius=outer, fx=fx, fz=fz,
        iterations=iters, converged=done, window_ok=window_ok,
    )


def as_traced(tree):
    """Python floats in a PyTree (parameters, operating point, models) -> float64 arrays.

    ``eqx.filter_jit`` treats Python floats as static (a recompile per value);
    passing arrays keeps one compilation per model structure. The arrays are
    NumPy's (0-d ``float64``): traced all the same, and no eager JAX op.
    """
    return jax.tree.map(
        lambda x: np.asarray(x, dtype=np.float64) if isinstance(x, (int, float)) and not isinstance(x, bool) else x,
        tree,
    )


#: Friction coefficient of the brush tread (docs/physics.md §6 tread_shear).
FRICTION = 1.0


class BrushShearLoad(eqx.Module):
    """Brush tread shear in the patch (docs/physics.md §6 ``tread_shear``) as a load hook
    ``(solution, ring, geometry) -> (q_w, q_v)`` grid loads [N/m].

    The tip sticks at the leading edge φ_L (the penetration's interpolated zero crossing) and then moves with
    the road; base position ``x_b(φ) = (R+τ+w) sin φ + v cos φ``; shear
    ``Δx = x_b(φ) − x_b(φ_L) − R_e(φ − φ_L)``; ``q_x = −k_x Δx`` while ``|q_x| < μ p``, sliding at μp
    (with memory, below); loads ``q_w += q_x sin φ``, ``q_v += q_x cos φ``. Free rolling fixes R_e: the tip forces
    drive no torque (:func:`free_rolling_radius`). ``k_x`` [N/m²].

    ``lever`` (static, default off): the tread element stays normal to the belt, so its tip
    sits at ``(R + w) sin φ + v cos φ + τ sin(φ − ψ)`` (τ = R_out − R, ψ = (w′ − v)/R the belt slope,
    docs/physics.md §5; to first order in ψ, ``x_b − τψ cos φ``); the tip's shear force then also acts
    on the belt through the lever τ, a moment ``m = −τ q_x cos(φ − ψ)`` per unit length whose virtual
    work ``∫ m δψ R dφ`` gives the loads ``q_w += −m′/R``, ``q_v += −m/R`` (docs/physics.md §6
    ``tread_shear``, the lever).

    Drive and brake (docs/physics.md §13): ``r_road`` [m], the road length per radian of wheel rotation
    (V/Ω), given instead of the free-rolling one; or ``slip`` κ, with ``r_road = r_free/(1 + κ)`` and r_free
    the free-rolling radius of the same tips (κ > 0 driving). Both None (the default): free rolling.

    ``memory`` (static, default on: the physical brush, docs/physics.md §6 ``tread_shear``, Pacejka §3.2): a tip
    that slid keeps the deflection it slid with and sticks again from there when μp rises above its force
    (:func:`brush_tip_forces`); off: the memoryless ``clip(−k_x Δx, ±μp)``, which equals it wherever μp does not
    rise behind a sliding tip (a one-humped pressure) and differs behind a dip of a two-humped one.
    """

    k_x: float
    mu: float = FRICTION
    lever: bool = eqx.field(static=True, default=False)
    r_road: object = None
    slip: object = None
    memory: bool = eqx.field(static=True, default=True)

    def tips(self, sol, ring, geometry) -> "BrushTips":
        """The tip forces q_x [N/m] on the grid and the radii of the brush at a radial contact solution.

        Free rolling (``r_road`` and ``slip`` None): the road moves R_e = r_free per radian, the root of the
        clipped tips' torque (:func:`free_rolling_radius`). Driven or braked (docs/physics.md §13): the road
        moves ``r_road`` per radian when given, else ``r_free/(1 + slip)`` (slip ratio κ = r_free/r_road − 1,
        SAE: κ > 0 driving); the tips stick at the leading edge and slide at μp as before.
        """
        phi = sol.phi
        p = sol.pressure
        inside = jax.lax.stop_gradient(p > 0)
        x_b = (geometry.outer_radius + sol.w) * jnp.sin(phi) + sol.v * jnp.cos(phi)
        tau = psi = None
        if self.lever:  # the element normal to the belt, exactly: its tip at (R + w) sin φ + v cos φ + τ sin(φ − ψ)
            tau = geometry.outer_radius - geometry.radius
            psi = belt_slope_grid(sol, geometry)
            x_b = (geometry.radius + sol.w) * jnp.sin(phi) + sol.v * jnp.cos(phi) + tau * jnp.sin(phi - psi)
        # leading edge φ_L: the zero crossing of the penetration δ between the last point before the patch and the
        # first in it, linearly interpolated (docs/physics.md §6 tread_shear); the first grid point instead moves
        # the sticking point by up to one grid step, a shear offset (x_b′ − R_e)Δφ that does not converge with M
        first = jnp.argmax(inside)
        d0, d1 = sol.penetration[first - 1], sol.penetration[first]
        reach = jnp.isfinite(d0)  # (the road out of reach before the patch: the edge at `first`)
        d0 = jnp.where(reach, d0, 0.0)  # finite in both branches: no NaN in the derivative
        t = jnp.where(reach & (d1 > d0), jnp.clip(-d0 / jnp.where(d1 > d0, d1 - d0, 1.0), 0.0, 1.0), 1.0)
        s = phi - (phi[first - 1] + t * (phi[first] - phi[first - 1]))
        D = x_b - (x_b[first - 1] + t * (x_b[first] - x_b[first - 1]))
        lim = self.mu * p
        r_free = free_rolling_radius(D, s, jnp.cos(phi), self.k_x, lim, inside, memory=self.memory)
        if self.r_road is not None:
            r_road = self.r_road
        elif self.slip is not None:
            r_road = r_free / (1.0 + self.slip)
        else:
            r_road = r_free
        q_x = brush_tip_forces(D, s, self.k_x, lim, inside, r_road, memory=self.memory)
        return BrushTips(q_x=q_x, r_free=r_free, r_road=r_road, tau=tau, psi=psi)

    def loads(self, tips: "BrushTips", sol, geometry):
        """``(q_w, q_v)`` [N/m] of the tip forces on the belt (with the lever's moment when ``lever``)."""
        phi = sol.phi
        q_x = tips.q_x
        q_w, q_v = q_x * jnp.sin(phi), q_x * jnp.cos(phi)
        if self.lever:
            m = -tips.tau * q_x * jnp.cos(phi - tips.psi)  # q_x ∂x_tip/∂ψ
            dphi = phi[1] - phi[0]
            dm = (jnp.roll(m, -1) - jnp.roll(m, 1)) / (2.0 * dphi)  # m is continuous: |q_x| ≤ μp → 0 at the edges
            q_w = q_w - dm / geometry.radius
            q_v = q_v - m / geometry.radius
        return q_w, q_v

    def __call__(self, sol, ring, geometry):
        return self.loads(self.tips(sol, ring, geometry), sol, geometry)


class BrushTips(eqx.Module):
    """The brush's tips at a radial contact solution (:meth:`BrushShearLoad.tips`).

    - ``q_x``: tip force on the tyre per unit centreline length, along x̂ (rearward +) [N/m], ``(M,)``.
    - ``r_free``: free-rolling road length per radian [m] (the clipped tips drive no torque).
    - ``r_road``: the road length per radian used [m] (= ``r_free`` in free rolling).
    - ``tau``, ``psi``: the lever τ [m] and the belt slope ψ [rad] (None without the lever).
    """

    q_x: jax.Array
    r_free: jax.Array
    r_road: jax.Array
    tau: object = None
    psi: object = None

    def fx(self, sol, geometry):
        """Fx = −R Σ q_x Δφ [N]: the tips' net force on the tyre along the direction of travel (driving +,
        docs/physics.md §13)."""
        dphi = sol.phi[1] - sol.phi[0]
        return -geometry.radius * dphi * jnp.sum(self.q_x)


def brush_tip_forces(D, s, k_x, lim, inside, r, *, memory: bool = True):
    """Tip forces q_x [N/m] of the brush on the grid (docs/physics.md §6 tread_shear), the road advancing ``r`` per
    radian; ``D`` the tips' displacement from the leading edge's, ``s = φ − φ_L``, ``lim`` = μp ≥ 0.

    The sticking force is ``q_s = −k_x (D − r s)``. ``memory`` (Pacejka, *Tire and Vehicle Dynamics*, §3.2, the
    brush model): walking from the leading edge to the trailing one, a tip's force changes as the sticking force
    does, ``q_j = clip(q_{j−1} + q_s,j − q_s,j−1, ±lim_j)`` (q = 0 before the patch): it sticks while
    |q| < μp, slides at μp, and a tip that slid sticks again from the force it has when μp rises: a
    ``jax.lax.scan`` along the grid (differentiable; a parallel prefix of the same maps compiles ~10× slower inside
    :func:`free_rolling_radius`'s bisection and runs slower on a CPU).
    Without ``memory``: ``clip(q_s, ±lim)`` inside the patch (equal to the above while μp never rises behind a
    sliding tip). Outside the patch 0.
    """
    q_s = jnp.where(inside, -k_x * (D - r * s), 0.0)
    if not memory:
        return jnp.where(inside, jnp.clip(q_s, -lim, lim), 0.0)

    def step(carry, x):
        q, before = carry  # the previous tip's force and sticking force (0, 0 outside the patch)
        stick, limit, here = x
        q = jnp.where(here, jnp.clip(q + stick - before, -limit, limit), 0.0)
        return (q, stick), q

    zero = jnp.zeros((), q_s.dtype)
    return jax.lax.scan(step, (zero, zero), (q_s, jnp.broadcast_to(lim, q_s.shape), inside))[1]


#: At most this many safeguarded Newton steps for the memory brush's free-rolling root, started at the clipped
#: brush's root (the same root on a one-humped pressure: one step; two to four where tips stick again).
MEMORY_NEWTON_STEPS = 24


def free_rolling_radius(D, s, c, k_x, lim, inside, steps: int = 60, *, memory: bool = False):
    """R_e of free rolling: the tip forces ``q_x`` inside the patch drive no torque, ``Σ q_x c = 0`` (docs/physics.md
    §6 tread_shear; ``c = cos φ``, the arm of a tangential tip force). ``memory`` False (this function's
    default): the clipped ``q_x = clip(−k_x (D − R_e s), ±lim)``; True: the brush with memory
    (:func:`brush_tip_forces`; each q_x is still non-decreasing in R_e, so is T).

    The torque is piecewise linear and non-decreasing in R_e (s > 0 in the patch): bisection on a bracket around
    the unclipped closed-form root (on the clipped torque; with ``memory`` then :data:`MEMORY_NEWTON_STEPS`
    bracketed Newton steps at most on the memory brush's torque from there), then one Newton step at that root
    with the derivatives flowing, so that ∂R_e/∂θ is the implicit function's ``−(∂T/∂θ)/(∂T/∂R_e)`` (the search
    itself is not differentiated).
    Without clipping the root is ``Σ D c / Σ s c`` (the bracket's centre); with the tips sliding near the exit
    (|q_x| at μp) it differs from that formula, which would leave the real tip forces a net torque.
    """
    def torque(r, memory=memory):
        return jnp.sum(brush_tip_forces(D, s, k_x, lim, inside, r, memory=memory) * c)

    sg = jax.lax.stop_gradient
    num = jnp.sum(jnp.where(inside, D * c, 0.0))
    den = jnp.sum(jnp.where(inside, s * c, 0.0))
    r_ls = sg(num / jnp.where(den == 0, 1.0, den))
    span = 0.5 * jnp.abs(r_ls) + 1e-3

    def bisect(_, ab):
        a, b = ab
        m = 0.5 * (a + b)
        above = torque(m, False) > 0.0  # the root lies below m
        return jnp.where(above, a, m), jnp.where(above, m, b)

    lo, hi = jax.lax.fori_loop(0, steps, bisect, (r_ls - span, r_ls + span))
    r_clip = sg(0.5 * (lo + hi))
    if memory:
        # the memory torque from the clipped one's root (the same root wherever μp never rises behind a sliding
        # tip): Newton on the piecewise-linear T, kept inside the bracket it narrows, bisecting where a step
        # would leave it — a few sequential scans instead of `steps`
        Ds, ss, cs, ks, ls = (sg(x) for x in (D, s, c, k_x, lim))  # the root's value only (its derivative: below)

        def t_fixed(r):
            return jnp.sum(brush_tip_forces(Ds, ss, ks, ls, inside, r, memory=True) * cs)

        def newton(state):
            i, r, a, b, _ = state
            t, dt = jax.jvp(t_fixed, (r,), (jnp.ones_like(r),))
            a, b = jnp.where(t <= 0.0, r, a), jnp.where(t >= 0.0, r, b)
            nr = r - t / jnp.where(dt > 0, dt, 1.0)
            ok = (dt > 0) & (nr >= a) & (nr <= b)  # (at the root nr = r = a or b in floating point)
            nr = jnp.where(t == 0.0, r, jnp.where(ok, nr, 0.5 * (a + b)))
            return i + 1, nr, a, b, (t == 0.0) | (jnp.abs(nr - r) <= 1e-15 * jnp.abs(r))

        start = (0, r_clip, r_ls - span, r_ls + span, False)
        r_clip = jax.lax.while_loop(lambda st: (st[0] < MEMORY_NEWTON_STEPS) & ~st[4], newton, start)[1]
    # k_x = 0 (the effect's null): T ≡ 0; R_e is then the limit k_x → 0⁺, where no tip slides: the closed form
    # (what the linearised screen's derivative ∂q_x/∂k_x = −(D − R_e s) needs)
    r0 = jnp.where(sg(k_x) > 0, r_clip, r_ls)
    if memory:  # the torque's slope in R_e: each sticking tip's k_x (s − s at its last slide), by forward mode
        t0, slope = jax.jvp(torque, (r0,), (jnp.ones_like(r0),))
    else:
        q = -k_x * (D - r0 * s)
        free = inside & (jnp.abs(q) < lim)  # tips sticking at r0: the torque's slope in R_e
        slope = jnp.sum(jnp.where(free, k_x * s * c, 0.0))
        t0 = torque(r0)
    step = t0 / jnp.where(slope > 0, slope, 1.0)
    return r0 - jnp.where(slope > 0, step - sg(step), 0.0)  # value r0; derivative −T_θ/T_r


def belt_slope_grid(sol, geometry):
    """Belt slope ψ = (w′ − v)/R [rad] on the grid of a contact solution (docs/physics.md §5; w′ spectral)."""
    M = sol.w.shape[-1]
    k = jnp.arange(sol.w_spectrum.shape[-1], dtype=jnp.float64)
    dw = jnp.fft.irfft(1j * k * sol.w_spectrum, M)
    return (dw - sol.v) / geometry.radius


@functools.partial(jit, static_argnums=1, quick=True)
def _solve_rolling_compiled(arrays, static):
    ring, geometry, operating, model, solver, extra_load = eqx.combine(arrays, static)
    return solve_rolling(ring, geometry, operating, model=model, solver=solver, extra_load=extra_load)


def solve_rolling_jit(ring, geometry, operating, *, model=RingModel(), solver=ContactSolver(), extra_load=None):
    """:func:`solve_rolling` compiled once per model/solver structure (floats passed as arrays).

    Compiled with :data:`ringfit._cache.QUICK_COMPILE`: a cold process (a diagnosis's static patches,
    ``ringfit roll``, ``ringfit campbell``) compiles it in about half the time, and a solve runs as fast
    (1.8 ms either way on the example tyre).
    """
    ring, geometry, operating, model = as_traced((ring, geometry, operating, model))
    arrays, static = eqx.partition((ring, geometry, operating, model, solver, extra_load), eqx.is_array)
    return _solve_rolling_compiled(arrays, static)


@eqx.filter_jit
def patch_edges(solution: RollingSolution):
    """Leading and trailing contact-patch edges [rad], linearly interpolated zero crossings of δ.

    **Returns:** ``(phi_leading, phi_trailing)`` (φ < 0 leading, φ > 0 trailing, docs/physics.md §0).
    """
    phi, delta = solution.phi, solution.penetration
    active = solution.pressure > 0.0
    M = phi.shape[0]
    i0 = jnp.argmax(active)  # first active point
    i1 = M - 1 - jnp.argmax(active[::-1])  # last active point

    def cross(a, b):
        da, db = delta[a], delta[b]
        return phi[a] + (phi[b] - phi[a]) * (0.0 - da) / (db - da)

    return cross(i0 - 1, i0), cross(i1, i1 + 1)


@eqx.filter_jit
def contact_length(solution: RollingSolution):
    """Patch length along the outer radius ``(R+τ)(φ_trailing − φ_leading)`` [m]."""
    lead, trail = patch_edges(solution)
    return solution.outer_radius * (trail - lead)


__all__ = [
    "BrushShearLoad", "BrushTips", "FRICTION", "brush_tip_forces", "free_rolling_radius",
    "ContactSolver", "RollingSolution", "tread_pressure", "circulant_block", "solve_rolling",
    "solve_rolling_jit", "as_traced", "patch_edges", "contact_length",
]
