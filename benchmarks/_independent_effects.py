"""Case generators for the gap diagnosis written apart from ringfit's model (issue 30 item 9): power measured on
data ringfit did not simulate.

Every truth here is computed with numpy/scipy from the physics as docs/physics.md states it, by a different
discretisation from the diagnosis's: the ring is the periodic central finite-difference ring of
:mod:`_independent_ring` (§4.1's equations in φ, χ = 1 unless said, a membrane penalty EA for inextensibility),
as a dense real operator; hysteretic loss is the real Hilbert-transform matrix of the FD elastic operator (not a
complex modulus per harmonic); mode tables are eigenvalues of the FD ring's symmetric (cos-type) and antisymmetric
(sin-type) subspaces (not eq. 18 nor the loaded ring's Fourier basis); contact is an active-set loop with a load
balance (not ringfit's spectral contact solve). ringfit is used only for the parameter values of Table 9
(:func:`ringfit.params.table9`), to write the folder files (:mod:`ringfit.io`) and for the km/h conversion
(:data:`ringfit.units.KMH`).

Families (``FAMILIES``; each generator's docstring has its physics):

- mode tables: ``none_modes``, ``cavity_mode``, ``ground_contact``, ``sensor_mass``;
- profiles: ``none_profiles``, ``tread_shear``, ``wave_damping``, ``gravity``, ``sensor_tilt``, ``iepe_highpass``,
  ``rotation``;
- rolling mode tables without labels (20/40/60 km/h, 4 kN, the modes of the Fourier collocation of
  :mod:`_independent_rolling`): ``rolling_contact``, ``rolling_free``.

Each generator ``make(folder, seed) -> IndependentLabel`` writes one case folder (docs/formats.md §6) and returns
the hidden answer: the effect that must be found (``None`` for a null; ``a+b``: every one of them), the effects the truth contains (a
``cavity_mode`` case on a loaded table also has the ground contact), and the realised noise for the ideal shrink
(the same fields bench_gap reads from ringfit's own labels); ``extra["candidates"]``, where set, the candidates
the benchmark gives the diagnosis (the rolling families: bench_gap_rolling's ``ground_contact,rotation``; their
``extra`` also holds the truth ring and every true line with its dominant harmonic).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.linalg as sla

from _independent_ring import _stencils
from ringfit.units import KMH

#: Sound speed [m/s] and cavity length [m] of eq. 22 (docs/physics.md §3.6).
SOUND_SPEED, CAVITY_LENGTH = 343.0, 1.568
ATMOSPHERE_PA = 101325.0
#: Membrane stiffness of the "inextensible" truth [N]: far above a belt's ~1e8 N, so no ring_extensibility
#: signature (relative frequency shift ~ k_w R²/EA ≈ 1e-6, well under the rows' noise).
EA_INEXTENSIBLE = 1e10


@dataclass
class IndependentLabel:
    """The hidden answer of one independent case."""

    family: str
    expected: str | None  # the effect(s) that must be accepted ("a+b": all; None: a null case, the verdict `none`)
    truth: tuple[str, ...]  # every effect the truth contains (accepted ones outside this are "extra")
    magnitude: dict
    noise: dict
    domain: str  # "modes" or "profiles"
    expected_verdict: str = ""  # for bench_gap's ideal-shrink helpers
    extra: dict = field(default_factory=dict)


def _truth_ring(rng, tread_sd=0.0):
    """Table 9's parameters (docs/physics.md §1) each scaled by a log-normal ±6 % (k_trd by ±tread_sd more)."""
    from ringfit.params import table9

    geometry, ring = table9()
    f = lambda: float(np.exp(rng.normal(0.0, 0.06)))  # noqa: E731
    p = dict(rho_a=float(ring.rho_a) * f(), ei=float(ring.ei) * f(), kw=float(ring.kw) * f(), kv=float(ring.kv) * f(),
             k_tread=float(ring.k_tread) * f() * float(np.exp(rng.normal(0.0, tread_sd))))
    g = dict(R=float(geometry.radius), b=float(geometry.width), p0=float(geometry.pressure),
             tau=float(geometry.tread_thickness))
    return geometry, p, g


# ============================================================================ the FD ring as dense operators
def _fd(n, order=4):
    return [d.toarray() for d in _stencils(n, 2 * np.pi / n, order)]


def _hilbert(n):
    """Real n×n matrix multiplying harmonic k of a periodic grid signal by i·sign(k) (Nyquist dropped)."""
    k = np.fft.fftfreq(n, 1.0 / n)
    s = 1j * np.sign(k)
    if n % 2 == 0:
        s[n // 2] = 0.0
    return np.real(np.fft.ifft(s[:, None] * np.fft.fft(np.eye(n), axis=0), axis=0))


def fd_operator(p, g, n, *, omega=0.0, eta=0.0, viscous_c=0.0, eta_slope=0.0, eta_order2=0.0, chi=1.0,
                ea=EA_INEXTENSIBLE,
                order=4, diff=None):
    """The steady rolling ring's operator L [w; v] = [q_w; q_v] of docs/physics.md §4.1 by central differences
    (2n × 2n, real): elastic part K_el (EI, the pressure term P = p0 b/R, k_w, k_v), membrane part (EA/R² − ρAΩ²),
    the (1−χ)ρAΩ² centrifugal term; damping in the φ domain: hysteretic η·H·K_el (H the Hilbert matrix: i sign(n)
    on harmonic n, §4.2's iη s_n K_n^c), viscous c_w = c_v = c as cΩ d/dφ on both equations (§4.2's i nΩ c), and a
    loss factor growing with the harmonic's frequency |n|Ω (§6 wave_damping's η1|n|Ω/ω_ref, ω_ref = 2π·100 Hz) as
    (η1 Ω/ω_ref)·d/dφ·K_el (the FD derivative, not the spectral n); and a hysteretic loss growing with the square of
    the order, η(n) = η0 + η2 (n/10)², as η2/100·H·(−d²/dφ²)·K_el — a form neither of wave_damping's two has."""
    d1, d2, d3, d4 = diff if diff is not None else _fd(n, order)
    eye, zero = np.eye(n), np.zeros((n, n))
    R = g["R"]
    b4 = p["ei"] / R**4
    P = g["p0"] * g["b"] / R
    # bending and membrane in energy form, B = [d2, -d1] (curvature change w'' - v') and E = [1, d1] (strain
    # w + v'): B^T B gives §4.1's EI/R^4 (w'''' - v''', w''' - v''), E^T E its (w + v', -(v'' + w')); a field with
    # w = -d1 v is then exactly inextensible on the grid (no membrane locking under the large EA penalty)
    B = np.hstack([d2, -d1])
    E = np.hstack([eye, d1])
    K_el = b4 * B.T @ B + np.block([[-P * (d2 + eye) + p["kw"] * eye, zero], [zero, p["kv"] * eye]])
    m = ea / R**2 - p["rho_a"] * omega**2
    memb = m * E.T @ E
    c = (1.0 - chi) * p["rho_a"] * omega**2
    cent = np.block([[c * d2, -c * d1], [c * d1, -c * eye]])  # (1−χ)ρAΩ²(w″ − v′), (1−χ)ρAΩ²(w′ − v)
    L = K_el + memb + cent
    if eta:
        H = _hilbert(n)
        L = L + eta * np.vstack([H @ K_el[:n], H @ K_el[n:]])
    if viscous_c:
        L = L + viscous_c * omega * np.kron(np.eye(2), d1)
    if eta_order2:
        H2 = _hilbert(n) @ (-d2) / 100.0
        L = L + eta_order2 * np.vstack([H2 @ K_el[:n], H2 @ K_el[n:]])
    if eta_slope:
        L = L + eta_slope * omega / (2 * np.pi * 100.0) * np.vstack([d1 @ K_el[:n], d1 @ K_el[n:]])
    return L


# ============================================================================ mode tables
def _symmetric_basis(n, parity):
    """Orthonormal basis of [w; v] grid fields with w(−φ) = ±w(φ), v(−φ) = ∓v(φ) (parity +1: cos-type)."""
    j = (-np.arange(n)) % n  # φ_j = −π + 2πj/n: −φ_j is grid point (n − j) mod n
    S = np.eye(n)[j]
    T = np.block([[parity * S, np.zeros((n, n))], [np.zeros((n, n)), -parity * S]])
    vals, vecs = np.linalg.eigh(0.5 * (np.eye(2 * n) + T))
    return vecs[:, vals > 0.5]


def fd_modes(p, g, *, n=384, patch=0.0, point_mass=0.0, n_max=10):
    """Natural frequencies [Hz] of the static FD ring (Ω = 0, undamped), per wave number 1…n_max, cos-type and
    sin-type: generalised eigenvalues of (K + springs, M) in each symmetry subspace, with K the FD operator of
    :func:`fd_operator` times R·h (forces per node), M = ρA·R·h per node plus ``point_mass`` [kg] at the node
    φ = 0 (both directions), and radial tread springs k_trd·R·h at the nodes with |φ| < ``patch`` [rad] (the
    loaded tyre's contact, docs/physics.md §6 ground_contact). The k-th mode of each type in frequency order is
    n = k (the belt's rigid turn, n = 0, left out). **Returns:** ``{"cos": array, "sin": array}`` indexed by n − 1 (NaN where none found)."""
    h = 2 * np.pi / n
    phi = -np.pi + h * np.arange(n)
    Rh = g["R"] * h
    K = fd_operator(p, g, n) * Rh
    K = 0.5 * (K + K.T)
    K[np.arange(n), np.arange(n)] += p["k_tread"] * Rh * (np.abs(phi) < patch)
    mdiag = np.full(2 * n, p["rho_a"] * Rh)
    j0 = n // 2  # φ = 0
    mdiag[j0] += point_mass
    mdiag[n + j0] += point_mass
    out = {}
    for name, parity in (("cos", 1), ("sin", -1)):
        B = _symmetric_basis(n, parity)
        lam, vec = sla.eigh(B.T @ K @ B, B.T @ np.diag(mdiag) @ B)
        f, k = np.full(n_max, np.nan), 0
        for lj, v in zip(lam, vec.T):  # ascending; the k-th flexural mode of its type is n = k (as measured
            # tables number the loaded modes), the rigid turn of the belt on its sidewalls (n = 0: v uniform) left out
            wv = B @ v
            if abs(np.mean(wv[n:])) > 0.5 * np.sqrt(np.mean(wv[n:] ** 2) + np.mean(wv[:n] ** 2)):
                continue
            if k < n_max:
                f[k] = math.sqrt(max(lj, 0.0)) / (2 * np.pi)
                k += 1
        out[name] = f
    return out


def fd_static(p, g, load, *, n=512, omega=0.0, eta=0.0, viscous_c=0.0, eta_slope=0.0, eta_order2=0.0, chi=1.0,
              tread_shear=None,
              window_deg=40.0, shear_iterations=80, relax=0.5):
    """The steady rolling (or standing) ring on a flat road by FD: docs/physics.md §4.1 (operator of
    :func:`fd_operator`), §4.3 (radial tread springs, s = H/cos φ, Fz = R∫p cos φ imposed) by an active-set loop;
    with ``tread_shear = (k_x, μ)`` also the brush with the lever (§6 tread_shear), iterated to its fixed point
    (damped, ``relax``; ≈ 30 steps for k_x = 40 MN/m², where one step — ringfit's scheme — is off by more than
    the shear's own signal):
    the tread tip, at x = (R+w) sin φ + v cos φ + τ sin(φ − ψ), ψ = (w′ − v)/R, sticks at the leading edge and is
    carried by the road, q_x = −k_x(x − x_lead − r_e(φ − φ_lead)) clipped at ±μp, r_e such that Σ q_x = 0 (no
    drive), and acts on the belt through the transpose of the linearised tip kinematics. **Returns:** dict with
    φ, w, v, p (tread pressure per length), H (axle height), the patch half-angle a [rad] and, with shear, q_x."""
    R, tau = g["R"], g["tau"]
    h = 2 * np.pi / n
    phi = -np.pi + h * np.arange(n)
    diff = _fd(n)
    d1 = diff[0]
    L = fd_operator(p, g, n, omega=omega, eta=eta, viscous_c=viscous_c, eta_slope=eta_slope, eta_order2=eta_order2,
                    chi=chi, diff=diff)
    lu = sla.lu_factor(L)
    win = np.flatnonzero(np.abs(phi) <= math.radians(window_deg))
    rhs = np.zeros((2 * n, win.size))
    rhs[win, np.arange(win.size)] = -1.0
    resp = sla.lu_solve(lu, rhs)
    A = resp[:n][win]
    phik = phi[win]
    ktrd = p["k_tread"]

    def contact(extra):  # extra: (2n,) response to the shear loads
        ew = extra[:n][win]
        active = np.abs(phik) < 0.1
        for _ in range(80):
            k_idx = np.flatnonzero(active)
            sysm = np.zeros((k_idx.size + 1, k_idx.size + 1))
            sysm[:-1, :-1] = np.eye(k_idx.size) - ktrd * A[np.ix_(k_idx, k_idx)]
            sysm[:-1, -1] = ktrd / np.cos(phik[k_idx])
            sysm[-1, :-1] = R * h * np.cos(phik[k_idx])
            x = np.linalg.solve(sysm, np.append(ktrd * (R + tau + ew[k_idx]), load))
            pk = np.zeros(win.size)
            pk[k_idx] = x[:-1]
            new = (R + tau + A @ pk + ew - x[-1] / np.cos(phik)) > 0
            if np.array_equal(new, active):
                break
            active = new
        wv = resp @ pk + extra
        pen = R + tau + wv[:n][win] - x[-1] / np.cos(phik)
        axle[0] = x[-1]
        return wv, pk, pen

    axle = [0.0]

    extra = np.zeros(2 * n)
    wv, pk, pen = contact(extra)
    q_x = np.zeros(n)
    if tread_shear is not None:
        k_x, mu = tread_shear
        for _ in range(shear_iterations):
            w, v = wv[:n], wv[n:]
            psi = (d1 @ w - v) / R
            x_tip = (R + w) * np.sin(phi) + v * np.cos(phi) + tau * np.sin(phi - psi)
            press = np.zeros(n)
            press[win] = pk
            inside = press > 0
            pen_full = np.full(n, -1.0)
            pen_full[win] = pen
            i0 = int(np.argmax(inside))
            t = -pen_full[i0 - 1] / (pen_full[i0] - pen_full[i0 - 1])  # leading edge between i0−1 and i0
            phi_l = phi[i0 - 1] + t * h
            x_l = x_tip[i0 - 1] + t * (x_tip[i0] - x_tip[i0 - 1])
            s = phi - phi_l

            def forces(r_e):
                q = -k_x * (x_tip - x_l - r_e * s)
                return np.where(inside, np.clip(q, -mu * press, mu * press), 0.0)

            lo, hi = 0.8 * R, 1.2 * (R + tau)
            for _ in range(80):
                mid = 0.5 * (lo + hi)
                lo, hi = (lo, mid) if forces(mid).sum() > 0 else (mid, hi)
            q_x = forces(0.5 * (lo + hi))
            cpsi = np.cos(phi - psi)
            # δx = sin φ δw + cos φ δv − τ cos(φ − ψ)(d1 δw − δv)/R: loads = (∂x/∂(w, v))ᵀ q_x
            q_w = np.sin(phi) * q_x - (tau / R) * d1.T @ (cpsi * q_x)
            q_v = np.cos(phi) * q_x + (tau / R) * cpsi * q_x
            extra_new = sla.lu_solve(lu, np.concatenate([q_w, q_v]))
            if np.max(np.abs(extra_new - extra)) < 1e-10:  # [m]: converged (the undamped iteration diverges)
                extra = extra_new
                break
            extra = (1.0 - relax) * extra + relax * extra_new  # damped fixed point
            wv, pk, pen = contact(extra)
    press = np.zeros(n)
    press[win] = pk
    inside = np.flatnonzero(press > 0)
    a = float(np.max(np.abs(phi[inside]))) + 0.5 * h if inside.size else 0.0
    return {"phi": phi, "w": wv[:n], "v": wv[n:], "p": press, "a": a, "q_x": q_x, "H": axle[0]}


def _spectral_derivatives(x, n):
    k = np.fft.rfftfreq(n, 1.0 / n)
    X = np.fft.rfft(x)
    return lambda order: np.fft.irfft((1j * k) ** order * X, n)


def fd_reading(sol, omega, *, offset=0.0, tilt_gain=0.0, gravity=0.0, corner_hz=0.0, settle=40.0):
    """The sensor's two channels from an FD solution, docs/physics.md §4.6 and §5 layers 1–5 written from the
    text: liner point v_s = v + eψ (ψ = (w′ − v)/R), a_r = Ω²(w″ − 2v_s′ − w) − Ω²R_s, a_θ = Ω²(v_s″ + 2w′ − v_s);
    specific force f_r = a_r − g cos φ, f_θ = a_θ + g sin φ; axes turned by γψ on the zeroth-order force;
    s_rad = −f_r + γψ g sin φ, s_tan = f_θ + γψ(−Ω²R_s − g cos φ). The IEPE high-pass (first order, corner f_c) is
    applied in the time domain: the revolution repeated, filtered with scipy's bilinear ``lfilter`` at 16 samples
    per grid step, the last revolution kept (not the harmonic gain H(ikΩ)). The repeats last ``settle`` time
    constants 1/(2πf_c) (at least 6 revolutions), so the filter's start-up transient — the centripetal level
    Ω²R switched on at t = 0 — has decayed to e^−40 of it: the periodic steady state a sensor on a rolling tyre
    gives. (Until stop 54 six revolutions were filtered: at a 0.8 Hz corner and 60 km/h that left 3 % of Ω²R
    decaying across the last revolution, a ramp of ~12 m/s² that no sensor in steady state shows.) Mean removed
    (docs/physics.md §5).
    **Returns:** (2, n) [radial, tangential] [m/s²]."""
    phi, w, v = sol["phi"], sol["w"], sol["v"]
    n = phi.size
    R = sol["R"]
    dw, dv = _spectral_derivatives(w, n), _spectral_derivatives(v, n)
    psi = (dw(1) - v) / R
    v_s = v + offset * psi
    dvs = _spectral_derivatives(v_s, n)
    R_s = R - offset
    a_r = omega**2 * (dw(2) - 2 * dvs(1) - w) - omega**2 * R_s
    a_t = omega**2 * (dvs(2) + 2 * dw(1) - v_s)
    f_r = a_r - gravity * np.cos(phi)
    f_t = a_t + gravity * np.sin(phi)
    s_rad = -f_r + tilt_gain * psi * gravity * np.sin(phi)
    s_tan = f_t + tilt_gain * psi * (-omega**2 * R_s - gravity * np.cos(phi))
    out = np.stack([s_rad, s_tan])
    if corner_hz > 0:
        import scipy.signal as ss

        up = 16
        dt = 2 * np.pi / omega / (n * up)
        b, a = ss.butter(1, corner_hz, btype="highpass", fs=1.0 / dt)
        fine = np.stack([np.interp(np.arange(n * up) / up, np.arange(n + 1), np.append(c, c[0])) for c in out])
        tau_revolutions = omega / (2 * np.pi) / (2 * np.pi * corner_hz)  # the time constant in revolutions
        long = np.tile(fine, (1, max(6, int(np.ceil(settle * tau_revolutions)) + 1)))
        filt = ss.lfilter(b, a, long, axis=-1)[:, -n * up:]
        out = filt[:, ::up]
    return out - out.mean(axis=-1, keepdims=True)


def fd_free_frequencies(p, g, n_max):
    """Free static natural frequencies [Hz], n = 1…n_max, of the FD ring (the cos-type set: the free ring's
    pairs are degenerate)."""
    return fd_modes(p, g, n_max=n_max)["cos"]


# ============================================================================ writers
def _write_tyre(folder):
    from ringfit.io.tyre import Tyre, write_tyre
    from ringfit.params import table9

    geometry, _ = table9()
    write_tyre(Tyre(geometry, {"rho_a": 2.715, "ei": 0.9426, "kw": 1.294e6, "kv": 1.161e6, "k_tread": 19e6,
                               "damping_ratio": 0.025}), folder / "tyre.toml")


def _write_table(folder, name, rows, condition):
    from ringfit.io.modes import ModeTable, write_mode_table

    f = np.array([r["freq_hz"] for r in rows])
    table = ModeTable(freq_hz=f, n=np.array([r.get("n", -1) for r in rows]),
                      tag=np.array([r.get("tag", "") for r in rows], object),
                      kind=np.array([r.get("kind", "structural") for r in rows], object),
                      branch=np.array([r.get("branch", "") for r in rows], object),
                      damping_pct=np.array([r.get("damping_pct", np.nan) for r in rows]),
                      freq_std_hz=None, condition=condition)
    write_mode_table(table, folder / name)


def _new(folder):
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if any(folder.iterdir()):
        raise FileExistsError(f"{folder} is not empty")
    return folder


FREE_CONDITION = {"state": "free", "speed_kmh": 0, "pressure_bar": 2.2, "frame": "fixed"}


# ============================================================================ mode-table families
def _cavity_pencil(w0, wa, n, p, g, area):
    """The structural root of the ring mode (ω₀) and the cavity mode (ω_a) coupled through the pressure on the
    belt (docs/physics.md §6 cavity_mode: the same physics, written as a 2-DOF pencil): per unit length
    m Ẅ + m ω₀² W − b P = 0 and P̈ + ω_a² P + β Ẅ = 0, β = ρ0 c² b/A_c, m = ρA (n² + 1)/n²; the eigenvalues of
    (K, M) = ([[m ω₀², −b], [0, ω_a²]], [[m, 0], [β, 1]]) by scipy, the root kept on ω₀'s side of ω_a (coupling
    repels the pair)."""
    rho0 = 1.2 * (g["p0"] + ATMOSPHERE_PA) / ATMOSPHERE_PA
    m = p["rho_a"] * (n**2 + 1) / n**2
    beta = rho0 * SOUND_SPEED**2 * g["b"] / area
    lam = np.sort(np.real(sla.eigvals(np.array([[m * w0**2, -g["b"]], [0.0, wa**2]]),
                                      np.array([[m, 0.0], [beta, 1.0]]))))
    return math.sqrt(lam[0] if w0 < wa else lam[1])


def _modal_case(folder, seed, family, loaded_only=False):
    """A mode-table case (docs/formats.md §6): ``tyre.toml`` (Table 9, not the truth), ``free.modes.csv`` (the FD
    ring's free modes, n = 1…8–10, relative noise σ 0.05–0.2 %, damping ζ0 with 8 % scatter, an acoustic row when
    the family is cavity_mode or by chance) and one test table:

    - ``none_modes``: a second free table (the same ring, fresh noise); expected verdict `none`.
    - ``ground_contact``: ``loaded.modes.csv`` at 4000 N, rows n = 1…6–8 tagged vert/extr (cos-type) and hort/0
      (sin-type): the FD ring's modes with radial tread springs k_trd on the nodes of the patch, the patch from
      the FD static contact solve (:func:`fd_static`, :func:`fd_modes`; docs/physics.md §6 ground_contact —
      ringfit solves the loaded modes in a truncated Fourier basis, this in the FD grid's symmetry subspaces).
    - ``cavity_mode``: the same loaded table, every row (and, unless ``loaded_only``, every free row: the air is
      there in every state) coupled with the cavity's acoustic mode of its n through :func:`_cavity_pencil` (a 2-DOF
      eigenproblem, not ringfit's closed root); n = 1 rows of the loaded table meet the lines the flat splits,
      f_cav √(1 ∓ W_2/h_c) (vertical / fore-aft), W_2 from the FD static deflection (docs/physics.md §6
      cavity_mode); A_c 0.008–0.02 m², f_cav 215–232 Hz given as the free table's acoustic row. The truth holds
      ground_contact too: the expected effect is cavity_mode, ground_contact is not an extra.
    - ``sensor_mass``: ``sensor.modes.csv``, a free test table of the ring carrying a 30–120 g point mass at φ = 0
      (both directions) that the free table does not carry: the cos-type FD modes with the mass in the mass matrix
      (the sensor sits at their antinode; docs/physics.md §6 sensor_mass, whose Rayleigh quotient ringfit uses).
    """
    rng = np.random.default_rng(seed)
    folder = _new(folder)
    geometry, p, g = _truth_ring(rng)
    sigma = float(rng.uniform(0.0005, 0.002))
    zeta0 = float(rng.uniform(0.015, 0.035))
    n_free = np.arange(1, int(rng.integers(8, 11)) + 1)
    free = fd_free_frequencies(p, g, int(n_free[-1]))
    magnitude, truth, expected = {}, (), None
    row_noise = []
    f_cav = float(rng.uniform(215.0, 232.0))
    load = 4000.0
    tables = []
    if family in ("cavity_mode", "ground_contact"):
        st = fd_static(p, g, load, n=512)
        a = st["a"]
        magnitude["half_angle_deg"] = math.degrees(a)
        n_load = np.arange(1, int(rng.integers(6, 9)) + 1)
        lm = fd_modes(p, g, patch=a, n_max=int(n_load[-1]))
        lc, ls = lm["cos"], lm["sin"]
        truth, expected = ("ground_contact",), "ground_contact"
        if family == "cavity_mode":
            area = float(rng.uniform(0.008, 0.02))
            magnitude.update(cavity_area_m2=area, cavity_hz=f_cav)
            # the flat splits the first cavity pair (docs/physics.md §6, ringfit/physics/cavity.py's text):
            # W_2 the cos 2φ coefficient of the FD static deflection, h_c = 2(R − L_c/2π)
            W2 = 2.0 * np.real(np.fft.rfft(np.roll(st["w"], -(st["w"].size // 2)))[2]) / st["w"].size
            h_c = 2.0 * (g["R"] - CAVITY_LENGTH / (2 * np.pi))
            magnitude["W2_over_hc"] = W2 / h_c
            wa = lambda nn, cos: 2 * np.pi * (f_cav * math.sqrt(1 - (1 if cos else -1) * W2 / h_c) if nn == 1  # noqa: E731
                                              else nn * f_cav)
            couple = lambda f0, nn, cos: _cavity_pencil(2 * np.pi * f0, wa(nn, cos), nn, p, g, area) / (2 * np.pi)  # noqa: E731
            if not loaded_only:
                free = np.array([_cavity_pencil(2 * np.pi * f0, 2 * np.pi * nn * f_cav, nn, p, g, area) / (2 * np.pi)
                                 for nn, f0 in zip(n_free, free)])
            lc = np.array([couple(f0, nn, True) for nn, f0 in zip(n_load, lc)])
            ls = np.array([couple(f0, nn, False) for nn, f0 in zip(n_load, ls)])
            truth, expected = ("ground_contact", "cavity_mode"), "cavity_mode"
        lrows = []
        for nn, fc, fs in zip(n_load, lc, ls):
            for tag, f0 in (("vert" if nn == 1 else "extr", fc), ("hort" if nn == 1 else "0", fs)):
                e = f0 * sigma * rng.normal()
                lrows.append({"n": int(nn), "tag": tag, "freq_hz": float(f0 + e)})
                tables.append(("freq", float(e)))
        loaded = ("loaded.modes.csv", lrows, {"state": "loaded", "load_n": load, "speed_kmh": 0,
                                               "pressure_bar": 2.2, "frame": "fixed"})
        test = [loaded]
    elif family == "sensor_mass":
        mass = float(rng.uniform(0.03, 0.12))
        magnitude["mass_kg"] = mass
        n_s = np.arange(1, int(rng.integers(6, 9)) + 1)
        fm = fd_modes(p, g, point_mass=mass, n_max=int(n_s[-1]))["cos"]  # the mode the sensor sees: antinode at it
        srows = []
        for nn, f0 in zip(n_s, fm):
            e = f0 * sigma * rng.normal()
            srows.append({"n": int(nn), "freq_hz": float(f0 + e)})
            tables.append(("freq", float(e)))
        test = [("sensor.modes.csv", srows, dict(FREE_CONDITION))]
        truth, expected = ("sensor_mass",), "sensor_mass"
    elif family == "none_modes":
        n_s = np.arange(1, int(rng.integers(6, 9)) + 1)
        fm = fd_free_frequencies(p, g, int(n_s[-1]))
        srows = []
        for nn, f0 in zip(n_s, fm):
            e = f0 * sigma * rng.normal()
            srows.append({"n": int(nn), "freq_hz": float(f0 + e)})
            tables.append(("freq", float(e)))
        test = [("repeat.modes.csv", srows, dict(FREE_CONDITION))]
    else:
        raise ValueError(family)
    rows = []
    for nn, f0 in zip(n_free, free):
        e = f0 * sigma * rng.normal()
        d = zeta0 * math.exp(rng.normal(0.0, 0.08))
        rows.append({"n": int(nn), "freq_hz": float(f0 + e), "damping_pct": 100.0 * d})
        row_noise += [("freq", float(e)), ("ln_damping", math.log(d / zeta0))]
    if family == "cavity_mode" or rng.random() < 0.5:
        rows.append({"kind": "acoustic", "freq_hz": f_cav})
    _write_tyre(folder)
    _write_table(folder, "free.modes.csv", rows, dict(FREE_CONDITION))
    for name, trows, cond in test:
        _write_table(folder, name, trows, cond)
    row_noise += tables
    return IndependentLabel(family=family, expected=expected, truth=truth, magnitude=magnitude,
                            noise={"relative": sigma, "rows": row_noise}, domain="modes",
                            expected_verdict=expected or "none")


# ============================================================================ profile families
PROFILE_SPEEDS = (20.0, 30.0, 40.0, 60.0)
#: FD points of the profile truths (their readings are then resampled band-limited to the file's angles)
FD_POINTS = 1024


def _profile_case(folder, seed, family):
    """A profile case (docs/formats.md §6): ``tyre.toml`` (Table 9), ``free.modes.csv`` (the FD ring's free modes,
    noisy, damping ζ0 0.015–0.035) and four profiles at ≈ 20/30/40/60 km/h, load 3.5–4.5 kN, flat road, the rim
    encoder's rotation_hz given (Ω from R_e = R_out − δ_z/3 of the FD standing solution, docs/physics.md §4.3). Each
    reading: the FD steady rolling ring (:func:`fd_static`: hysteretic loss η0 = 2ζ0 as a Hilbert matrix, the truth's
    ring ±6 %, k_trd ±15 % more) on 1024 points, the sensor chain of :func:`fd_reading`, resampled band-limited to
    360–1024 angles, white noise 0.2–1.5 m/s² at 40 km/h growing ∝ speed. Families:

    - ``none_profiles``: nothing more; expected `none`.
    - ``tread_shear``: the brush with the lever iterated to its fixed point (k_x 8–40 MN/m², μ 0.7–1.2).
    - ``wave_damping``: by seed mod 3, viscous material damping c = c_w = c_v 400–1200 N s/m² (docs/physics.md §4.2),
      a hysteretic loss growing linearly with the harmonic's frequency (η1 0.05–0.15 per 100 Hz, §6 wave_damping's
      first form, by FD derivative), or one growing with the square of the order, η0 + η2 (n/10)², η2 0.03–0.1
      (neither of ringfit's two forms).
    - ``gravity`` (gain 0.95–1.05 g), ``sensor_tilt`` (γ 0.5–1, e 1–6 mm), ``iepe_highpass`` (first order,
      0.8–3 Hz, filtered in time over repeated revolutions): docs/physics.md §5 layers 1–5, in :func:`fd_reading`.
    - ``rotation``: χ 0.1–0.6, the (1−χ)ρAΩ² term of §4.1 in the FD operator.
    """
    from ringfit.io.profiles import Profile, band_limited_resample, grid_angles_deg, resample_profile, write_profile

    rng = np.random.default_rng(seed)
    folder = _new(folder)
    geometry, p, g = _truth_ring(rng, tread_sd=0.15)
    g_R = g["R"]
    zeta0 = float(rng.uniform(0.015, 0.035))
    load = float(rng.uniform(3500.0, 4500.0))
    n_points = int(rng.choice([360, 512, 720, 1024]))
    n = FD_POINTS
    # noise at 40 km/h 0.2 … 1.5 m/s² (growing ∝ speed): above the FD truth's own discretisation error against the
    # continuum (≈ 0.04 m/s² RMS radial at 60 km/h on 1024 points), so that a null case is a null
    sigma40 = float(np.exp(rng.uniform(np.log(0.2), np.log(1.5))))
    speeds = [s + float(rng.uniform(-2.0, 2.0)) for s in PROFILE_SPEEDS]
    magnitude, kw_solve, kw_read = {}, {}, {}
    truth = (family,) if family != "none_profiles" else ()
    if family == "tread_shear":
        magnitude.update(k_x=float(rng.uniform(8e6, 40e6)), mu=float(rng.uniform(0.7, 1.2)))
        kw_solve["tread_shear"] = (magnitude["k_x"], magnitude["mu"])
    elif family == "wave_damping":
        form = seed % 3  # three forms of loss growing with the harmonic's order, in turn
        if form == 0:  # viscous material damping (docs/physics.md §4.2)
            magnitude["viscous_c"] = float(rng.uniform(400.0, 1200.0))
            kw_solve["viscous_c"] = magnitude["viscous_c"]
        elif form == 1:  # hysteretic loss growing linearly with the harmonic's frequency (§6 wave_damping)
            magnitude["eta_slope"] = float(rng.uniform(0.05, 0.15))
            kw_solve["eta_slope"] = magnitude["eta_slope"]
        else:  # hysteretic loss growing with the square of the order: η0 + η2 (n/10)²
            magnitude["eta_order2"] = float(rng.uniform(0.03, 0.1))
            kw_solve["eta_order2"] = magnitude["eta_order2"]
    elif family == "rotation":
        magnitude["chi"] = float(rng.uniform(0.1, 0.6))
        kw_solve["chi"] = magnitude["chi"]
    elif family == "gravity":
        magnitude["gravity_gain"] = float(rng.uniform(0.95, 1.05))
        kw_read["gravity"] = 9.81 * magnitude["gravity_gain"]
    elif family == "sensor_tilt":
        magnitude.update(tilt_gain=float(rng.uniform(0.5, 1.0)), offset_mm=float(rng.uniform(1.0, 6.0)))
        kw_read.update(tilt_gain=magnitude["tilt_gain"], offset=magnitude["offset_mm"] * 1e-3)
    elif family == "iepe_highpass":
        magnitude["corner_hz"] = float(rng.uniform(0.8, 3.0))
        kw_read["corner_hz"] = magnitude["corner_hz"]
    elif family != "none_profiles":
        raise ValueError(family)
    # free table: the FD ring's static frequencies, noisy, with damping ζ0
    n_free = np.arange(1, int(rng.integers(8, 11)) + 1)
    free = fd_free_frequencies(p, g, int(n_free[-1]))
    sig_f = float(rng.uniform(5e-4, 2e-3))
    rows = [{"n": int(k), "freq_hz": float(f * (1 + sig_f * rng.normal())),
             "damping_pct": float(100 * zeta0 * math.exp(rng.normal(0.0, 0.05)))} for k, f in zip(n_free, free)]
    _write_tyre(folder)
    _write_table(folder, "free.modes.csv", rows, dict(FREE_CONDITION))
    # rolling radius R_e = R_out − δ_z/3 (docs/physics.md §4.3) from the standing FD solution
    st = fd_static(p, g, load, n=n)
    r_e = g_R + g["tau"] - (g_R + g["tau"] - st["H"]) / 3.0
    by_run = []
    for i, speed in enumerate(speeds):
        omega = speed * KMH / r_e
        sol = fd_static(p, g, load, n=n, omega=omega, eta=2 * zeta0, **kw_solve)
        sol["R"] = g_R
        values = band_limited_resample(fd_reading(sol, omega, **kw_read), n_points)
        level = sigma40 * (speed / 40.0)
        noise = rng.normal(0.0, level, (2, n_points))
        noise -= noise.mean(-1, keepdims=True)
        angle = grid_angles_deg(n_points)
        cond = {"speed_kmh": round(speed, 3), "load_n": round(load, 1), "pressure_bar": 2.2,
                "revolutions": int(rng.integers(20, 60)), "sample_rate_hz": 25600.0,
                "rotation_hz": omega / (2 * np.pi)}
        data = values + noise
        write_profile(Profile(angle, data[0], data[1], condition=cond), folder / f"run{i + 1}.profile.csv")
        on_grid = resample_profile(Profile(angle, noise[0], noise[1]), 512)
        ms = np.mean((on_grid - on_grid.mean(-1, keepdims=True)) ** 2, -1)
        by_run.append(np.sqrt(ms).tolist())
    expected = family if family != "none_profiles" else None
    return IndependentLabel(family=family, expected=expected, truth=truth, magnitude=magnitude,
                            noise={"grid_rms_by_run_ms2": by_run, "sigma40_ms2": sigma40}, domain="profiles",
                            expected_verdict=expected or "none", extra={"load_n": load, "n_points": n_points})


# ============================================================================ rolling, loaded tables
ROLLING_SPEEDS = (20.0, 40.0, 60.0)
ROLLING_LOAD_N = 4000.0
#: The candidates bench_gap_rolling gives the diagnosis on its rolling cases (its default, not ``--all``).
ROLLING_CANDIDATES = "ground_contact,rotation"


def _rolling_case(folder, seed, family):
    """A rolling mode-table case (docs/formats.md §6), the independent counterpart of
    :func:`ringfit.synth.cases.make_rolling_case`: ``tyre.toml`` (Table 9), ``free.modes.csv`` (the FD ring's free
    modes, n = 1…8–10, relative noise σ 0.05–0.2 %, damping ζ0 with 8 % scatter) and ``roll20/40/60.modes.csv``
    (``state: rolling``, ``load_n`` 4000, ``speed_kmh``, ``frame: rotating``): what the co-rotating sensor sees of
    the rolling tyre's modes, **without n, tag or branch labels**, relative noise σ·U(1, 1.3), one or two lines
    missing per table, scattered damping.

    The modes are those of the independent Fourier collocation of eq. (3.1) in the fixed frame
    (:func:`_independent_rolling.collocation_modes`, the truth ring, χ = 1), each seen on the line |ω + k_dΩ| of
    its dominant radial-acceleration harmonic k_d, 1 ≤ |k_d| ≤ 6–8 (:func:`_independent_rolling.sensor_lines`).
    Ω = V/R_e, R_e = R_out − δ_z/3 of the FD ring's standing solution at 4 kN (docs/physics.md §4.3).

    - ``rolling_contact``: tread springs k_trd on the patch, its edges ±a from the FD ring's own steady rolling
      contact solve at that Ω (:func:`fd_static`, undamped: symmetric; 1024 points, a to half a cell). Truth and
      expected verdict ``ground_contact`` + ``rotation`` (bench_gap_rolling's contact case).
    - ``rolling_free``: no patch (the free spinning ring, whose collocation is eq. 26; Ω as above). Expected
      ``rotation`` (bench_gap_rolling's control).
    """
    from _independent_rolling import collocation_modes, sensor_lines

    rng = np.random.default_rng(seed)
    folder = _new(folder)
    geometry, p, g = _truth_ring(rng)
    contact = family == "rolling_contact"
    sigma = float(rng.uniform(0.0005, 0.002))
    sigma_roll = sigma * float(rng.uniform(1.0, 1.3))
    zeta0 = float(rng.uniform(0.015, 0.035))
    n_free = np.arange(1, int(rng.integers(8, 11)) + 1)
    free = fd_free_frequencies(p, g, int(n_free[-1]))
    rows, row_noise = [], []
    for nn, f0 in zip(n_free, free):
        e = f0 * sigma * rng.normal()
        d = zeta0 * math.exp(rng.normal(0.0, 0.08))
        rows.append({"n": int(nn), "freq_hz": float(f0 + e), "damping_pct": 100.0 * d})
        row_noise += [("freq", float(e)), ("ln_damping", math.log(d / zeta0))]
    _write_tyre(folder)
    _write_table(folder, "free.modes.csv", rows, dict(FREE_CONDITION))
    standing = fd_static(p, g, ROLLING_LOAD_N, n=1024)
    r_e = g["R"] + g["tau"] - (g["R"] + g["tau"] - standing["H"]) / 3.0
    n_top = int(rng.integers(6, 9))
    magnitude = {"load_n": ROLLING_LOAD_N, "contact": contact, "half_angle_deg": {}}
    # the truth in full (bulky: kept out of the magnitude the benchmark prints)
    truth_lines = {"ring": dict(p), "geometry": dict(g), "r_e_m": float(r_e), "true_hz": {}, "k": {}}
    for speed in ROLLING_SPEEDS:
        omega = speed * KMH / r_e
        a = fd_static(p, g, ROLLING_LOAD_N, n=1024, omega=omega)["a"] if contact else 0.0
        f, k, acc = collocation_modes(p, g, omega, -a, a, radial_floor=1e-2)
        line, kd, _ = sensor_lines(f, k, acc, omega, n_top)
        drop = set(rng.choice(line.size, size=int(rng.integers(1, 3)), replace=False).tolist())
        keep = [j for j in range(line.size) if j not in drop]
        trows = []
        for j in keep:
            e = float(line[j]) * sigma_roll * rng.normal()
            trows.append({"freq_hz": float(line[j] + e),
                          "damping_pct": float(100.0 * zeta0 * np.exp(rng.normal(0.3, 0.4)))})
            row_noise.append(("freq", e))
        name = f"roll{int(speed)}.modes.csv"
        magnitude["half_angle_deg"][name] = round(math.degrees(a), 3)
        truth_lines["true_hz"][name] = [float(line[j]) for j in keep]
        truth_lines["k"][name] = [int(kd[j]) for j in keep]
        _write_table(folder, name, trows, {"state": "rolling", "load_n": ROLLING_LOAD_N, "speed_kmh": speed,
                                           "pressure_bar": 2.2, "frame": "rotating"})
    expected = "ground_contact+rotation" if contact else "rotation"
    truth = ("ground_contact", "rotation") if contact else ("rotation",)
    return IndependentLabel(family=family, expected=expected, truth=truth, magnitude=magnitude,
                            noise={"relative": sigma, "relative_rolling": sigma_roll, "rows": row_noise},
                            domain="modes", expected_verdict=expected,
                            extra={"candidates": ROLLING_CANDIDATES, **truth_lines})


MODAL_FAMILIES = ("none_modes", "cavity_mode", "ground_contact", "sensor_mass")
PROFILE_FAMILIES = ("none_profiles", "tread_shear", "wave_damping", "gravity", "sensor_tilt", "iepe_highpass",
                    "rotation")
ROLLING_FAMILIES = ("rolling_contact", "rolling_free")
FAMILIES = MODAL_FAMILIES + PROFILE_FAMILIES + ROLLING_FAMILIES


def make(family: str, folder, seed: int) -> IndependentLabel:
    """Write the independent case of ``family`` (one of :data:`FAMILIES`) into ``folder`` (absent or empty)."""
    if family in MODAL_FAMILIES:
        return _modal_case(folder, seed, family)
    if family in PROFILE_FAMILIES:
        return _profile_case(folder, seed, family)
    if family in ROLLING_FAMILIES:
        return _rolling_case(folder, seed, family)
    raise ValueError(f"unknown family {family!r}; known: {', '.join(FAMILIES)}")
