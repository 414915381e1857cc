"""Noise level of averaged rolling profiles, estimated from the data itself (gap diagnosis, docs/formats.md §3).

A profile is deterministic physics plus noise (what is left of random
vibration after averaging revolutions, DAQ noise). Far from the contact patch
the belt's deformation — and whatever any effect does to it — is smooth, so
there the residual's content above a few revolution harmonics is noise.

Per profile and channel, with the baseline residual r(φ_j) on the model grid:

1. taper to the far side of the wheel, ``w(φ) = cos⁴φ`` for |φ| > 90° and 0
   inside (C³-smooth, so smooth residual content does not leak to high k);
2. periodogram ``s_k = |FFT(r·w)_k|² / Σw²`` (for white noise E s_k = σ²);
3. octave bands k ∈ [8, 16), [16, 32), … up to the measurement's band edge:
   robust level ``median(s_k)/ln 2`` per band (a periodogram ordinate is
   exponentially distributed);
4. a power law ``s(k) = a·k^b`` fitted to the band levels — one slope b for
   all profiles and channels (clipped to [−2, 0.5]: white, pink, red or mildly
   blue noise), a level a per profile and channel — extrapolated to the low
   harmonics 1…7 that the far-side window cannot separate from smooth model error;
5. ``σ² = (2/M) Σ_{k=1}^{k_max} s(k)`` — the noise variance per grid sample.

Coloured noise therefore counts in full, its low-harmonic part by
extrapolation (stated in the JSON ``noise_method``). The same power law gives
the effective degrees of freedom of a noise series, :func:`noise_dof`
(2·k_max for white noise, far fewer for red), used by the χ² test of
:mod:`ringfit.gap.verdict`. A user value (``noise=
{"profile_ms2": σ}``) replaces the estimate.
"""

from __future__ import annotations

import math

import numpy as np

#: Lowest revolution harmonic used for the noise spectrum.
LOWEST_HARMONIC = 8
#: Range of the fitted spectral slope.
SLOPE_RANGE = (-2.0, 0.5)


def far_side_window(phi: np.ndarray) -> np.ndarray:
    """``cos⁴φ`` for |φ| > 90°, else 0; ``phi`` [rad] shape ``(M,)``."""
    c = np.cos(phi)
    return np.where(c < 0.0, c**4, 0.0)


def band_levels(residual: np.ndarray, phi: np.ndarray, k_max: int) -> tuple[np.ndarray, np.ndarray]:
    """Robust far-side periodogram levels in octave bands: ``(centres, levels)`` (steps 1–3 above).

    ``residual`` shape ``(M,)`` [m/s²] on the grid ``phi`` [rad]; bands need ≥ 4 harmonics below ``k_max``.
    """
    w = far_side_window(phi)
    X = np.fft.rfft((residual - np.sum(residual * w) / np.sum(w)) * w)
    s = np.abs(X) ** 2 / np.sum(w**2)
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


def profile_noise(residual: np.ndarray, phi: np.ndarray, k_max) -> tuple[np.ndarray, float]:
    """Noise σ [m/s²] per profile and channel from the baseline residual.

    The spectral slope b is common to all profiles and channels (one sensor, one
    DAQ: one noise colour), fitted to the band levels with a free level per profile
    and channel — far steadier than one slope per spectrum; the levels are per
    profile and channel (noise grows with speed, channels differ).

    **Arguments:** ``residual`` ``(P, 2, M)``; ``phi`` ``(M,)`` [rad]; ``k_max`` ``(P,)`` highest
    revolution harmonic each measurement holds.

    **Returns:** ``(sigma (P, 2), slope b)``.
    """
    P, C, M = residual.shape
    bands = [[band_levels(residual[p, c], phi, int(k_max[p])) for c in range(C)] for p in range(P)]
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
    for p in range(P):
        k = np.arange(1, int(k_max[p]) + 1, dtype=np.float64)
        for c in range(C):
            centres, levels = bands[p][c]
            if centres.size == 0:
                continue
            a = float(np.mean(np.log(levels) - b * np.log(centres)))
            sigma[p, c] = math.sqrt(2.0 / M * float(np.sum(np.exp(a + b * np.log(k)))))
    return sigma, b


def noise_dof(slope: float, k_max: int) -> float:
    """Effective degrees of freedom ν = 2(Σs_k)²/Σs_k² of a periodic noise series with power ``s_k ∝ k^slope``.

    Harmonics k = 1 … ``k_max`` are independent, each a scaled χ²_2 (Satterthwaite): white noise gives
    ν = 2·k_max (the samples of a band-limited series), red noise (slope −1.5) about 11.
    """
    k = np.arange(1, int(k_max) + 1, dtype=np.float64)
    s = k**slope
    return float(2.0 * np.sum(s) ** 2 / np.sum(s**2))


__all__ = ["profile_noise", "noise_dof", "band_levels", "far_side_window", "LOWEST_HARMONIC"]
