"""Covariance-driven stochastic subspace identification, SSI-cov/ref (seed §2.4).

Axis order everywhere: ``y`` is ``(channels, samples)``.

The chain, each step one function:

1. :func:`output_covariances` — unbiased output covariances
   ``Λ_i = 1/(N−i) Σ_k y(k+i) y_ref(k)ᵀ`` (seed eq. 16 uses 1/(N−1); we divide
   each lag by the number of products it sums), all lags in ONE batched matmul.
2. :func:`block_hankel` — ``H[i, j] = Λ_{i+j+1}``, p block rows, q block
   columns (seed eq. 8), shape ``(p·l, q·r)``.
3. :func:`truncated_svd` — only the leading ``max(orders)`` singular triplets
   are needed: a randomized SVD with power iterations (default), ARPACK
   (``svds``) or the full LAPACK SVD (for checks).
4. :func:`poles_from_svd` — every model order from slices of that ONE SVD:
   observability ``O = U_n S_n^½`` (eq. 10), A by least squares on the shifted
   observability (eq. 11) through one QR of the largest ``O↑`` (the leading
   columns of a QR are the QR of the leading columns), C = first block row,
   poles λ_c = ln(λ)/Δt (eq. 13), f = |λ_c|/2π, ζ = −Re λ_c/|λ_c| (eq. 14),
   shapes φ = Cψ (eq. 15).

:func:`ssi_cov` runs 1–4 for one matrix of channels; :func:`ssi_cov_multi_setup`
merges several setups (records) that share reference channels.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.linalg

from ringfit.errors import InputError


@dataclass
class PoleSet:
    """All poles of an order sweep, one entry per pole (only Im λ > 0 kept).

    **Fields** (shape ``(poles,)`` unless stated):

    - ``order``: model order (state dimension) that produced the pole.
    - ``freq_hz``: undamped natural frequency |λ_c|/2π [Hz].
    - ``damping``: damping ratio −Re λ_c/|λ_c| [-] (not percent).
    - ``lam``: continuous-time pole λ_c [rad/s], complex.
    - ``shape``: mode shape φ = Cψ, complex, shape ``(poles, channels)``,
      scaled to unit norm.
    - ``orders``: the model orders of the sweep, shape ``(orders,)``.
    - ``singular_values``: leading singular values of the block Hankel matrix.
    """

    order: np.ndarray
    freq_hz: np.ndarray
    damping: np.ndarray
    lam: np.ndarray
    shape: np.ndarray
    orders: np.ndarray
    singular_values: np.ndarray

    def __len__(self) -> int:
        return self.order.shape[0]

    def at_order(self, order: int) -> np.ndarray:
        """Indices of the poles of one model order."""
        return np.flatnonzero(self.order == order)


def output_covariances(y: np.ndarray, max_lag: int, refs: np.ndarray | None = None) -> np.ndarray:
    """Unbiased output covariances Λ_0 … Λ_max_lag (seed eq. 6, 16).

    ``Λ_i = 1/(N−i) Σ_{k=0}^{N−i−1} y(k+i) y_ref(k)ᵀ`` for every lag in one
    batched matrix product over a zero-padded sliding-window view of ``y``
    (no copy of the lagged data).

    **Arguments:**

    - ``y``: outputs, shape ``(channels, samples)``.
    - ``max_lag``: largest lag i (< samples).
    - ``refs``: indices of the reference channels (default: all).

    **Returns:** shape ``(max_lag + 1, channels, refs)``.
    """
    y = np.asarray(y, dtype=np.float64)
    l, n = y.shape
    if not 0 <= max_lag < n - 1:
        raise InputError(f"max lag {max_lag} needs more than {max_lag + 1} samples; have {n}")
    yref = y if refs is None else y[np.asarray(refs)]
    padded = np.concatenate([y, np.zeros((l, max_lag + 1))], axis=1)
    lagged = np.lib.stride_tricks.sliding_window_view(padded, n, axis=1)[:, : max_lag + 1]  # (l, lags, n)
    cov = np.matmul(lagged.transpose(1, 0, 2), yref.T)  # (lags, l, r)
    cov /= (n - np.arange(max_lag + 1))[:, None, None]
    return cov


def block_hankel(cov: np.ndarray, block_rows: int, block_cols: int | None = None) -> np.ndarray:
    """Block Hankel matrix of covariances ``H[i, j] = Λ_{i+j+1}`` (seed eq. 8).

    **Arguments:** ``cov`` of shape ``(lags, l, r)`` with lags ≥ p + q;
    ``block_rows`` p; ``block_cols`` q (default p).

    **Returns:** shape ``(p·l, q·r)``.
    """
    p = int(block_rows)
    q = p if block_cols is None else int(block_cols)
    lags, l, r = cov.shape
    if lags < p + q:
        raise InputError(f"need covariances up to lag {p + q - 1}; have {lags - 1}")
    idx = np.arange(p)[:, None] + np.arange(q)[None, :] + 1  # (p, q) lag of each block
    return cov[idx].transpose(0, 2, 1, 3).reshape(p * l, q * r)


def truncated_svd(
    h: np.ndarray,
    rank: int,
    *,
    method: str = "randomized",
    n_iter: int = 2,
    oversample: int | None = None,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Leading ``rank`` left singular vectors and values of ``h``.

    **Arguments:**

    - ``method``: ``"randomized"`` (Halko–Martinsson–Tropp range finder with
      ``n_iter`` power iterations and QR re-orthonormalisation, then the exact
      SVD of the small projected matrix), ``"svds"`` (ARPACK via
      ``scipy.sparse.linalg.svds``) or ``"full"`` (LAPACK ``gesdd``).
    - ``oversample``: extra random vectors (default ``max(20, rank // 4)``).

    **Returns:** ``(u, s)`` with shapes ``(rows, rank)`` and ``(rank,)``, s descending.
    """
    m, n = h.shape
    rank = int(min(rank, m, n))
    if method == "full" or rank >= min(m, n) - 1:
        u, s, _ = scipy.linalg.svd(h, full_matrices=False, check_finite=False)
        return u[:, :rank], s[:rank]
    if method == "svds":
        from scipy.sparse.linalg import svds

        u, s, _ = svds(h, k=rank, random_state=seed)
        order = np.argsort(s)[::-1]
        return u[:, order], s[order]
    if method != "randomized":
        raise ValueError(f"unknown SVD method {method!r}; expected randomized, svds or full")
    k = min(rank + (max(20, rank // 4) if oversample is None else int(oversample)), min(m, n))
    rng = np.random.default_rng(seed)
    qmat = _orth(h @ rng.standard_normal((n, k)))
    for _ in range(int(n_iter)):
        qmat = _orth(h @ _orth(h.T @ qmat))
    ub, s, _ = scipy.linalg.svd(qmat.T @ h, full_matrices=False, check_finite=False)
    return (qmat @ ub[:, :rank]), s[:rank]


def _orth(a: np.ndarray) -> np.ndarray:
    return scipy.linalg.qr(a, mode="economic", check_finite=False)[0]


def small_matrix_threads():
    """Context manager: one BLAS thread for loops of small dense problems (eig of ≤ 200 × 200).

    Multi-threaded BLAS on matrices this small only adds synchronisation; on
    a loaded machine it made the order sweep 30× slower. Uses
    ``threadpoolctl`` when installed, else does nothing.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - optional
        import contextlib

        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def poles_from_svd(
    u: np.ndarray,
    s: np.ndarray,
    n_channels: int,
    orders: Sequence[int],
    dt: float,
    *,
    max_damping: float = 0.3,
    progress: bool = False,
) -> PoleSet:
    """Poles and shapes of every model order from one SVD (seed eq. 10–15).

    **Arguments:**

    - ``u``, ``s``: leading left singular vectors ``(p·l, k)`` and values ``(k,)``, k ≥ max(orders).
    - ``n_channels``: l, rows per block of the Hankel matrix.
    - ``orders``: model orders (state dimensions) to evaluate.
    - ``dt``: sample interval [s].
    - ``max_damping``: poles with ζ outside (0, max_damping) are dropped.
    - ``progress``: show a tqdm bar over the orders (stderr).

    **Returns:** :class:`PoleSet`.
    """
    orders = np.asarray(sorted(set(int(o) for o in orders)), dtype=np.int64)
    kmax = int(orders[-1])
    l = int(n_channels)
    if orders[0] < 1 or kmax > s.shape[0]:
        raise InputError(f"model orders must lie in 1..{s.shape[0]} (the rank of the block Hankel matrix; "
                         f"more block rows raise it); got {orders[0]}..{kmax}")
    if u.shape[0] - l < kmax:
        raise InputError(
            f"model order {kmax} needs at least {kmax // l + 2} block rows for {l} channels; "
            f"have {u.shape[0] // l}"
        )
    obs = u[:, :kmax] * np.sqrt(s[:kmax])
    q, r = scipy.linalg.qr(obs[:-l], mode="economic", check_finite=False)
    s_mat = q.T @ obs[l:]
    c_full = obs[:l]
    out = {k: [] for k in ("order", "freq_hz", "damping", "lam", "shape")}
    iterator = orders
    if progress:
        from tqdm import tqdm

        iterator = tqdm(orders, desc="SSI orders", unit="order", leave=False)
    with small_matrix_threads():
        _sweep(iterator, r, s_mat, c_full, dt, max_damping, out)
    if not out["order"]:
        empty = np.zeros(0)
        return PoleSet(empty.astype(np.int64), empty, empty, empty.astype(complex),
                       np.zeros((0, l), complex), orders, s)
    return PoleSet(
        order=np.concatenate(out["order"]),
        freq_hz=np.concatenate(out["freq_hz"]),
        damping=np.concatenate(out["damping"]),
        lam=np.concatenate(out["lam"]),
        shape=np.concatenate(out["shape"]),
        orders=orders,
        singular_values=s,
    )


def _sweep(orders, r, s_mat, c_full, dt, max_damping, out) -> None:
    """A_n = R_n⁻¹ S_n for each order, eigen-decomposition, poles and shapes appended to ``out``."""
    for n in orders:
        a = scipy.linalg.solve_triangular(r[:n, :n], s_mat[:n, :n], check_finite=False)
        mu, psi = np.linalg.eig(a)
        keep = mu.imag > 0
        if not keep.any():
            continue
        mu, psi = mu[keep], psi[:, keep]
        lam = np.log(mu) / dt
        wn = np.abs(lam)
        zeta = -lam.real / wn
        ok = (zeta > 0) & (zeta < max_damping)
        if not ok.any():
            continue
        phi = c_full[:, :n] @ psi[:, ok]
        phi /= np.linalg.norm(phi, axis=0, keepdims=True)
        m = int(ok.sum())
        out["order"].append(np.full(m, n))
        out["freq_hz"].append(wn[ok] / (2 * np.pi))
        out["damping"].append(zeta[ok])
        out["lam"].append(lam[ok])
        out["shape"].append(phi.T)


def default_block_rows(max_order: int, n_channels: int, n_refs: int) -> int:
    """Smallest p with p·l and (p−1)·l, q·r ≥ max_order + 1, at least 10 (p = q)."""
    need = max_order + 1
    p = max(10, -(-need // max(n_refs, 1)), -(-need // max(n_channels, 1)) + 1)
    return int(p)


def ssi_cov(
    y: np.ndarray,
    fs_hz: float,
    *,
    orders: Sequence[int] = range(2, 161, 2),
    block_rows: int | None = None,
    refs: np.ndarray | None = None,
    svd_method: str = "randomized",
    max_damping: float = 0.3,
    progress: bool = False,
) -> PoleSet:
    """Covariance-driven SSI (SSI-cov/ref) over a sweep of model orders (seed §2.4).

    **Arguments:**

    - ``y``: outputs, shape ``(channels, samples)`` [any unit].
    - ``fs_hz``: sample rate [Hz].
    - ``orders``: model orders (state dimensions), e.g. ``range(2, 161, 2)``.
    - ``block_rows``: p (= q block columns); default :func:`default_block_rows`.
    - ``refs``: reference channel indices (SSI-cov/ref); default all channels.
    - ``svd_method``: see :func:`truncated_svd`.

    **Returns:** :class:`PoleSet`.
    """
    y = np.asarray(y, dtype=np.float64)
    if y.ndim != 2:
        raise InputError(f"outputs have shape {y.shape}; expected (channels, samples)")
    if not np.isfinite(y).all():
        raise InputError("outputs contain NaN or inf")
    orders = list(orders)
    l = y.shape[0]
    r = l if refs is None else len(refs)
    p = default_block_rows(max(orders), l, r) if block_rows is None else int(block_rows)
    cov = output_covariances(y, 2 * p - 1, refs)
    h = block_hankel(cov, p)
    u, s = truncated_svd(h, max(orders), method=svd_method)
    return poles_from_svd(u, s, l, orders, 1.0 / fs_hz, max_damping=max_damping, progress=progress)


def multi_setup_hankel(
    setups: Sequence[np.ndarray], ref_index: Sequence[Sequence[int]], block_rows: int
) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """One block Hankel matrix from several setups sharing reference channels.

    Each setup ``j`` holds ``y_j`` of shape ``(channels_j, samples_j)``; its
    channels ``ref_index[j]`` are the same reference sensors, in the same order,
    in every setup. Covariances are taken against the references only (SSI-ref),
    so all setups share the right factor of ``H = O Γ``. Setup j is rescaled by
    the least-squares factor ``α_j`` that maps its reference block Hankel onto
    setup 0's (excitation level differs between setups: PreGER-style merging);
    the merged matrix has, per block row, the mean scaled reference rows
    followed by the moving channels of each setup.

    **Returns:** ``(H, channel_map)``: H of shape ``(p·l_total, p·r)``, and for
    each merged channel its ``(setup, channel)`` origin (references from setup 0).
    """
    p = int(block_rows)
    refs0 = list(ref_index[0])
    r = len(refs0)
    hs, ref_rows = [], []
    for j, (y, refs) in enumerate(zip(setups, ref_index)):
        refs = list(refs)
        if len(refs) != r:
            raise InputError(f"setup {j} has {len(refs)} reference channels; setup 0 has {r}")
        cov = output_covariances(np.asarray(y, dtype=np.float64), 2 * p - 1, refs)
        hs.append(cov)
    base = block_hankel(hs[0][:, refs0], p)
    blocks = []
    channel_map = [(0, c) for c in refs0]
    ref_sum = np.zeros_like(hs[0][:, refs0])
    for j, (cov, refs) in enumerate(zip(hs, ref_index)):
        href = block_hankel(cov[:, list(refs)], p)
        alpha = float(np.vdot(base, href) / np.vdot(href, href))
        cov = cov * alpha
        ref_sum += cov[:, list(refs)]
        moving = [c for c in range(cov.shape[1]) if c not in set(refs)]
        blocks.append(cov[:, moving])
        channel_map += [(j, c) for c in moving]
    merged = np.concatenate([ref_sum / len(hs)] + blocks, axis=1)  # (lags, l_total, r)
    return block_hankel(merged, p), channel_map


def ssi_cov_multi_setup(
    setups: Sequence[np.ndarray],
    ref_index: Sequence[Sequence[int]],
    fs_hz: float,
    *,
    orders: Sequence[int] = range(2, 161, 2),
    block_rows: int | None = None,
    svd_method: str = "randomized",
    max_damping: float = 0.3,
    progress: bool = False,
) -> tuple[PoleSet, list[tuple[int, int]]]:
    """SSI-cov/ref over several setups sharing references (see :func:`multi_setup_hankel`).

    **Returns:** ``(poles, channel_map)``; the shapes of ``poles`` follow ``channel_map``.
    """
    orders = list(orders)
    r = len(ref_index[0])
    l_total = r + sum(np.asarray(y).shape[0] - len(ri) for y, ri in zip(setups, ref_index))
    p = default_block_rows(max(orders), l_total, r) if block_rows is None else int(block_rows)
    h, channel_map = multi_setup_hankel(setups, ref_index, p)
    u, s = truncated_svd(h, max(orders), method=svd_method)
    poles = poles_from_svd(u, s, l_total, orders, 1.0 / fs_hz, max_damping=max_damping, progress=progress)
    return poles, channel_map
