"""Revolution harmonics of the radial reading, and their noise spectrum (docs/physics.md §10).

The load estimate fits harmonics k = 2 … k_max of the radial reading on a grid of angles
φ_j = −π + 2πj/M. This module converts between grid signals and complex amplitudes
(:func:`harmonic_amplitudes`, the profile block's one transform, :func:`band_signal`, :func:`grid_signal`), lays
amplitudes out as real residual rows (:func:`amplitude_rows`; the profile block's ``harmonic_rows`` are the same
rows scaled to σ per sample) and gives σ per harmonic of a residual (:func:`smoothed_noise`: the profile
block's noise spectrum, the one noise model of profiles). NumPy and JAX arrays alike.
"""

from __future__ import annotations

import numpy as np

from ringfit.fit.profile_block import NOISE_SMOOTHING, amplitude_rows, harmonic_amplitudes, noise_spectrum  # noqa: F401 (re-exported)


def band_signal(amplitudes, k_min: int, angle_rad) -> np.ndarray:
    """``Σ_k Re(a_k e^{ikα})`` at angles ``α`` [rad] ``(N,)`` of amplitudes ``(..., K)`` → ``(..., N)``."""
    k = np.arange(k_min, k_min + np.shape(amplitudes)[-1])
    return np.real(np.asarray(amplitudes) @ np.exp(1j * np.outer(k, angle_rad)))


def grid_signal(amplitudes, k_min: int, n_points: int) -> np.ndarray:
    """:func:`band_signal` on the grid α_j = −π + 2πj/n (one inverse FFT) → ``(..., n_points)``."""
    amplitudes = np.asarray(amplitudes)
    K = amplitudes.shape[-1]
    k = np.arange(k_min, k_min + K)
    spec = np.zeros(amplitudes.shape[:-1] + (n_points // 2 + 1,), dtype=complex)
    spec[..., k_min : k_min + K] = amplitudes * np.where(k % 2, -1.0, 1.0) * (n_points / 2.0)
    return np.fft.irfft(spec, n_points, axis=-1)


def smoothed_noise(rows: np.ndarray, half_width: int = NOISE_SMOOTHING) -> np.ndarray:
    """σ per row ``(..., 2K)`` from residual rows ``(..., 2K)`` of harmonics 2 … K + 1: the profile block's noise
    spectrum (:func:`ringfit.fit.profile_block.noise_spectrum`: a power law, then the ratio averaged over the
    ±half_width neighbouring harmonics, each harmonic's own left out), without its degrees-of-freedom inflation
    (:func:`ringfit.fit.profile_block.noise_from_residual` has it)."""
    K = rows.shape[-1] // 2
    power = 0.5 * (rows[..., :K] ** 2 + rows[..., K:] ** 2)
    noise, _ = noise_spectrum(power, k_min=2, half_width=half_width)
    sigma = np.sqrt(noise)
    sigma = np.maximum(sigma, 1e-6 * max(float(np.max(sigma)), 1e-300))
    return np.concatenate([sigma, sigma], axis=-1)
