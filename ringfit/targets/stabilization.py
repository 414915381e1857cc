"""Stabilization diagram with the source's criteria plus a pair-aware shape check (seed §2.5).

Each pole of model order ``o_j`` is compared with the pole of the previous
order ``o_{j−1}`` nearest in frequency:

- frequency stable: ``|f − f_prev| ≤ freq_tol · f_prev`` (source: 1 %);
- damping stable: ``|ζ − ζ_prev| ≤ damping_tol · ζ_prev`` (source: 5 %);
- shape stable (added here): the pole's shape lies in the shape subspace of
  its neighbours, MAC ≥ ``mac_tol``.

A free tyre has DOUBLE poles (cos nθ and sin nθ, or two counter-rotating
waves): from one order to the next the identified shape turns freely inside
the 2-D subspace of the pair, so the plain MAC with the previous pole drops
although the pole is physical. The pair-aware check therefore uses the
subspace MAC ``‖Bᴴφ‖²`` (φ of unit norm) against an orthonormal basis B of
at most two vectors: the leading left singular vectors of the shapes of all
poles within ``pair_window`` (relative frequency) at the previous
``history`` orders (singular values below ``0.2 × s_max`` are ignored).
The plain MAC is kept for comparison (``plain_mac``).

Symbols (source, seed §2.5 / figure 2): square = frequency and damping
stable, circle = frequency stable only; unstable poles are not drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ringfit.targets.ssi import PoleSet

#: Source criteria (seed §2.5).
FREQ_TOL = 0.01
DAMPING_TOL = 0.05
#: Working-memory cap of one batch of the pair-MAC computation [bytes].
_BATCH_BYTES = 2 * 2**20


@dataclass
class Stability:
    """Stability of every pole of a :class:`~ringfit.targets.ssi.PoleSet` (shape ``(poles,)``).

    - ``freq``, ``damping``, ``shape``: the three criteria (bool).
    - ``plain_mac``: MAC with the nearest pole of the previous order.
    - ``pair_mac``: subspace MAC against the pair (see module docstring);
      evaluated only where it can decide the label — frequency-stable poles
      whose plain MAC is below the threshold — NaN elsewhere.
    - ``label``: 2 = square (frequency, damping and shape stable), 1 =
      circle (frequency and shape stable, damping not), 0 = not stable.
    - ``source_label``: the same without the shape check (the source's symbols).
    """

    freq: np.ndarray
    damping: np.ndarray
    shape: np.ndarray
    plain_mac: np.ndarray
    pair_mac: np.ndarray
    label: np.ndarray
    source_label: np.ndarray


def mac(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Modal assurance criterion ``|aᴴb|² / (‖a‖²‖b‖²)`` over the last axis (broadcasts)."""
    num = np.abs(np.sum(np.conj(a) * b, axis=-1)) ** 2
    return num / (np.sum(np.abs(a) ** 2, axis=-1) * np.sum(np.abs(b) ** 2, axis=-1))


def pair_basis(shapes: np.ndarray, weights: np.ndarray | None = None, rel: float = 0.2, max_dim: int = 2) -> np.ndarray:
    """Orthonormal basis (channels, ≤ max_dim) of the subspace spanned by ``shapes`` (m, channels)."""
    x = np.asarray(shapes)
    if weights is not None:
        x = x * weights[:, None]
    u, s, _ = np.linalg.svd(x.T, full_matrices=False)
    keep = min(max_dim, int(np.sum(s >= rel * s[0]))) if s.size and s[0] > 0 else 0
    return u[:, :keep]


def subspace_mac(basis: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """``‖Bᴴφ‖² / ‖φ‖²`` for an orthonormal basis B (channels, d); φ (..., channels)."""
    proj = np.conj(basis.T) @ np.moveaxis(np.atleast_2d(phi), -1, 0)
    return np.sum(np.abs(proj) ** 2, axis=0) / np.sum(np.abs(np.atleast_2d(phi)) ** 2, axis=-1)


def stabilization_diagram(
    poles: PoleSet,
    *,
    freq_tol: float = FREQ_TOL,
    damping_tol: float = DAMPING_TOL,
    mac_tol: float = 0.9,
    pair_window: float = 0.02,
    history: int = 3,
    pair_aware: bool = True,
) -> Stability:
    """Label every pole as in the source's stabilization diagram, plus the shape check.

    **Arguments:** tolerances as in the module docstring; ``pair_aware=False``
    uses the plain MAC only (for comparison).

    The pair MAC is evaluated only where it can change the label: for
    frequency-stable poles (the others are unstable whatever their shape)
    whose plain MAC is below ``mac_tol`` (the others are shape stable
    already); ``pair_mac`` is NaN elsewhere. On free decays that is ~10 % of
    the frequency-stable poles. Batched eigen-decompositions over all orders
    (one per neighbour count).

    **Returns:** :class:`Stability`.
    """
    m = len(poles)
    f, z, phi = poles.freq_hz, poles.damping, poles.shape
    freq = np.zeros(m, bool)
    damp = np.zeros(m, bool)
    plain = np.zeros(m)
    pair = np.full(m, np.nan)
    by_order = [poles.at_order(o) for o in poles.orders]
    tasks = []  # (poles, their neighbours (c, k), valid (c, k)) per order
    for j in range(1, len(poles.orders)):
        cur, prev = by_order[j], by_order[j - 1]
        if cur.size == 0 or prev.size == 0:
            continue
        rel = np.abs(f[cur][:, None] - f[prev][None, :]) / f[prev][None, :]
        k = prev[np.argmin(rel, axis=1)]
        fs = rel.min(axis=1) <= freq_tol
        freq[cur] = fs
        damp[cur] = np.abs(z[cur] - z[k]) <= damping_tol * z[k]
        plain[cur] = mac(phi[cur], phi[k])
        need = fs & (plain[cur] < mac_tol)
        if pair_aware and need.any():
            hist = np.concatenate(by_order[max(0, j - history):j])
            tasks.append(_neighbours(cur[need], hist, f, pair_window))
    if tasks:
        pair_idx = np.concatenate([t[0] for t in tasks])
        pair[pair_idx] = _pair_mac(phi, tasks)
    shape_ok = (plain >= mac_tol) | (pair >= mac_tol) if pair_aware else plain >= mac_tol
    label = np.where(freq & damp & shape_ok, 2, np.where(freq & shape_ok, 1, 0))
    source = np.where(freq & damp, 2, np.where(freq, 1, 0))
    return Stability(freq, damp, shape_ok, plain, pair, label, source)


def _neighbours(cur, hist, f, window):
    """Poles of ``hist`` within ``window`` (relative frequency) of each pole of ``cur``: indices (c, k) and mask."""
    near = np.abs(f[cur][:, None] - f[hist][None, :]) <= window * f[cur][:, None]  # (c, h)
    k = max(1, int(near.sum(axis=1).max()))
    order = np.argsort(~near, axis=1, kind="stable")[:, :k]  # neighbours first
    return cur, hist[order], np.take_along_axis(near, order, axis=1)


def _pair_mac(phi, tasks) -> np.ndarray:
    """Pair MAC of the poles of all ``tasks``, one batched eigen-decomposition per neighbour count k."""
    cur = np.concatenate([t[0] for t in tasks])
    ks = np.concatenate([np.full(t[0].size, t[1].shape[1]) for t in tasks])
    out = np.zeros(cur.size)
    batch = max(16, _BATCH_BYTES // (16 * phi.shape[1] * max(int(ks.max()), 1)))  # bounded working memory
    for k in np.unique(ks):
        sel = [t for t in tasks if t[1].shape[1] == k]
        rows = np.flatnonzero(ks == k)
        c, nb, valid = (np.concatenate([t[i] for t in sel]) for i in range(3))
        for a in range(0, rows.size, batch):
            out[rows[a:a + batch]] = _pair_mac_batch(phi, c[a:a + batch], nb[a:a + batch], valid[a:a + batch])
    return out


def _pair_mac_batch(phi, cur, nb, valid, rel: float = 0.2, max_dim: int = 2) -> np.ndarray:
    """Subspace MAC of each pole ``cur`` against the ≤ 2-D principal subspace of its neighbours ``nb`` (c, k).

    Same as :func:`pair_basis` + :func:`subspace_mac` per pole, batched: the
    principal directions come from the eigen-decomposition of the neighbours'
    Gram matrix ``XᴴX`` (k × k, zero rows for padding), so the projection of
    φ is ``Σ_m |v_mᴴ Xᴴφ|² / λ_m`` over the leading eigenpairs with
    ``λ_m ≥ rel² λ_max``.
    """
    k = nb.shape[1]
    x = phi[nb] * valid[..., None]  # (c, k, ch)
    xh = np.conj(x)
    gram = np.matmul(xh, x.transpose(0, 2, 1))  # (c, k, k): x_kᴴ x_l
    lam, vec = np.linalg.eigh(gram)  # ascending
    proj = np.matmul(xh, phi[cur][:, :, None])  # Xᴴφ: (c, k, 1)
    coef = np.abs(np.matmul(np.conj(vec.transpose(0, 2, 1)), proj)[:, :, 0]) ** 2  # |v_mᴴ Xᴴφ|²
    use = (lam >= (rel**2) * lam[:, -1:]) & (lam > 0)
    use &= np.arange(k)[None, :] >= k - max_dim  # at most the max_dim leading ones
    with np.errstate(divide="ignore", invalid="ignore"):
        val = np.where(use, coef / np.where(lam > 0, lam, 1.0), 0.0).sum(axis=1)
    norm = np.sum(np.abs(phi[cur]) ** 2, axis=1)
    return np.where(valid.any(axis=1), val / norm, 0.0)
