"""An independent discretisation of the rolling, loaded ring's modes (docs/physics.md §3.7), shared by
tests/test_rolling_modes_loads.py (the check of :func:`ringfit.physics.rolling_modes.loaded_rolling_modes`) and
the ``rolling_contact`` / ``rolling_free`` families of :mod:`_independent_effects` (issue 30 item 4: power on
unlabelled rolling-loaded tables ringfit did not simulate).

Written from the PDEs alone, with numpy: eq. (3.1) in the space-fixed angle α = θ + Ωt
(∂/∂t|θ = ∂/∂t + Ω∂/∂α), inextensible ring (w = −v′, the tension eliminated by virtual work), discretised by
**Fourier collocation** on an odd grid (a dense differentiation matrix, not harmonics), the contact **sampled in
space** (k_trd times the share of each grid cell inside the patch [leading, trailing]), and the quadratic
eigenproblem solved by a companion linearisation with a general (non-Hermitian) eigensolver. The patch edges are
the caller's (the test takes ringfit's steady contact solve, §4; the benchmark family the FD ring's own contact
loop, :func:`_independent_effects.fd_static`). Nothing of ``ringfit.physics`` is used here.

Besides the frequencies, the eigenvectors give each mode's radial acceleration content per signed harmonic k
(what a co-rotating accelerometer's data carry): the sensor sees mode j on the line |ω_j + kΩ| of its dominant k
(:func:`sensor_lines`).
"""

from __future__ import annotations

import numpy as np

#: Collocation points (odd: the derivative is exact for orders ≤ 200); 401 puts the frequencies within 0.023 Hz
#: of the converged ones at 0.05–0.3 × rated load (edges inside a cell: ≤ 0.07 Hz at 201 points).
POINTS = 401


def collocation_d(points: int) -> np.ndarray:
    """First-derivative matrix of trigonometric interpolation on ``points`` (odd) equispaced nodes over 2π."""
    h = 2 * np.pi / points
    j = np.arange(points)
    diff = j[:, None] - j[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        D = 0.5 * (-1.0) ** diff / np.sin(diff * h / 2)
    D[diff == 0] = 0.0
    return D


def collocation_modes(p: dict, g: dict, omega: float, leading: float, trailing: float, *, chi: float = 1.0,
                      points: int = POINTS, radial_floor: float = 1e-6):
    """Fixed-frame modes of (3.1) with tread springs on [leading, trailing] [rad]: ``(freq_hz, k, acc_content)``.

    ``p``: ring parameters ``rho_a, ei, kw, kv, k_tread`` (SI); ``g``: ``R`` [m], ``b`` [m], ``p0`` [Pa] (the
    pressure term P = p0 b/R); ``omega`` [rad/s]; ``chi`` the belt's share of the centrifugal hoop tension.
    ``freq_hz`` ascending (the roots with positive imaginary part, one per mode); ``k`` the signed harmonic of
    each FFT bin; ``acc_content[j, :]`` is |−(ω_j + kΩ)² W_k|² per signed harmonic k (normalised per mode; NaN
    for a mode without radial content: ‖w‖ < ``radial_floor``·‖v‖ on the grid), W_k the Fourier coefficient of
    the radial displacement over α (α = 0 the patch centre, + in the direction of rotation). The belt's turn
    (n = 0, w ≡ 0 on the free ring) picks up ‖w‖/‖v‖ ~ 1e-4 of round-off when a flexural mode lies within a
    fraction of a hertz of it (the companion matrix's norm ~1e12 over the gap): a sensor-view caller sets the
    floor at 1e-2 (a radial content under 1 % of the tangential one is not a line the accelerometer reads).
    """
    D = collocation_d(points)
    h = 2 * np.pi / points
    alpha = (np.arange(points) - (points - 1) / 2) * h
    lo, hi = np.maximum(alpha - h / 2, leading), np.minimum(alpha + h / 2, trailing)
    kc = float(p["k_tread"]) * np.clip(hi - lo, 0.0, None) / h  # share of each cell inside the patch
    I = np.eye(points)
    R = float(g["R"])
    rho, b4, P = float(p["rho_a"]), float(p["ei"]) / R**4, float(g["p0"]) * float(g["b"]) / R
    kw, kv, O = float(p["kw"]), float(p["kv"]), float(omega)
    D2, D3, D4 = D @ D, D @ D @ D, D @ D @ D @ D
    W = -D  # w = W v (inextensible)
    # (R) and (T) of (3.1) in α: ∂t → ∂t + Ω∂α; coefficients of λ², λ, 1 acting on v
    R2, R1 = rho * W, rho * (2 * O * D @ W - 2 * O * I)
    R0 = (rho * (O**2 * D2 @ W - 2 * O**2 * D - O**2 * W) + b4 * (D4 @ W - D3) - P * (D2 @ W + W)
          - chi * rho * O**2 * (D2 @ W - D) + kw * W + np.diag(kc) @ W)
    T2, T1 = rho * I, rho * (2 * O * D + 2 * O * W)
    T0 = (rho * (O**2 * D2 + 2 * O**2 * D @ W - O**2 * I) + b4 * (D3 @ W - D2)
          + chi * rho * O**2 * (I - D @ W) + kv * I)
    # virtual work: δw (R) + δv (T) with δw = −D δv, D skew on the grid: (T) + D (R) = 0
    A2, A1, A0 = T2 + D @ R2, T1 + D @ R1, T0 + D @ R0
    Z = np.zeros_like(I)
    comp = np.block([[Z, I], [-np.linalg.solve(A2, A0), -np.linalg.solve(A2, A1)]])
    lam, vec = np.linalg.eig(comp)
    keep = lam.imag > 1e-6
    lam, vec = lam[keep], vec[:points, keep]
    order = np.argsort(lam.imag)
    w_ang, v = lam.imag[order], vec[:, order]
    w = W @ v  # radial displacement on the grid
    k = np.fft.fftfreq(points, 1.0 / points)  # signed harmonic of each FFT bin
    Wk = np.exp(-1j * k[:, None] * alpha[0]) * np.fft.fft(w, axis=0) / points  # coefficients of e^{ikα}
    acc = np.abs((w_ang[None, :] + k[:, None] * O) ** 2 * Wk) ** 2
    acc /= acc.sum(axis=0, keepdims=True)
    # no radial content (w = −v′ ≈ 0: the belt turning, n = 0): no harmonic to read
    acc[:, np.linalg.norm(w, axis=0) < radial_floor * np.linalg.norm(v, axis=0)] = np.nan
    return w_ang / (2 * np.pi), k.astype(int), acc.T


def sensor_lines(freq_hz: np.ndarray, k: np.ndarray, acc: np.ndarray, omega: float, n_max: int,
                 rtol: float = 1e-6):
    """What the co-rotating sensor sees of the modes of :func:`collocation_modes`: for every mode whose dominant
    radial-acceleration harmonic k_d has 1 ≤ |k_d| ≤ ``n_max``, the line |f + k_d Ω/2π| [Hz] (the material
    point at θ sees e^{i(ω + kΩ)t} of harmonic k). Modes without radial content (NaN content: the inextensible
    ring's n = 0, the belt turning) are left out.

    Modes degenerate in the fixed frame (within ``rtol``: the free spinning ring's n = 1 pair, eq. 26 puts its
    forward and backward waves both at ω_f) span pure harmonics the eigensolver returns mixed (±1 at 55/45 %):
    such a cluster of m modes is read as the m strongest harmonics of its summed content, each its own line
    (ω_f ± Ω: the split the sensor sees). **Returns:** ``(line_hz, k_d, share)`` sorted by line, share the
    dominant harmonic's fraction of one mode's content."""
    j = np.flatnonzero(np.all(np.isfinite(acc), axis=1))
    f, a = freq_hz[j], acc[j]
    lines, kds, shares = [], [], []
    i = 0
    while i < f.size:
        c = i + 1
        while c < f.size and abs(f[c] - f[i]) <= rtol * abs(f[i]):
            c += 1
        m = c - i
        tot = a[i:c].sum(axis=0)
        fc = float(np.mean(f[i:c]))
        for t in np.argsort(tot)[::-1][:m]:
            if 1 <= abs(int(k[t])) <= n_max:
                lines.append(abs(fc + int(k[t]) * omega / (2 * np.pi)))
                kds.append(int(k[t]))
                shares.append(float(tot[t]))
        i = c
    o = np.argsort(lines)
    return np.asarray(lines)[o], np.asarray(kds, int)[o], np.asarray(shares)[o]
