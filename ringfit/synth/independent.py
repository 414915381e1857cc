"""Joint identification cases whose truth is a discretisation written apart from ringfit's model (issue 32 item 4).

``ringfit identify`` is built on one forward model per state: eq. 18 for the free ring, a Galerkin basis of
inextensible harmonics with the tread springs of the patch for the standing loaded ring (docs/physics.md §6
``ground_contact``), a spectral contact solve for the rolling profiles (§4.4). A case generated with the same
model (:func:`ringfit.synth.identify.make_identify_case`) cannot show the error of that model's *form*. Here the
same physics is discretised otherwise, and **nothing of** ``ringfit.physics`` **is used**:

- the ring is the pair (w, v) on ``n`` grid points φ_j = −π + 2πj/n, derivatives by periodic central finite
  differences of order 2 or 4 (:func:`stencils`), the membrane kept stiff by a penalty EA (not the
  inextensible constraint), the rim fixed: the stiffness of §2.2/§4.1 (EI, P = p₀b/R, k_w, k_v, EA),
  mass ρA on both w and v (:func:`ring_stiffness`);
- **free modes**: the lowest eigenpairs of that sparse generalised problem (shift-invert), each labelled by the
  dominant harmonic of its w (:func:`fd_free_frequencies`);
- **loaded, standing modes**: the same matrices plus the tread springs k_trd on w at the grid points inside the
  static patch (the fraction of each cell inside |φ| < a, so the patch is not a staircase), a from this module's
  own static contact solve; modes split by the parity of w about the patch centre, ascending, the rigid
  rotation (w ≡ 0) left out (:func:`fd_loaded_frequencies`);
- **rolling profiles** at known load and speed: the steady equations of §4.1 (χ = 1, hysteretic damping
  η = 2ζ on the elastic terms as §4.2 states it) in the FD discretisation — circulant, so solved per discrete
  harmonic with the stencils' own symbols —, the §4.3 tread-spring law on a flat road with Fz imposed by a plain
  active-set loop (:func:`fd_rolling`), and the baseline sensor of §4.6/§5 (no gravity, tilt or high-pass:
  ``s_rad = −a_r``, ``s_tan = a_θ``; :func:`fd_channels`).

The FD discretisation converges to the closed forms (eq. 18, §2.2's extensible root) at the stencil's order
(tests/test_independent_truth.py); ringfit's equations are used nowhere else as a check.

:func:`make_independent_case` writes a ``ringfit identify`` case folder (docs/formats.md §6) with the file
layout of :func:`ringfit.synth.identify.make_identify_case` and its noise: random ring around Table 9, relative
noise on frequencies, coloured noise, a gain and an angle offset on the profiles.
"""

from __future__ import annotations

import json
import math
import os
from typing import Literal

import numpy as np

from ringfit.units import KMH

#: Periodic central-difference coefficients {offset: c} and the power of h dividing them, per order and derivative.
_COEFFS = {
    2: ({-1: -1, 1: 1}, {-1: 1, 0: -2, 1: 1}, {-2: -1, -1: 2, 1: -2, 2: 1}, {-2: 1, -1: -4, 0: 6, 1: -4, 2: 1}),
    4: ({-2: 1, -1: -8, 1: 8, 2: -1}, {-2: -1, -1: 16, 0: -30, 1: 16, 2: -1},
        {-3: 1, -2: -8, -1: 13, 1: -13, 2: 8, 3: -1}, {-3: -1, -2: 12, -1: -39, 0: 56, 1: -39, 2: 12, 3: -1}),
}
_DENOM = {2: (2, 1, 2, 1), 4: (12, 12, 8, 6)}

#: Penalty EA [N] of the truth's membrane: §2.2 puts the flexural branch within 0.03 Hz of eq. 18 at 1e6 N.
EA_PENALTY = 1e9
#: Grid of the free and loaded eigenproblems, of the static patch solve and of the rolling profiles.
EIGEN_GRID = 1024
PATCH_GRID = 4096
PROFILE_GRID = 2048
#: A discretisation of the truth (the keys of :data:`RESOLUTIONS`).
Resolution = Literal["fine", "coarse"]
#: The truth's discretisations: ``fine`` (the default) is converged far below the noise (4th order; the patch's
#: edge cells weighted by the share inside it); ``coarse`` is the same physics on a coarse 2nd-order grid with a
#: staircase patch (the grid points inside it, its half-angle from the active set's count) — a discretisation
#: still consistent with the equations whose own error, of the order of the data's noise, stands in for a model
#: form that differs from the data's more than ringfit's grid check can see.
RESOLUTIONS: dict[Resolution, dict] = {
    "fine": dict(order=4, eigen=EIGEN_GRID, patch=PATCH_GRID, profile=PROFILE_GRID, staircase=False),
    "coarse": dict(order=2, eigen=360, patch=720, profile=720, staircase=True),
}
#: Loads [N] of the standing loaded tables and of the profiles with their speeds [km/h] (as make_identify_case).
LOADED_LOADS = (3000.0, 5000.0)
PROFILE_POINTS = ((3000.0, 30.0), (4000.0, 50.0), (5000.0, 70.0))


def stencils(n: int, h: float, order: int = 4):
    """Periodic central finite-difference matrices d/dφ … d⁴/dφ⁴ (``scipy.sparse``, order 2 or 4)."""
    import scipy.sparse as sp

    out = []
    for coeffs, d, p in zip(_COEFFS[order], _DENOM[order], (1, 2, 3, 4)):
        rows = np.concatenate([np.arange(n)] * len(coeffs))
        cols = np.concatenate([(np.arange(n) + k) % n for k in coeffs])
        vals = np.concatenate([np.full(n, c / (d * h**p)) for c in coeffs.values()])
        out.append(sp.csr_matrix((vals, (rows, cols)), shape=(n, n)))
    return tuple(out)


def symbols(n: int, order: int = 4) -> tuple:
    """The stencils' symbols on the discrete harmonics m = ``np.fft.fftfreq(n, 1/n)``: (d^p x)_j = Σ_k c_k x_{j+k}
    acting on e^{imφ} multiplies it by Σ_k c_k e^{imkh}. **Returns** ``(m, (D1, D2, D3, D4))``."""
    h = 2 * np.pi / n
    m = np.fft.fftfreq(n, 1.0 / n)
    out = []
    for coeffs, d, p in zip(_COEFFS[order], _DENOM[order], (1, 2, 3, 4)):
        out.append(sum(c * np.exp(1j * m * k * h) for k, c in coeffs.items()) / (d * h**p))
    return m, tuple(out)


def _params(ring, geometry):
    R, b, p0, tau = (float(x) for x in (geometry.radius, geometry.width, geometry.pressure, geometry.tread_thickness))
    rho_a, ei, kw, kv, ktrd = (float(getattr(ring, k)) for k in ("rho_a", "ei", "kw", "kv", "k_tread"))
    return R, b, p0, tau, rho_a, ei, kw, kv, ktrd


def ring_stiffness(ring, geometry, n: int, *, order: int = 4, ea: float = EA_PENALTY, omega: float = 0.0):
    """The ring's sparse stiffness (w block first, then v) on n points, §4.1 at χ = 1 without damping:

    ``(R) EI/R⁴(w'''' − v''') + (EA/R² − ρAΩ²)(w + v') − P(w'' + w) + k_w w``,
    ``(T) EI/R⁴(w''' − v'') − (EA/R² − ρAΩ²)(v'' + w') + k_v v``, P = p₀b/R (symmetric: d1, d3
    antisymmetric).
    The membrane terms are the energy of the discrete strain ε = (w + d1 v)/R, so that v'' there is d1·d1, not
    the 5-point d2: a shape with ε = 0 on the grid then carries no penalty (with d2 the penalty EA locks the ring,
    an error ∝ EA h⁴)."""
    import scipy.sparse as sp

    R, b, p0, _, rho_a, ei, kw, kv, _ = _params(ring, geometry)
    P = p0 * b / R
    d1, d2, d3, d4 = stencils(n, 2 * np.pi / n, order)
    eye = sp.identity(n)
    m = ea / R**2 - rho_a * omega**2
    b4 = ei / R**4
    return sp.bmat([[b4 * d4 + m * eye - P * (d2 + eye) + kw * eye, -b4 * d3 + m * d1],
                    [b4 * d3 - m * d1, -b4 * d2 - m * (d1 @ d1) + kv * eye]]).tocsc()


def patch_weights(n: int, half_angle: float, staircase: bool = False) -> np.ndarray:
    """The share of each grid cell [φ_j − h/2, φ_j + h/2] inside the patch |φ| < a (``staircase``: 1 for the grid
    points inside it, 0 elsewhere)."""
    h = 2 * np.pi / n
    phi = -np.pi + h * np.arange(n)
    if half_angle >= np.pi:
        return np.ones(n)  # the whole circle (the cell at φ = −π wraps round)
    if staircase:
        return (np.abs(phi) < half_angle).astype(np.float64)
    lo = np.maximum(phi - h / 2, -half_angle)
    hi = np.minimum(phi + h / 2, half_angle)
    return np.clip(hi - lo, 0.0, None) / h


def fd_modes(ring, geometry, n: int = EIGEN_GRID, *, half_angle: float = 0.0, order: int = 4,
             ea: float = EA_PENALTY, count: int = 26, staircase: bool = False):
    """The ``count`` lowest modes of the rim-fixed ring, with the tread springs k_trd on w over |φ| < a.

    **Returns** ``(f_hz, w, v)``: frequencies ascending ``(count,)`` and the mode shapes ``(n, count)``."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    R, b, p0, tau, rho_a, ei, kw, kv, ktrd = _params(ring, geometry)
    K = ring_stiffness(ring, geometry, n, order=order, ea=ea)
    if half_angle > 0:
        K = K + sp.diags(np.concatenate([ktrd * patch_weights(n, half_angle, staircase), np.zeros(n)]))
    M = sp.identity(2 * n, format="csc") * rho_a
    # a fixed start vector: ARPACK's default is random, which made a seeded case differ between runs in its last bits
    lam, vec = spla.eigsh(K.tocsc(), k=count, M=M, sigma=0.0, which="LM", v0=np.ones(2 * n))
    order_ = np.argsort(lam)
    lam, vec = lam[order_], vec[:, order_]
    return np.sqrt(np.clip(lam, 0.0, None)) / (2 * np.pi), vec[:n], vec[n:]


def _dominant_harmonic(w: np.ndarray) -> int:
    return int(np.argmax(np.abs(np.fft.rfft(w, axis=0))))


def fd_free_frequencies(ring, geometry, n_max: int = 9, n: int = EIGEN_GRID, *, order: int = 4,
                        ea: float = EA_PENALTY) -> np.ndarray:
    """Free (rim-fixed, no contact) flexural frequencies [Hz] of harmonics 1 … n_max by the FD eigenproblem:
    each eigenpair labelled by the dominant harmonic of its w (a degenerate cos/sin pair: the mean of the two)."""
    f, w, v = fd_modes(ring, geometry, n, order=order, ea=ea, count=2 * n_max + 4)
    out = {}
    for j in range(f.size):
        if np.linalg.norm(w[:, j]) < 1e-3 * np.linalg.norm(v[:, j]):
            continue  # the rigid rotation (n = 0)
        out.setdefault(_dominant_harmonic(w[:, j]), []).append(f[j])
    return np.array([np.mean(out[k]) for k in range(1, n_max + 1)])


def fd_loaded_frequencies(ring, geometry, half_angle: float, n_max: int = 7, n: int = EIGEN_GRID, *,
                          order: int = 4, ea: float = EA_PENALTY,
                          staircase: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Standing loaded modes [Hz]: ``(cos_type, sin_type)``, each the ``n_max`` lowest modes whose w is even
    (resp. odd) about the patch centre φ = 0, ascending (the k-th continues harmonic k of the free ring); the
    rigid rotation (w ≡ 0; the patch's radial springs do not see it) is left out."""
    f, w, v = fd_modes(ring, geometry, n, half_angle=half_angle, order=order, ea=ea, count=2 * n_max + 8,
                       staircase=staircase)
    refl = (-np.arange(n)) % n  # φ_j → −φ_j
    even, odd = [], []
    for j in range(f.size):
        wj = w[:, j]
        if np.linalg.norm(wj) < 1e-3 * np.linalg.norm(v[:, j]):
            continue
        (even if np.linalg.norm(wj - wj[refl]) < np.linalg.norm(wj + wj[refl]) else odd).append(f[j])
    if len(even) < n_max or len(odd) < n_max:
        raise RuntimeError(f"FD loaded modes: {len(even)} even and {len(odd)} odd found, {n_max} each wanted")
    return np.array(even[:n_max]), np.array(odd[:n_max])


def fd_rolling(ring, geometry, load: float, n: int = PROFILE_GRID, *, order: int = 4, omega: float = 0.0,
               ea: float = EA_PENALTY, window_deg: float = 35.0, damped: bool = True) -> dict:
    """The steady rolling (or, Ω = 0, standing) ring on a flat road, written independently of ringfit.

    §4.1's equations at χ = 1 by central finite differences in φ on n points — a circulant operator, solved per
    discrete harmonic m with the stencils' symbols (:func:`symbols`; the same solution as the sparse FD system,
    without its factorisation); hysteretic damping (§4.2: the elastic terms EI, P, k_w, k_v times 1 + iη sign m,
    η = 2ζ; EA and inertia undamped) when ``damped`` and Ω > 0; the Nyquist harmonic zeroed. Contact (§4.3):
    radial tread springs, s = H/cos φ, Fz = R Σ p cos φ Δφ imposed, a plain active-set loop on the window
    |φ| ≤ ``window_deg``.

    **Returns** ``dict(phi, w, v, p, H, delta, lead, trail)``: grid [rad], displacements [m], pressure [N/m],
    axle height [m], penetration δ on the window [m] and the patch edges [rad] (zero crossings of δ, linear
    interpolation between the grid points)."""
    R, b, p0, tau, rho_a, ei, kw, kv, ktrd = _params(ring, geometry)
    P = p0 * b / R
    h = 2 * np.pi / n
    phi = -np.pi + h * np.arange(n)
    m, (D1, D2, D3, D4) = symbols(n, order)
    b4 = ei / R**4
    eta = 2.0 * float(ring.damping_ratio) if damped and omega > 0 else 0.0
    damp = 1.0 + 1j * eta * np.sign(m)
    mem = ea / R**2 - rho_a * omega**2
    L = np.empty((n, 2, 2), complex)
    L[:, 0, 0] = (b4 * D4 - P * (D2 + 1) + kw) * damp + mem
    L[:, 0, 1] = -b4 * D3 * damp + mem * D1
    L[:, 1, 0] = b4 * D3 * damp - mem * D1
    L[:, 1, 1] = (-b4 * D2 + kv) * damp - mem * D1 * D1
    G = np.linalg.inv(L)
    G[n // 2] = 0.0  # the Nyquist harmonic
    # w = g ⊛ q_w for a radial load density q_w on the grid (circular convolution)
    g_ww = np.fft.ifft(G[:, 0, 0]).real
    win = np.flatnonzero(np.abs(phi) <= math.radians(window_deg))
    A = -g_ww[(win[:, None] - win[None, :]) % n]  # w at the window from a unit pressure (q_w = −p)
    phik = phi[win]
    active = np.abs(phik) < 0.1
    for _ in range(100):
        k_idx = np.flatnonzero(active)
        sysm = np.zeros((k_idx.size + 1, k_idx.size + 1))
        sysm[:-1, :-1] = np.eye(k_idx.size) - ktrd * A[np.ix_(k_idx, k_idx)]
        sysm[:-1, -1] = ktrd / np.cos(phik[k_idx])
        sysm[-1, :-1] = R * h * np.cos(phik[k_idx])
        x = np.linalg.solve(sysm, np.append(np.full(k_idx.size, ktrd * (R + tau)), load))
        p = np.zeros(win.size)
        p[k_idx] = x[:-1]
        delta = R + tau + A @ p - x[-1] / np.cos(phik)
        new = delta > 0
        if np.array_equal(new, active):
            break
        active = new
    else:
        raise RuntimeError(f"FD contact at {load:g} N: the active set did not settle")
    if active[0] or active[-1]:
        raise RuntimeError(f"FD contact at {load:g} N: the patch reaches the window's edge")
    q = np.zeros(n)
    q[win] = -p
    Q = np.fft.fft(q)
    w = np.fft.ifft(G[:, 0, 0] * Q).real
    v = np.fft.ifft(G[:, 1, 0] * Q).real
    idx = np.flatnonzero(active)
    i0, i1 = idx[0], idx[-1]

    def cross(a, b_):  # zero of δ between window points a (δ ≤ 0) and b_ (δ > 0)
        return phik[a] + (phik[b_] - phik[a]) * (-delta[a]) / (delta[b_] - delta[a])

    full_p = np.zeros(n)
    full_p[win] = p
    return dict(phi=phi, w=w, v=v, p=full_p, H=float(x[-1]), delta=delta, lead=float(cross(i0 - 1, i0)),
                trail=float(cross(i1 + 1, i1)), active=int(idx.size))


def fd_channels(sol: dict, omega: float) -> tuple[np.ndarray, np.ndarray]:
    """The baseline sensor's reading of a :func:`fd_rolling` solution (§4.6, §5 layers 2 and 6 only): radial
    ``−a_r`` (toward the centre +) and tangential ``a_θ`` (along travel +), ``a_r = Ω²(w″ − 2v′ − w)``,
    ``a_θ = Ω²(v″ + 2w′ − v)`` by spectral derivatives of the FD fields, each without its mean [m/s²]."""
    w, v = sol["w"], sol["v"]
    n = w.size
    k = np.fft.rfftfreq(n, 1.0 / n)
    W, V = np.fft.rfft(w), np.fft.rfft(v)
    a_r = omega**2 * np.fft.irfft(-(k**2) * W - 2j * k * V - W, n)
    a_t = omega**2 * np.fft.irfft(-(k**2) * V + 2j * k * W - V, n)
    return -(a_r - a_r.mean()), a_t - a_t.mean()


def fd_profile(ring, geometry, load, n, *, order=4, omega=2 * math.pi * 9.0, ea=EA_PENALTY, window_deg=35.0,
               damped=False):
    """The radial reading of the steady rolling ring (:func:`fd_rolling`, :func:`fd_channels`) on φ_j =
    −π + 2πj/n: ``(φ, reading)`` [rad, m/s²], toward the centre +, without its mean. Undamped unless ``damped``
    (then hysteretic with ``ring``'s damping ratio)."""
    sol = fd_rolling(ring, geometry, load, n, order=order, omega=omega, ea=ea, window_deg=window_deg, damped=damped)
    return sol["phi"], fd_channels(sol, omega)[0]


def standing_half_angle(ring, geometry, load: float, n: int = PATCH_GRID, *, order: int = 4,
                        staircase: bool = False) -> float:
    """Half the static patch's length [rad] at ``load`` (Ω = 0) by :func:`fd_rolling`: between the zero crossings
    of the penetration, or (``staircase``) the active grid points' count times h/2."""
    sol = fd_rolling(ring, geometry, load, n, order=order, omega=0.0)
    if staircase:
        return 0.5 * sol["active"] * 2 * np.pi / n
    return 0.5 * (sol["trail"] - sol["lead"])


def resample(values: np.ndarray, angles_rad: np.ndarray, k_max: int) -> np.ndarray:
    """The periodic grid function ``values`` (on φ_j = −π + 2πj/n) evaluated at ``angles_rad`` by its Fourier
    series up to harmonic ``k_max`` (band-limited interpolation)."""
    n = values.size
    c = np.fft.rfft(values)[: k_max + 1] / n
    k = np.arange(c.size)
    c = c * np.exp(1j * k * np.pi)  # the grid starts at −π
    x = np.asarray(angles_rad)[:, None]
    terms = c[None, :] * np.exp(1j * k[None, :] * x)
    return (terms[:, 0] + 2.0 * terms[:, 1:].sum(axis=1)).real


def make_independent_case(folder: str | os.PathLike, seed: int = 0, *, profiles: bool = True, loaded: bool = True,
                          noise_colour: str | None = None, truth_file: bool = True,
                          resolution: Resolution = "fine") -> dict:
    """Write a ``ringfit identify`` case into ``folder`` (created; must be empty or absent) from the independent
    FD truth at ``resolution`` (:data:`RESOLUTIONS`); returns the truth (also ``truth.json`` there when
    ``truth_file``; the identification does not read it). Files and noise as
    :func:`ringfit.synth.identify.make_identify_case`."""
    if resolution not in RESOLUTIONS:
        raise ValueError(f"resolution = {resolution!r}; expected one of {tuple(RESOLUTIONS)}")
    res = RESOLUTIONS[resolution]
    order, stair = res["order"], res["staircase"]
    from ringfit.io.profiles import Profile, write_profile
    from ringfit.io.tyre import Tyre, write_tyre
    from ringfit.synth.cases import NOISE_COLOURS, TableWriter, _new_case_folder, coloured_noise, joint_ring

    rng = np.random.default_rng(seed)
    folder = _new_case_folder(folder)
    geometry, ring, zeta = joint_ring(rng)
    if float(geometry.tread_rib_width) > 0:
        raise ValueError("the FD truth has Winkler tread springs: tread_rib_width must be 0")
    sigma_rel = float(rng.uniform(0.001, 0.003))
    with_std = bool(rng.random() < 0.5)
    write_tyre(Tyre(geometry, {}), folder / "tyre.toml")

    table = TableWriter(folder, rng, sigma_rel, with_std)

    n_free = np.arange(1, 10)
    f_free = fd_free_frequencies(ring, geometry, 9, res["eigen"], order=order)
    damp = 100.0 * zeta * np.exp(rng.normal(0.0, 0.05, n_free.size))
    table("free.modes.csv", f_free, n_free, [""] * n_free.size, damp, {"state": "free"})
    half_angles = {}
    if loaded:
        for load in LOADED_LOADS:
            half = standing_half_angle(ring, geometry, load, res["patch"], order=order, staircase=stair)
            half_angles[load] = half
            c, s = fd_loaded_frequencies(ring, geometry, half, 7, res["eigen"], order=order, staircase=stair)
            n = np.arange(1, 8)
            tags = ["vert" if k == 1 else "extr" for k in n] + ["hort" if k == 1 else "0" for k in n]
            table(f"loaded{int(load)}.modes.csv", np.concatenate([c, s]), np.concatenate([n, n]), tags,
                  np.full(2 * n.size, np.nan), {"state": "loaded", "load_n": load, "speed_kmh": 0.0})
    truth_profiles = []
    if profiles:
        colour = noise_colour or str(rng.choice(NOISE_COLOURS))
        R_out = float(geometry.radius + geometry.tread_thickness)
        for i, (load, speed) in enumerate(PROFILE_POINTS):
            n_points = int(rng.choice([720, 1000, 1024]))
            # Ω = V/R_e, R_e = R_out − δ_z/3 with the standing deflection (docs/physics.md §4.3)
            still = fd_rolling(ring, geometry, load, res["profile"], order=order, omega=0.0)
            omega = speed * KMH / (R_out - (R_out - still["H"]) / 3.0)
            sol = fd_rolling(ring, geometry, load, res["profile"], order=order, omega=omega)
            rad, tan = fd_channels(sol, omega)
            gain = float(np.exp(rng.normal(0.0, 0.03)))
            offset_deg = float(rng.uniform(-1.0, 1.0))
            # recorded angle α = φ − offset (docs/physics.md §5 layer 6): the reading at α is the ring at
            # α + offset
            alpha = -180.0 + 360.0 * np.arange(n_points) / n_points
            at = np.radians(alpha + offset_deg)
            k_max = (n_points - 1) // 2
            ch = gain * np.stack([resample(rad, at, k_max), resample(tan, at, k_max)])
            sigma = float(rng.uniform(0.005, 0.02)) * float(np.std(ch[0]))
            ch = ch + np.stack([coloured_noise(rng, n_points, sigma, colour),
                                coloured_noise(rng, n_points, sigma, colour)])
            cond = dict(speed_kmh=speed, load_n=load, pressure_bar=float(geometry.pressure) / 1e5,
                        rotation_hz=omega / (2 * np.pi), revolutions=50, sample_rate_hz=25600.0)
            write_profile(Profile(alpha, ch[0], ch[1], condition=cond, source=""), folder / f"run{i + 1}.profile.csv")
            truth_profiles.append(dict(load_n=load, speed_kmh=speed, gain=gain, angle_offset_deg=offset_deg,
                                       noise_ms2=sigma, noise_colour=colour, n_points=n_points,
                                       half_angle=0.5 * (sol["trail"] - sol["lead"])))
    truth = dict(seed=seed, ring={k: float(v) for k, v in ring.as_dict().items() if math.isfinite(v)},
                 sigma_rel=sigma_rel, with_std=with_std, half_angles=half_angles, profiles=truth_profiles,
                 truth="finite differences (ringfit.synth.independent)",
                 resolution=resolution, discretisation=dict(res, ea=EA_PENALTY))
    if truth_file:
        (folder / "truth.json").write_text(json.dumps(truth, indent=1))
    truth["ring_object"] = ring
    truth["geometry"] = geometry
    return truth


__all__ = ["stencils", "symbols", "ring_stiffness", "patch_weights", "fd_modes", "fd_free_frequencies",
           "fd_loaded_frequencies", "fd_rolling", "fd_channels", "fd_profile", "standing_half_angle", "resample",
           "make_independent_case", "RESOLUTIONS", "Resolution", "LOADED_LOADS",
           "PROFILE_POINTS"]
