"""Mode shapes around the tyre: spatial harmonics, n, travelling waves, real shapes, ring-likeness.

A shape vector has one entry per channel; each channel has a sensor angle θ
[rad] (from the impact point) and an axis (``radial``, ``tangential``,
``lateral``). Per axis the shape is expanded in circumferential harmonics
``φ(θ) = Σ_{m=−M}^{M} c_m e^{imθ}`` by least squares (M ≤ (angles − 1)/2):

- the circumferential index n is the dominant harmonic of the power
  ``P_n = Σ_axes |c_n|² + |c_{−n}|²`` (summed over a pair's basis), with
  confidence ``P_n / Σ P`` (1 = a pure ring shape);
- the two counter-rotating waves of harmonic n are ``c_{+n} e^{inθ}`` and
  ``c_{−n} e^{−inθ}``; the travelling measure
  ``| |c_n|² − |c_{−n}|² | / (|c_n|² + |c_{−n}|²)`` is 0 for a standing wave
  and 1 for a wave running one way;
- real shapes: the source's rule ``v_r = sign(Im v)·|v|`` (seed §4.3) and a
  better one, :func:`real_shape_principal`, which turns the complex vector
  by the phase that makes it as real as possible (½ arg Σv²) before taking
  the real part (exact for any standing wave, whatever its phase);
- :func:`acoustic_candidates` flags modes that are not ring-like: a weak
  dominant harmonic, or an n out of the ring's monotone order (a ring's
  flexural frequencies rise with n for n ≥ 1, docs/physics.md §2.1; the cavity
  mode seen by a tread sensor shows an n = 1 pattern far above the ring's n = 1).
"""

from __future__ import annotations

import numpy as np

from ringfit.io.record_types import AXES as AXIS_ORDER


def max_harmonic(angle_rad: np.ndarray) -> int:
    """Largest harmonic M resolvable from the distinct sensor angles: (angles − 1) // 2."""
    k = np.unique(np.round(np.mod(angle_rad, 2 * np.pi), 9)).size
    return max(0, (k - 1) // 2)


def harmonic_coefficients(shape: np.ndarray, angle_rad: np.ndarray, axis: np.ndarray, n_max: int | None = None) -> dict[str, np.ndarray]:
    """Least-squares coefficients c_m, m = −M…M, of the shape on each axis.

    **Arguments:** ``shape`` (channels,) or (channels, d) complex; ``angle_rad``,
    ``axis`` (channels,).

    **Returns:** axis name -> array (2M+1,) or (2M+1, d), index ``m + M``.
    """
    shape = np.asarray(shape)
    axis = np.asarray(axis)
    out = {}
    for name in AXIS_ORDER:
        sel = axis == name
        if not sel.any():
            continue
        th = np.asarray(angle_rad)[sel]
        m_max = max_harmonic(th) if n_max is None else min(int(n_max), max_harmonic(th))
        m = np.arange(-m_max, m_max + 1)
        design = np.exp(1j * th[:, None] * m[None, :])
        out[name] = np.linalg.lstsq(design, shape[sel], rcond=None)[0]
    return out


def harmonic_power(shape: np.ndarray, angle_rad: np.ndarray, axis: np.ndarray, n_max: int | None = None) -> np.ndarray:
    """``P_n = Σ_axes Σ_cols |c_n|² + |c_{−n}|²``, n = 0…M (shape (M+1,)); each axis normalised to unit total power."""
    coeffs = harmonic_coefficients(shape, angle_rad, axis, n_max)
    m_max = min((c.shape[0] - 1) // 2 for c in coeffs.values())
    total = np.zeros(m_max + 1)
    for c in coeffs.values():
        mm = (c.shape[0] - 1) // 2
        p = np.abs(c.reshape(c.shape[0], -1)) ** 2
        p = p.sum(axis=1)
        pn = p[mm:mm + m_max + 1].copy()
        pn[1:] += p[mm - 1::-1][:m_max]
        s = pn.sum()
        total += pn / s if s > 0 else pn
    return total


def mode_number(basis: np.ndarray, angle_rad: np.ndarray, axis: np.ndarray, n_max: int | None = None) -> tuple[int, float]:
    """Circumferential index n from the dominant spatial harmonic, and its confidence in [0, 1].

    **Arguments:** ``basis`` (channels,) or (channels, d): a shape or a pair's basis.
    """
    p = harmonic_power(basis, angle_rad, axis, n_max)
    n = int(np.argmax(p))
    return n, float(p[n] / p.sum()) if p.sum() > 0 else 0.0


def travelling_measure(shape: np.ndarray, angle_rad: np.ndarray, axis: np.ndarray, n: int) -> float:
    """0 for a standing wave, 1 for a wave travelling one way (harmonic n, all axes pooled)."""
    if n == 0:
        return 0.0
    coeffs = harmonic_coefficients(shape, angle_rad, axis, n)
    a = sum(np.sum(np.abs(c[(c.shape[0] - 1) // 2 + n]) ** 2) for c in coeffs.values())
    b = sum(np.sum(np.abs(c[(c.shape[0] - 1) // 2 - n]) ** 2) for c in coeffs.values())
    return float(abs(a - b) / (a + b)) if a + b > 0 else 0.0


def real_shape_source(v: np.ndarray) -> np.ndarray:
    """The source's rule ``v_r = sign(Im v)·|v|`` (seed §4.3)."""
    v = np.asarray(v)
    return np.sign(v.imag) * np.abs(v)


def real_shape_principal(v: np.ndarray) -> np.ndarray:
    """``Re(v e^{−iφ₀})`` with ``φ₀ = ½ arg Σ v²``: the most real rotation of v (unit sign: largest entry > 0)."""
    v = np.asarray(v)
    phase = 0.5 * np.angle(np.sum(v**2))
    r = np.real(v * np.exp(-1j * phase))
    return r * np.sign(r[np.argmax(np.abs(r))])


def acoustic_candidates(n: np.ndarray, confidence: np.ndarray, freq_hz: np.ndarray, min_confidence: float = 0.5) -> np.ndarray:
    """Flag modes that are not ring-like (candidate acoustic cavity modes).

    A mode is flagged when its dominant harmonic is weak (``confidence <
    min_confidence``) or when its n breaks the ring's order: among the
    confident modes sorted by frequency, the longest subsequence with
    non-decreasing n (n ≥ 1) is the ring; the others are flagged. Of equally long subsequences the one with
    the larger summed confidence is the ring (a half of a double pole whose shape reads the next n, a little
    below its mode, would otherwise tie with the mode itself).

    **Returns:** bool array (modes,).
    """
    n = np.asarray(n)
    conf = np.asarray(confidence)
    flag = conf < min_confidence
    idx = np.flatnonzero(~flag & (n >= 1))
    idx = idx[np.argsort(np.asarray(freq_hz)[idx], kind="stable")]
    seq = n[idx]
    if seq.size:
        best = np.ones(seq.size, int)
        score = conf[idx].astype(np.float64)
        prev = np.full(seq.size, -1)
        for i in range(seq.size):
            for j in range(i):
                if seq[j] <= seq[i] and (best[j] + 1, score[j] + conf[idx[i]]) > (best[i], score[i]):
                    best[i], score[i], prev[i] = best[j] + 1, score[j] + conf[idx[i]], j
        keep = set()
        i = max(range(seq.size), key=lambda k: (best[k], score[k]))
        while i >= 0:
            keep.add(int(idx[i]))
            i = int(prev[i])
        for i in idx:
            if int(i) not in keep:
                flag[i] = True
    return flag
