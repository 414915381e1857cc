"""Noise level of averaged rolling profiles, estimated from the data itself (gap diagnosis, docs/physics.md §6
*baselines*, ``gong-rolling``).

Far from the contact patch the belt's deformation, and whatever an effect does to it, is smooth, so there the
residual's content above a few revolution harmonics is noise. Per profile and channel: the far-side windowed
periodogram ``s_k`` (:func:`far_side_window`, :func:`periodogram`); σ² = (2/M)·(Σ_{k ≥ 8} s_k, the measured
part, plus a power law fitted to octave-band levels and extrapolated to k = 1…7, which the window cannot
separate from smooth model error); the effective degrees of freedom of the χ² test from the same spectrum.

Example (pure white noise of σ = 1 on four profiles, both channels)::

    phi = -np.pi + 2 * np.pi * np.arange(512) / 512
    sigma, slope, dof = profile_noise(np.random.default_rng(0).normal(size=(4, 2, 512)), phi, np.full(4, 255))
    # sigma ≈ 1 (4, 2); slope ≈ 0; dof ≈ 2·255 per series (white noise: the samples of a band-limited series)
"""

from __future__ import annotations

import math

import numpy as np

#: Lowest revolution harmonic used for the noise spectrum.
LOWEST_HARMONIC = 8
#: Range of the fitted spectral slope.
SLOPE_RANGE = (-2.0, 0.5)
#: Harmonics per band over which the periodogram is averaged for the degrees of freedom (narrow enough to follow a
#: resonance bump of a few harmonics).
DOF_BAND = 8


def far_side_window(phi: np.ndarray) -> np.ndarray:
    """``cos⁴φ`` for |φ| > 90°, else 0; ``phi`` [rad] shape ``(M,)``."""
    c = np.cos(phi)
    return np.where(c < 0.0, c**4, 0.0)


def periodogram(residual: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """Far-side windowed periodogram ``s_k = |FFT((r − r̄_w)·w)_k|² / Σw²`` ``(M//2 + 1,)`` of ``residual`` ``(M,)``
    [m/s²] on the grid ``phi`` [rad]: for white noise of variance σ², E s_k = σ² at every k."""
    w = far_side_window(phi)
    X = np.fft.rfft((residual - np.sum(residual * w) / np.sum(w)) * w)
    return np.abs(X) ** 2 / np.sum(w**2)


def band_levels(residual: np.ndarray, phi: np.ndarray, k_max: int, s: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """Robust far-side periodogram levels in octave bands ``[8, 16), [16, 32), …``: ``(centres, levels)``, each
    level ``median(s_k)/ln 2`` (a periodogram ordinate is exponentially distributed) — what the power law below
    harmonic 8 is fitted to.

    ``residual`` shape ``(M,)`` [m/s²] on the grid ``phi`` [rad]; bands need ≥ 4 harmonics below ``k_max``;
    ``s``: its :func:`periodogram`, where already computed.
    """
    s = periodogram(residual, phi) if s is None else s
    centres, levels = [], []
    lo = LOWEST_HARMONIC
    while lo + 3 <= k_max:
        hi = min(2 * lo, k_max + 1)
        centres.append(math.sqrt(lo * (hi - 1)))
        levels.append(max(float(np.median(s[lo:hi])) / math.log(2.0), 1e-300))
        lo = hi
    if not centres and k_max >= 2:  # too few harmonics: one band over the upper half
        lo = max(1, k_max // 2)
        centres.append(math.sqrt(lo * k_max))
        levels.append(max(float(np.median(s[lo : k_max + 1])) / math.log(2.0), 1e-300))
    return np.asarray(centres), np.asarray(levels)


def profile_noise(residual: np.ndarray, phi: np.ndarray, k_max, *, dof: bool = True
                  ) -> tuple[np.ndarray, float, np.ndarray | None]:
    """Noise σ [m/s²] and effective degrees of freedom per profile and channel from the baseline residual
    (docs/physics.md §6 *baselines*, ``gong-rolling``, *noise*).

    σ² = (2/M)·Σ_{k=1}^{k_max} S_k with S_k the far-side periodogram itself from harmonic
    :data:`LOWEST_HARMONIC` up (its sum is unbiased for any noise spectrum: a resonance bump counts in full,
    where a power law through band medians missed a third of it) and, below, a power law ``a·k^b`` fitted to
    the octave-band levels (:func:`band_levels`) — one slope b for all profiles and channels (one sensor, one
    DAQ; clipped to :data:`SLOPE_RANGE`), a level a per profile and channel — extrapolated to k = 1 … 7.
    ν = 2(ΣS_k)²/ΣS_k² (Satterthwaite, as :func:`spectrum_dof`), with S_k² ≥ 8 from the periodogram averaged
    over :data:`DOF_BAND`-harmonic bands, squared and freed of its estimation noise (:func:`_band_power2`).

    **Arguments:** ``residual`` ``(P, 2, M)``; ``phi`` ``(M,)`` [rad]; ``k_max`` ``(P,)`` highest
    revolution harmonic each measurement holds.

    **Returns:** ``(sigma (P, 2), slope b, dof (P, 2))``; ``dof=False`` (the parametric null's noise rule, which
    needs σ only): dof None, its spectrum squares not computed.
    """
    P, C, M = residual.shape
    spectra = [[periodogram(residual[p, c], phi) for c in range(C)] for p in range(P)]
    bands = [[band_levels(residual[p, c], phi, int(k_max[p]), spectra[p][c]) for c in range(C)] for p in range(P)]
    xs, ys = [], []
    for row in bands:
        for centres, levels in row:
            if centres.size >= 2:
                lx, ly = np.log(centres), np.log(levels)
                xs.append(lx - lx.mean())
                ys.append(ly - ly.mean())
    if xs:
        x, yv = np.concatenate(xs), np.concatenate(ys)
        b = float(np.clip(np.sum(x * yv) / max(np.sum(x * x), 1e-300), *SLOPE_RANGE))
    else:
        b = 0.0
    sigma = np.zeros((P, C))
    nu = np.ones((P, C)) if dof else None
    rho = ordinate_correlation(phi) if dof else None
    for p in range(P):
        K = int(k_max[p])
        k_lo = min(LOWEST_HARMONIC, K + 1)
        k = np.arange(1, k_lo, dtype=np.float64)
        for c in range(C):
            centres, levels = bands[p][c]
            if centres.size == 0:
                continue
            a = float(np.mean(np.log(levels) - b * np.log(centres)))
            low = np.exp(a + b * np.log(k))
            high = spectra[p][c][k_lo : K + 1]
            sigma[p, c] = math.sqrt(2.0 / M * (float(np.sum(low)) + float(np.sum(high))))
            if dof:
                nu[p, c] = spectrum_dof(np.concatenate([low, high]),
                                        np.concatenate([low**2, _band_power2(high, DOF_BAND, rho)]))
    return sigma, b, nu


def _band_power2(s: np.ndarray, width: int, rho: np.ndarray) -> np.ndarray:
    """Unbiased squares S_k² of the spectrum under the ordinates ``s`` ``(n,)``: each ordinate's band mean m
    (``width``-harmonic bands, a short last band joining the one before) squared and divided by 1 + 1/n_eff,
    where n_eff = n²/Σ_{i,j} ρ_{|i−j|} counts the band's independent ordinates (``rho``: correlation of two
    ordinates j apart, from the window). For white noise E m² = S²(1 + 1/n_eff)."""
    edges = list(range(0, s.size, width))
    if len(edges) > 1 and s.size - edges[-1] < width // 2:
        edges.pop()
    edges.append(s.size)
    lo, hi = np.asarray(edges[:-1]), np.asarray(edges[1:])
    n = hi - lo
    means = np.add.reduceat(s, lo) / n
    lags = np.arange(int(n.max()), dtype=np.int64)
    r = rho[np.minimum(lags, rho.size - 1)]
    # Σ_{i,j<n} ρ_|i−j| = n ρ_0 + 2 Σ_{j=1}^{n−1} (n − j) ρ_j
    pair = np.array([m * r[0] + 2.0 * float(np.sum((m - lags[1:m]) * r[1:m])) for m in n.tolist()])
    return np.repeat(means**2 / (1.0 + pair / (n * n)), n)


def ordinate_correlation(phi: np.ndarray) -> np.ndarray:
    """Correlation ρ_j of two far-side periodogram ordinates j harmonics apart under white noise,
    |Σw² e^{−ijφ}|² / (Σw²)² (``(M//2 + 1,)``)."""
    w2 = far_side_window(phi) ** 2
    return np.abs(np.fft.rfft(w2)) ** 2 / np.sum(w2) ** 2


def spectrum_dof(s: np.ndarray, s2: np.ndarray | None = None) -> float:
    """Effective degrees of freedom ν = 2(Σs_k)²/Σs_k² of a periodic noise series with power ``s_k`` per
    harmonic k = 1 … (each harmonic an independent scaled χ²_2; Satterthwaite). ``s2``: the squares s_k² where
    they are estimated apart from ``s`` (:func:`profile_noise`: freed of their estimation noise)."""
    s = np.asarray(s, dtype=np.float64)
    q = float(np.sum(s**2 if s2 is None else s2))
    return float(2.0 * np.sum(s) ** 2 / q) if q > 0.0 else 1.0


__all__ = ["profile_noise", "spectrum_dof", "periodogram", "band_levels", "far_side_window",
           "LOWEST_HARMONIC", "SLOPE_RANGE", "DOF_BAND"]
