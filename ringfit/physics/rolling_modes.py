"""Modes of the rolling, loaded ring in the space-fixed frame, and what each observer sees (docs/physics.md §3.7).

In the space-fixed frame the patch stands still, so the rolling ring on its tread springs is a linear,
time-invariant gyroscopic system. Hill's method over harmonics k = −K…K (the patch couples k with j through the
Fourier coefficient ĉ_{k−j} of its stiffness) gives the quadratic eigenproblem ``(λ² M + λ G + K + K_c) c = 0``,
whose steady part is §4.2's operator (:func:`ringfit.physics.rolling.ring_operator`), solved as one Hermitian
``eigh`` so that every frequency is differentiable in the ring, the load and the speed. Damping is a first-order
perturbation; a co-rotating sensor sees each mode as lines at ``ω + kΩ`` weighted by |W_k|², |V_k|²
(:func:`sensor_lines`); each mode carries its travel (backward/forward) and contact symmetry labels. The
derivation, the limits the tests pin (eq. 25/26 at k_c = 0) and which branches survive under contact:
docs/physics.md §3.7.

Shapes: K harmonics (static), H = 2K + 1 harmonics k = −K…K, ``dof`` = H (inextensible, the default) or 2H
(``extensible=True``); every mode array has a leading mode axis of length ``dof``; :func:`campbell_modes` adds a
leading speed axis.

Example (Table 9's tyre at its rated 4 kN, rolling at 40 km/h on a flat road)::

    from ringfit import data
    from ringfit.io.tyre import read_tyre
    from ringfit.physics.operating import OperatingPoint
    from ringfit.physics.rolling_modes import loaded_rolling_modes

    tyre = read_tyre(data.path("table9.tyre.toml"))
    point = OperatingPoint.from_speed(40.0, 4000.0, float(tyre.geometry.outer_radius))
    modes, steady = loaded_rolling_modes(tyre.ring, tyre.geometry, point)
    print(modes.freq_hz[:8], modes.order[:8], modes.travel[:8])
"""

from __future__ import annotations

from typing import Literal, get_args

import equinox as eqx
import jax
import jax.numpy as jnp

from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, as_traced, patch_edges, solve_rolling
from ringfit.physics.operating import KMH, AbstractRoad, FlatRoad, OperatingPoint, rolling_radius
from ringfit.physics.rolling import NoDamping, RingModel, elastic_stiffness, harmonic_basis, ring_operator

#: Harmonics |k| ≤ K of the Hill basis. K = 32 keeps every mode of dominant order n ≤ 15
#: within 1e-4 of K = 200 (Table 9 tyre, 4 kN, 0–80 km/h; tests/test_rolling_modes.py).
DEFAULT_HARMONICS = 32
#: What :func:`sensor_lines` weights a mode's lines by: ``"displacement"`` or ``"acceleration"`` (an accelerometer's).
SensorQuantity = Literal["displacement", "acceleration"]
#: The unit of :func:`campbell_modes`'s speeds: ``"kmh"`` (road speed V [km/h]) or ``"rad/s"`` (wheel speed Ω).
SpeedUnit = Literal["kmh", "rad/s"]

TWO_PI = 2.0 * jnp.pi
_J = jnp.array([[0.0, -1.0], [1.0, 0.0]], dtype=jnp.complex128)


class ContactArc(eqx.Module):
    """The linearised contact: tread springs on the arc ``leading ≤ α ≤ trailing`` (docs/physics.md §3.7, §4.3).

    **Fields** (scalars, may be traced):

    - ``leading``, ``trailing``: patch edges [rad] (leading < 0 < trailing, §0).
    - ``k_radial``: radial stiffness k_c on the arc [N/m²] (the tread spring k_trd).
    - ``k_tangential``: tangential (tread-shear) stiffness k_ct on the arc [N/m²]; 0 in the baseline.

    ``ContactArc(0, 0, 0)`` (:meth:`none`) is the free ring.
    """

    leading: jax.Array
    trailing: jax.Array
    k_radial: jax.Array
    k_tangential: jax.Array = 0.0

    @classmethod
    def symmetric(cls, half_angle, k_radial, k_tangential=0.0) -> "ContactArc":
        """Arc ``|α| ≤ a`` (the standing loaded tyre of docs/physics.md §6 ``ground_contact``)."""
        a = jnp.asarray(half_angle, dtype=jnp.float64)
        return cls(-a, a, jnp.asarray(k_radial, dtype=jnp.float64), jnp.asarray(k_tangential, dtype=jnp.float64))

    @classmethod
    def none(cls) -> "ContactArc":
        """No contact (a free, spinning ring)."""
        z = jnp.zeros((), dtype=jnp.float64)
        return cls(z, z, z, z)

    def fourier(self, m):
        """Fourier coefficients ``ĉ_m = (1/2π)∫ k(α) e^{−imα} dα`` of the radial and tangential stiffness.

        **Arguments:** ``m`` — harmonic numbers (float array).

        **Returns:** ``(radial, tangential)`` [N/m²], complex, shape of ``m``.
        """
        m = jnp.asarray(m, dtype=jnp.float64)
        width = self.trailing - self.leading
        centre = 0.5 * (self.trailing + self.leading)
        # ∫ over the arc of e^{−imα} = width · sinc(m·width/2π) · e^{−im·centre}
        shape = width * jnp.sinc(m * width / TWO_PI) * jnp.exp(-1j * m * centre) / TWO_PI
        return self.k_radial * shape, self.k_tangential * shape


def contact_arc(
    ring: RingParams,
    geometry: TyreGeometry,
    operating: OperatingPoint,
    *,
    model: RingModel = RingModel(),
    solver: ContactSolver = ContactSolver(),
    k_tangential=0.0,
) -> tuple[ContactArc, jax.Array]:
    """The contact arc of the steady rolling solution (docs/physics.md §3.7, §4.3–4.4).

    Solves the steady rolling state (:func:`ringfit.physics.contact.solve_rolling`)
    and takes the patch edges (:func:`ringfit.physics.contact.patch_edges`,
    interpolated zero crossings of the penetration, so the arc is a smooth
    function of the parameters, the load and the speed) with k_c = ``ring.k_tread``.

    **Returns:** ``(arc, solution)`` — :class:`ContactArc` and the
    :class:`~ringfit.physics.contact.RollingSolution` (check ``solution.ok``).
    """
    sol = solve_rolling(ring, geometry, operating, model=model, solver=solver)
    lead, trail = patch_edges(sol)
    return ContactArc(lead, trail, ring.k_tread, jnp.asarray(k_tangential, dtype=jnp.float64)), sol


class RollingModes(eqx.Module):
    """Modes of the rolling, loaded ring in the fixed frame (docs/physics.md §3.7).

    **Fields** (N = dof modes, ascending in frequency; H = 2K + 1 harmonics):

    - ``omega``: wheel speed Ω [rad/s] (scalar).
    - ``k``: harmonic numbers −K…K, float, ``(H,)``.
    - ``angular_frequency``: fixed-frame ω [rad/s], ``(N,)`` (> 0).
    - ``radial``, ``tangential``: harmonic content W_k, V_k, complex ``(N, H)``,
      normalised ``Σ|W_k|² + |V_k|² = 1``, the largest W_k (else V_k) real positive.
    - ``damping_ratio``: ζ = σ/ω from the hysteretic loss (first order, not differentiated), ``(N,)``.
    - ``order``: dominant order n = |k| of ``|W_k|² + |V_k|² + |W_−k|² + |V_−k|²``, int ``(N,)``.
    - ``travel``: signed travelling ratio of the dominant order, ``(N,)``:
      ``+r`` when its backward part is r ≥ 1 times its forward part (amplitudes),
      ``−r`` when forward; ±1 is a standing wave.
    - ``symmetry``: share of the radial content even about α = 0, ``(N,)`` in [0, 1]
      (NaN without radial content, e.g. the n = 0 mode of the inextensible ring).
    """

    omega: jax.Array
    k: jax.Array
    angular_frequency: jax.Array
    radial: jax.Array
    tangential: jax.Array
    damping_ratio: jax.Array
    order: jax.Array
    travel: jax.Array
    symmetry: jax.Array
    #: with a wheel (:mod:`ringfit.physics.wheel`): the body's amplitudes ``(N, 3)`` — p₊, p₋ (rim
    #: translation in harmonics +1, −1) and Rβ (rim rotation) — on the ring's scale; else ``None``
    body: jax.Array | None = None

    @property
    def freq_hz(self):
        """Fixed-frame frequencies f = ω/2π [Hz], ``(..., N)``."""
        return self.angular_frequency / TWO_PI


def gyroscopic_matrices(
    ring: RingParams,
    geometry: TyreGeometry,
    omega,
    arc: ContactArc,
    *,
    harmonics: int = DEFAULT_HARMONICS,
    extensible: bool = False,
):
    """Matrices of ``(λ² M + λ G + K) c = 0`` in the Hill basis (docs/physics.md §3.7).

    **Arguments:**

    - ``ring``, ``geometry``: the ring (``ring.chi``, and ``ring.ea`` if extensible).
    - ``omega``: Ω [rad/s].
    - ``arc``: the contact (:class:`ContactArc`; :meth:`ContactArc.none` for a free ring).
    - ``harmonics``: K (static); ``extensible``: basis form (static).

    **Returns:** ``(M, G, K, E, k_of_dof)`` — complex ``(dof, dof)`` matrices
    [kg/m, kg/(m s), N/m²]: mass (Hermitian), gyroscopic (skew-Hermitian),
    stiffness including the contact (Hermitian), the elastic stiffness the
    hysteretic loss acts on (block diagonal, Hermitian), and the harmonic
    number of each degree of freedom ``(dof,)``. Per unit length of ring.
    """
    k = jnp.arange(-harmonics, harmonics + 1, dtype=jnp.float64)
    omega = jnp.asarray(omega, dtype=jnp.float64)
    b = harmonic_basis(k, extensible)  # (H, 2, d)
    bh = jnp.conj(jnp.swapaxes(b, -1, -2))  # (H, d, 2)
    rho_a = ring.rho_a
    eye = jnp.eye(2, dtype=jnp.complex128)
    undamped = RingModel(extensible=extensible, damping=NoDamping())
    D = ring_operator(ring, geometry, k, omega, undamped)  # (H, 2, 2) = P_k(ikΩ)
    gyro = 2.0 * rho_a * omega * (1j * k[:, None, None] * eye + _J)
    el = elastic_stiffness(ring, geometry, k)

    def project(A):  # (H, 2, 2) -> (H, d, d)
        return bh @ A @ b

    def block_diag(blocks):  # (H, d, d) -> (H d, H d)
        H, d = blocks.shape[0], blocks.shape[1]
        out = jnp.zeros((H, d, H, d), dtype=jnp.complex128)
        idx = jnp.arange(H)
        out = out.at[idx, :, idx, :].set(blocks)
        return out.reshape(H * d, H * d)

    M = block_diag(project(jnp.broadcast_to(rho_a * eye, (k.size, 2, 2))))
    G = block_diag(project(gyro))
    Kd = block_diag(project(D))
    E = block_diag(project(el))
    # contact: row k, column j gets b_kᴴ diag(ĉ_{k−j}, ĉt_{k−j}) b_j
    cr, ct = arc.fourier(k[:, None] - k[None, :])  # (H, H)
    Kc = (
        cr[:, None, :, None] * (bh[:, :, 0][:, :, None, None] * b[None, None, :, 0, :])
        + ct[:, None, :, None] * (bh[:, :, 1][:, :, None, None] * b[None, None, :, 1, :])
    )  # (H, d, H, d)
    d = b.shape[-1]
    Kc = Kc.reshape(k.size * d, k.size * d)
    k_of_dof = jnp.repeat(k, d)
    return M, G, Kd + Kc, E, k_of_dof


def _hermitian(A):
    return 0.5 * (A + jnp.conj(A.T))


def rolling_modes(
    ring: RingParams,
    geometry: TyreGeometry,
    omega,
    arc: ContactArc,
    *,
    harmonics: int = DEFAULT_HARMONICS,
    extensible: bool = False,
    wheel=None,
) -> RollingModes:
    """Fixed-frame modes of the ring rotating at Ω with the contact ``arc`` (docs/physics.md §3.7).

    **Arguments:** as :func:`gyroscopic_matrices`; ``wheel``: ``None`` (rim fixed) or a
    :class:`ringfit.physics.wheel.Wheel` — the rim as a rigid body on its suspension, three
    extra degrees of freedom coupled to the ring's k = ±1 and 0 harmonics
    (:func:`ringfit.physics.wheel.border_hill`, docs/physics.md §6 ``wheel_suspension``).

    **Returns:** :class:`RollingModes` (dof modes, ascending; dof + 3 with a wheel, whose
    ``body`` holds the body's amplitudes). Pure JAX:
    jit-, vmap- and grad-compatible. Valid below the critical speed (the
    stiffness must stay positive definite; beyond it the frequencies are NaN).
    """
    M, G, K, E, kd = gyroscopic_matrices(ring, geometry, omega, arc, harmonics=harmonics, extensible=extensible)
    C = None
    if wheel is not None:
        from ringfit.physics.wheel import border_hill

        M, G, K, E, C, kd = border_hill(M, G, K, E, kd, ring, geometry, wheel, harmonics, extensible)
    omega = jnp.asarray(omega, dtype=jnp.float64)
    n = M.shape[0]
    Gt = _hermitian(-1j * G)
    # M is diagonal in both bases: scale by M^{-1/2}, factor K̂ = L Lᴴ, and the Hermitian matrix
    # [[0, Lᴴ], [L, −Ĝ]] has the eigenvalues ω of (ω² I + ω Ĝ − K̂) x = 0 (x = z₂/ω, c = M^{-1/2} x)
    scale = 1.0 / jnp.sqrt(jnp.real(jnp.diagonal(M)))
    outer = scale[:, None] * scale[None, :]
    L = jnp.linalg.cholesky(_hermitian(K) * outer)
    zero = jnp.zeros_like(L)
    Hm = jnp.block([[zero, jnp.conj(L.T)], [L, -Gt * outer]])
    w, Z = jnp.linalg.eigh(_hermitian(Hm))
    w, Z = w[n:], Z[:, n:]  # ω > 0 half: one mode per degree of freedom
    q = (scale[:, None] * Z[n:] / w[None, :]).T  # (N, dof)

    k = jnp.arange(-harmonics, harmonics + 1, dtype=jnp.float64)
    H = k.size
    d = 2 if extensible else 1
    ring_dof = H * d
    b = harmonic_basis(k, extensible)  # (H, 2, d)
    wv = jnp.einsum("hcd,mhd->mhc", b, q[:, :ring_dof].reshape(-1, H, d))  # (N, H, 2)
    # damping (first order): σ = cᴴ E_s c / cᴴ(2ωM + G̃)c with the material frequency's sign per harmonic
    sgn = jnp.sign(w[:, None] + kd[None, :] * omega)  # (N, dof)
    eta = 2.0 * ring.damping_ratio
    qE = jnp.einsum("md,de,me->m", jnp.conj(q) * sgn, E, q).real
    qM = jnp.einsum("md,de,me->m", jnp.conj(q), M, q).real
    qG = jnp.einsum("md,de,me->m", jnp.conj(q), Gt, q).real
    qD = 2.0 * w * qM + qG
    zeta = eta * qE / (qD * w)
    if C is not None:  # viscous dampers of the wheel's support: σ = ω cᴴCc / cᴴ(2ωM + G̃)c
        zeta = zeta + jnp.einsum("md,de,me->m", jnp.conj(q), C, q).real / qD
    zeta = jax.lax.stop_gradient(zeta)

    wv = jax.lax.stop_gradient(wv)
    norm = jnp.sqrt(jnp.sum(jnp.abs(wv) ** 2, axis=(-2, -1)))
    wv = wv / norm[:, None, None]
    has_w = jnp.sum(jnp.abs(wv[..., 0]) ** 2, axis=-1) > 1e-20
    src = jnp.where(has_w[:, None], wv[..., 0], wv[..., 1])
    ref = jnp.take_along_axis(src, jnp.argmax(jnp.abs(src), axis=-1)[:, None], axis=1)[:, 0]
    wv = wv * (jnp.conj(ref) / jnp.abs(ref))[:, None, None]
    W, V = wv[..., 0], wv[..., 1]
    labels = mode_labels(W, V, k, jax.lax.stop_gradient(w), omega)
    body = None
    if wheel is not None:  # body amplitudes (p₊, p₋, Rβ) on the ring's normalisation and phase
        body = jax.lax.stop_gradient(q[:, ring_dof:]) / norm[:, None] * (jnp.conj(ref) / jnp.abs(ref))[:, None]
    return RollingModes(omega=omega, k=k, angular_frequency=w, radial=W, tangential=V, damping_ratio=zeta,
                        body=body, **labels)


_rolling_modes_compiled = eqx.filter_jit(rolling_modes)


def rolling_modes_jit(ring, geometry, omega, arc: ContactArc, **settings) -> RollingModes:
    """:func:`rolling_modes` compiled once per settings (floats passed as arrays)."""
    ring, geometry, arc = as_traced((ring, geometry, arc))
    return _rolling_modes_compiled(ring, geometry, jnp.asarray(omega, dtype=jnp.float64), arc, **settings)


def mode_labels(W, V, k, angular_frequency, omega):
    """Dominant order, travelling ratio and contact symmetry of modes from their harmonic content (docs/physics.md §3.7).

    **Arguments:** ``W``, ``V`` — radial and tangential content per harmonic,
    complex ``(..., N, H)`` (displacements, or accelerations: see
    :func:`material_acceleration`); ``k`` — harmonics −K…K ``(H,)``;
    ``angular_frequency`` — fixed-frame ω ``(..., N)`` [rad/s]; ``omega`` — Ω [rad/s].

    **Returns:** dict ``order`` (int, dominant n = |k| of |W|² + |V|²), ``travel``
    (signed amplitude ratio backward/forward of the dominant order; harmonic
    k is a backward wave when ``k(ω + kΩ) > 0``) and ``symmetry`` (share of
    |W| even about α = 0; NaN without radial content), each ``(..., N)``.
    """
    K = (k.shape[-1] - 1) // 2
    w = angular_frequency
    omega = jnp.asarray(omega)[..., None]
    power = jnp.abs(W) ** 2 + jnp.abs(V) ** 2  # (..., N, H), index K is k = 0
    pos = power[..., K:]  # k = 0..K
    neg = jnp.flip(power[..., : K + 1], axis=-1)  # k = 0..−K
    per_order = pos + neg.at[..., 0].set(0.0)
    order = jnp.argmax(per_order, axis=-1)
    kp = order.astype(jnp.float64)
    amp_p = jnp.sqrt(jnp.take_along_axis(pos, order[..., None], -1)[..., 0])
    amp_n = jnp.sqrt(jnp.take_along_axis(neg, order[..., None], -1)[..., 0])
    back_p = kp * (w + kp * omega) > 0  # is +n a backward-wave harmonic?
    back_n = -kp * (w - kp * omega) > 0
    back = jnp.where(back_p, amp_p, 0.0) + jnp.where(back_n, amp_n, 0.0)
    fwd = jnp.where(back_p, 0.0, amp_p) + jnp.where(back_n, 0.0, amp_n)
    tiny = 1e-300
    travel = jnp.where(back >= fwd, back / jnp.maximum(fwd, tiny), -fwd / jnp.maximum(back, tiny))
    travel = jnp.where(order == 0, 1.0, jnp.clip(travel, -1e12, 1e12))
    Wm = jnp.flip(W, axis=-1)  # W_{−k}
    even = jnp.sum(jnp.abs(W + Wm) ** 2, axis=-1)
    odd = jnp.sum(jnp.abs(W - Wm) ** 2, axis=-1)
    tot = even + odd
    ok = tot > 1e-20 * jnp.max(tot)
    symmetry = jnp.where(ok, even / jnp.where(ok, tot, 1.0), jnp.nan)
    return dict(order=order, travel=travel, symmetry=symmetry)


def material_acceleration(modes: RollingModes):
    """Per-harmonic acceleration a material point feels, ``−(ω + kΩ)² (W_k, V_k)`` (docs/physics.md §3.7).

    The material sees harmonic k of a mode at ``μ = i(ω + kΩ)``; this is the
    content an accelerometer's data carry (a co-rotating sensor, or the
    angle–time field of a cleat test). **Returns:** ``(A_r, A_t)`` complex
    ``(..., N, H)`` [m/s² per unit modal amplitude].
    """
    mu2 = (modes.angular_frequency[..., :, None] + modes.k[..., None, :] * modes.omega[..., None, None]) ** 2
    return -mu2 * modes.radial, -mu2 * modes.tangential


def sensor_lines(modes: RollingModes, quantity: SensorQuantity = "displacement"):
    """Lines of each mode as the co-rotating sensor sees them (docs/physics.md §3.7).

    **Arguments:** ``quantity`` — ``"displacement"`` (weights |W_k|², |V_k|²)
    or ``"acceleration"`` (weights of :func:`material_acceleration`, what an
    accelerometer reads).

    **Returns:** ``(freq_hz, radial_weight, tangential_weight)``, each
    ``(..., N, H)``: the signed line frequency ``(ω + kΩ)/2π`` [Hz] of harmonic
    k (a real sensor reads |·|), and the weights normalised per mode
    (NaN where a mode has no content on that axis).
    """
    f = (modes.angular_frequency[..., :, None] + modes.k[..., None, :] * modes.omega[..., None, None]) / TWO_PI
    if quantity == "displacement":
        W, V = modes.radial, modes.tangential
    elif quantity == "acceleration":
        W, V = material_acceleration(modes)
    else:
        raise ValueError(f"quantity={quantity!r}; expected {' or '.join(map(repr, get_args(SensorQuantity)))}")
    pr = jnp.abs(W) ** 2
    pt = jnp.abs(V) ** 2
    return f, pr / jnp.sum(pr, -1, keepdims=True), pt / jnp.sum(pt, -1, keepdims=True)


def observed_frequencies(modes: RollingModes, mode_index, k, fixed_frame):
    """Frequencies [Hz] of chosen (mode, line) pairs as their observer sees them (docs/physics.md §3.7).

    **Arguments:** ``modes`` — :class:`RollingModes` (one speed); ``mode_index`` — int
    array of modes; ``k`` — harmonic of the sensor line (ignored in the fixed frame);
    ``fixed_frame`` — bool array, broadcast together.

    **Returns:** ``ω_j/2π`` (fixed) or ``|ω_j + kΩ|/2π`` (co-rotating sensor). Pure JAX,
    differentiable: a diagnosis can keep an assignment made by
    :func:`ringfit.gap.campbell.match_tables` and refit parameters through it.
    """
    w = modes.angular_frequency[jnp.asarray(mode_index)]
    line = jnp.abs(w + jnp.asarray(k, dtype=jnp.float64) * modes.omega)
    return jnp.where(jnp.asarray(fixed_frame), w, line) / TWO_PI


def loaded_rolling_modes(
    ring: RingParams,
    geometry: TyreGeometry,
    operating: OperatingPoint,
    *,
    harmonics: int = DEFAULT_HARMONICS,
    extensible: bool = False,
    model: RingModel = RingModel(),
    solver: ContactSolver = ContactSolver(),
    k_tangential=0.0,
    wheel=None,
):
    """Modes of the tyre rolling at ``operating`` (Ω, Fz, road) (docs/physics.md §3.7).

    The contact arc comes from the steady rolling solution at the same point
    (:func:`contact_arc`); ``wheel`` as :func:`rolling_modes`. **Returns:** ``(modes, solution)``.
    """
    arc, sol = contact_arc(ring, geometry, operating, model=model, solver=solver, k_tangential=k_tangential)
    modes = rolling_modes(ring, geometry, operating.omega, arc, harmonics=harmonics, extensible=extensible,
                          wheel=wheel)
    return modes, sol


class CampbellModes(eqx.Module):
    """Modes at a series of speeds (one jit, vmapped): ``modes`` has a leading speed axis (docs/physics.md §3.7).

    **Fields:** ``modes`` (:class:`RollingModes`, arrays ``(S, …)``), ``omega`` Ω ``(S,)`` [rad/s],
    ``leading``, ``trailing`` patch edges ``(S,)`` [rad], ``deflection`` ``(S,)`` [m],
    ``rolling_radius`` R_e [m] (scalar), ``ok`` ``(S,)`` (contact solve converged, patch in its window).
    """

    modes: RollingModes
    omega: jax.Array
    leading: jax.Array
    trailing: jax.Array
    deflection: jax.Array
    rolling_radius: jax.Array
    ok: jax.Array


def campbell_modes(
    ring: RingParams,
    geometry: TyreGeometry,
    load,
    speeds,
    road: AbstractRoad = FlatRoad(),
    *,
    speed_unit: SpeedUnit = "kmh",
    contact: bool = True,
    harmonics: int = DEFAULT_HARMONICS,
    extensible: bool = False,
    model: RingModel = RingModel(),
    solver: ContactSolver = ContactSolver(),
    k_tangential=0.0,
    wheel=None,
) -> CampbellModes:
    """Modes of the loaded tyre at every speed (Campbell diagram data, docs/physics.md §3.7).

    **Arguments:**

    - ``load``: Fz [N]; ``road``: :class:`~ringfit.physics.operating.FlatRoad` or ``Drum``.
    - ``speeds``: ``(S,)`` — road speeds V [km/h] (``speed_unit="kmh"``: Ω = V/R_e with
      ``R_e = R_out − δ/3``, δ of the standing tyre at this load,
      :func:`ringfit.physics.operating.rolling_radius`) or wheel speeds Ω [rad/s]
      (``speed_unit="rad/s"``).
    - ``contact`` (static): ``False`` gives the free spinning ring (no patch, R_e = R_out; ``load`` unused).
    - ``wheel``: ``None`` (rim fixed) or a :class:`ringfit.physics.wheel.Wheel` (the rim on its
      suspension: three more modes per speed, :func:`rolling_modes`).
    - the rest as :func:`loaded_rolling_modes` (static settings).

    **Returns:** :class:`CampbellModes`. Pure JAX, vmapped over speeds; use
    :func:`campbell_modes_jit` for one compilation per number of speeds and settings.
    """
    speeds = jnp.asarray(speeds, dtype=jnp.float64)
    load = jnp.asarray(load, dtype=jnp.float64)
    if contact:
        standing = solve_rolling(ring, geometry, OperatingPoint(jnp.zeros(()), load, road), model=model, solver=solver)
        r_e = rolling_radius(geometry.outer_radius, standing.deflection)
    else:
        r_e = jnp.asarray(geometry.outer_radius, dtype=jnp.float64)
    if speed_unit == "kmh":
        omegas = speeds * KMH / r_e
    elif speed_unit == "rad/s":
        omegas = speeds
    else:
        raise ValueError(f"speed_unit={speed_unit!r}; expected {' or '.join(map(repr, get_args(SpeedUnit)))}")

    def one(om):
        if not contact:
            modes = rolling_modes(ring, geometry, om, ContactArc.none(), harmonics=harmonics, extensible=extensible,
                                  wheel=wheel)
            z = jnp.zeros(())
            return modes, z, z, z, jnp.asarray(True)
        op = OperatingPoint(om, load, road)
        modes, sol = loaded_rolling_modes(ring, geometry, op, harmonics=harmonics, extensible=extensible,
                                          model=model, solver=solver, k_tangential=k_tangential, wheel=wheel)
        lead, trail = patch_edges(sol)
        return modes, lead, trail, sol.deflection, sol.ok

    modes, lead, trail, defl, ok = jax.vmap(one)(omegas)
    return CampbellModes(modes=modes, omega=omegas, leading=lead, trailing=trail, deflection=defl,
                         rolling_radius=r_e, ok=ok)


#: :func:`campbell_modes` wrapped for trace counting (``eqx.debug.get_num_traces`` in the tests).
campbell_modes_traced = eqx.debug.assert_max_traces(campbell_modes, max_traces=None)
_campbell_compiled = eqx.filter_jit(campbell_modes_traced)


def campbell_modes_jit(ring, geometry, load, speeds, road: AbstractRoad = FlatRoad(), **settings) -> CampbellModes:
    """:func:`campbell_modes` compiled once per (number of speeds, settings); floats passed as arrays."""
    ring, geometry, road = as_traced((ring, geometry, road))
    return _campbell_compiled(ring, geometry, jnp.asarray(load, dtype=jnp.float64),
                              jnp.asarray(speeds, dtype=jnp.float64), road, **settings)


__all__ = [
    "DEFAULT_HARMONICS", "ContactArc", "contact_arc", "RollingModes", "harmonic_basis", "gyroscopic_matrices",
    "rolling_modes", "rolling_modes_jit", "mode_labels", "material_acceleration", "sensor_lines",
    "observed_frequencies", "loaded_rolling_modes", "CampbellModes", "campbell_modes",
    "campbell_modes_jit", "campbell_modes_traced", "SensorQuantity", "SpeedUnit",
]
