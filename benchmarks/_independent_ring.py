"""An independent discretisation of the steady rolling ring's radial reading, for truths that do not share
ringfit's spectral contact solve (issue 22 item 5; used by bench_estimate, tests/test_estimate.py and
experiments/light_load_bias.py).

§4.1's steady equations (χ = 1, a membrane penalty EA for inextensibility, no damping) by central finite
differences in φ, §4.3's tread-spring law (radial springs, s = H/cos φ, flat road) with Fz imposed by a plain
active-set loop, §4.6's a_r (spectral derivatives of the FD solution). Nothing of ringfit's physics is used.
"""

from __future__ import annotations

import math

import numpy as np


def _stencils(n, h, order):
    """Periodic central finite-difference matrices d/dφ … d⁴/dφ⁴ (order 2 or 4)."""
    import scipy.sparse as sp

    def st(coeffs, scale):
        rows = np.concatenate([np.arange(n)] * len(coeffs))
        cols = np.concatenate([(np.arange(n) + k) % n for k in coeffs])
        vals = np.concatenate([np.full(n, c / scale) for c in coeffs.values()])
        return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))

    if order == 4:
        return (st({-2: 1, -1: -8, 1: 8, 2: -1}, 12 * h), st({-2: -1, -1: 16, 0: -30, 1: 16, 2: -1}, 12 * h**2),
                st({-3: 1, -2: -8, -1: 13, 1: -13, 2: 8, 3: -1}, 8 * h**3),
                st({-3: -1, -2: 12, -1: -39, 0: 56, 1: -39, 2: 12, 3: -1}, 6 * h**4))
    return (st({-1: -1, 1: 1}, 2 * h), st({-1: 1, 0: -2, 1: 1}, h**2), st({-2: -1, -1: 2, 1: -2, 2: 1}, 2 * h**3),
            st({-2: 1, -1: -4, 0: 6, 1: -4, 2: 1}, h**4))


def fd_profile(ring, geometry, load, n, *, order=4, omega=2 * math.pi * 9.0, ea=1e9, window_deg=35.0):
    """The radial reading of the steady rolling ring on a flat road, written independently of ringfit:
    §4.1's steady equations (χ = 1, a membrane penalty EA for inextensibility, no damping) by central
    finite differences in φ on n points, the §4.3 tread-spring law (radial springs, s = H/cos φ) with Fz
    imposed, a plain active-set loop, and §4.6's a_r = Ω²(w″ − 2v′ − w) (spectral derivatives of the FD
    solution). No gravity, no high-pass, sensor on the belt. ``ring``: ρA, EI, k_w, k_v, k_trd (its damping is
    not used); ``geometry``: R, b, p₀, τ. **Returns:** ``(φ, reading)`` on φ_j = −π + 2πj/n [rad, m/s²],
    the reading toward the centre positive, without its mean."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    R, b, p0, tau = float(geometry.radius), float(geometry.width), float(geometry.pressure), float(geometry.tread_thickness)
    rho_a, ei, kw, kv, ktrd = (float(getattr(ring, k)) for k in ("rho_a", "ei", "kw", "kv", "k_tread"))
    P = p0 * b / R
    h = 2 * np.pi / n
    phi = -np.pi + h * np.arange(n)
    d1, d2, d3, d4 = _stencils(n, h, order)
    eye = sp.identity(n)
    m = ea / R**2 - rho_a * omega**2
    b4 = ei / R**4
    L = sp.bmat([[b4 * d4 + m * eye - P * (d2 + eye) + kw * eye, -b4 * d3 + m * d1],
                 [b4 * d3 - m * d1, -b4 * d2 - m * d2 + kv * eye]]).tocsc()
    lu = spla.splu(L)
    win = np.flatnonzero(np.abs(phi) <= math.radians(window_deg))
    rhs = np.zeros((2 * n, win.size))
    rhs[win, np.arange(win.size)] = -1.0
    resp = lu.solve(rhs)
    A = resp[:n][win]
    phik = phi[win]
    active = np.abs(phik) < 0.1
    for _ in range(60):
        k_idx = np.flatnonzero(active)
        sysm = np.zeros((k_idx.size + 1, k_idx.size + 1))
        sysm[:-1, :-1] = np.eye(k_idx.size) - ktrd * A[np.ix_(k_idx, k_idx)]
        sysm[:-1, -1] = ktrd / np.cos(phik[k_idx])
        sysm[-1, :-1] = R * h * np.cos(phik[k_idx])
        x = np.linalg.solve(sysm, np.append(np.full(k_idx.size, ktrd * (R + tau)), load))
        p = np.zeros(win.size)
        p[k_idx] = x[:-1]
        new = (R + tau + A @ p - x[-1] / np.cos(phik)) > 0
        if np.array_equal(new, active):
            break
        active = new
    wv = resp @ p
    w, v = wv[:n], wv[n:]
    k = np.fft.rfftfreq(n, 1.0 / n)
    W, V = np.fft.rfft(w), np.fft.rfft(v)
    a_r = omega**2 * np.fft.irfft(-(k**2) * W - 2j * k * V - W, n)
    reading = -a_r  # toward the centre +, DC (−Ω²R) left out: the estimator fits k ≥ 2
    return phi, reading
