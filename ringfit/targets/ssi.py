"""Covariance-driven stochastic subspace identification, SSI-cov/ref (seed §2.4; docs/physics.md §9).

Axis order everywhere: ``y`` is ``(channels, samples)``. The chain, each step one function:
:func:`output_covariances` (all lags at once; blocked FFT correlation for long records) →
:func:`block_hankel` (or :class:`BlockHankelOperator`, its products without forming it) →
:func:`truncated_svd` (only the leading ``max(orders)`` triplets) → :func:`poles_from_svd` (every model order
from slices of that one SVD and one QR). :func:`ssi_cov` runs them for one matrix of channels;
:func:`ssi_cov_multi_setup` merges several setups (records) that share reference channels. The equations and the
numerics (the FFT correlation's cost, why the leading block of one matrix gives every order) are in
docs/physics.md §9 (*SSI-cov*).

Example (three channels of a free decay holding 81 Hz at ζ = 2 % and 123 Hz at ζ = 1 %)::

    import numpy as np
    from ringfit.targets.ssi import ssi_cov
    fs = 1024.0
    t = np.arange(4096) / fs
    y = np.array([np.exp(-2 * np.pi * 0.02 * 81 * t) * np.sin(2 * np.pi * 81 * t + ph)
                  + 0.5 * np.exp(-2 * np.pi * 0.01 * 123 * t) * np.sin(2 * np.pi * 123 * t + 2 * ph)
                  for ph in (0.3, 1.4, 2.5)])
    poles = ssi_cov(y, fs, orders=range(2, 13, 2), unbiased=False)  # a free decay: 1/N covariances
    at8 = poles.order == 8
    poles.freq_hz[at8], poles.damping[at8]   # [81.016, 123.006] Hz, [0.020, 0.010]
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from typing import Literal, Sequence

import numpy as np
import scipy.linalg

from ringfit._threads import small_matrix_threads
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


#: Use blocked FFT correlation for the covariances when the record has at least this many lags' worth of samples.
FFT_COV_MIN_RATIO = 8
#: Use :class:`BlockHankelOperator` (FFT products) instead of a dense Hankel matrix from this many l·r on.
FFT_HANKEL_MIN_LR = 1024
#: Working-memory cap of the blocked FFT covariances [bytes] (blocks are processed in chunks below it).
_FFT_COV_CHUNK_BYTES = 4 * 2**20
#: Columns per chunk in :class:`BlockHankelOperator` products (measured best at 32 and 128 channels alike).
_HANKEL_CHUNK_COLS = 32


def output_covariances(y: np.ndarray, max_lag: int, refs: np.ndarray | None = None, *,
                       unbiased: bool = True) -> np.ndarray:
    """Output covariances Λ_0 … Λ_max_lag (seed eq. 6, 16).

    ``Λ_i = 1/(N−i) Σ_{k=0}^{N−i−1} y(k+i) y_ref(k)ᵀ`` for every lag at once
    (``unbiased=False``: ``1/N`` for every lag; see below).
    Long records (N ≥ 8 L, L = max_lag + 1 ≥ 16 lags): blocked FFT correlation
    (see :func:`_covariances_fft`); otherwise one batched matrix product over a
    zero-padded sliding-window view of ``y`` (no copy of the lagged data).

    **Arguments:**

    - ``y``: outputs, shape ``(channels, samples)``.
    - ``max_lag``: largest lag i (< samples).
    - ``refs``: indices of the reference channels (default: all).
    - ``unbiased``: divide lag i by its number of products N − i (stationary
      responses: ambient or white-noise excitation). ``False`` divides every
      lag by N: right for FREE DECAYS that have died out within the record
      (docs/physics.md §9): there ``Σ_k y(k+i) y(k)ᵀ = C Aⁱ G`` exactly, and
      the lag-dependent factor 1/(N − i) ≈ (1 + 1/N)ⁱ/N would shift every
      pole's decay rate by ≈ fs/N (on 0.5 s decays: −12 % on a 2.5 %
      damping at 107 Hz) while leaving the frequencies alone.

    **Returns:** shape ``(max_lag + 1, channels, refs)``.
    """
    y = np.asarray(y, dtype=np.float64)
    l, n = y.shape
    if not 0 <= max_lag < n - 1:
        raise InputError(f"max lag {max_lag} needs more than {max_lag + 1} samples; have {n}")
    lags = max_lag + 1
    if lags >= 16 and n >= FFT_COV_MIN_RATIO * lags:
        cov = _covariances_fft(y, refs, lags)
    else:
        yref = y if refs is None else y[np.asarray(refs)]
        padded = np.concatenate([y, np.zeros((l, lags))], axis=1)
        lagged = np.lib.stride_tricks.sliding_window_view(padded, n, axis=1)[:, :lags]  # (l, lags, n)
        cov = np.matmul(lagged.transpose(1, 0, 2), yref.T)  # (lags, l, r)
    cov /= (n - np.arange(lags))[:, None, None] if unbiased else n
    return cov


def _covariances_fft(y: np.ndarray, refs: np.ndarray | None, lags: int) -> np.ndarray:
    """Sums ``Σ_k y(k+i) y_ref(k)ᵀ`` for i < lags by overlap-save FFT correlation, shape ``(lags, l, r)``.

    The reference samples are cut into blocks of B; block b of the reference
    (zero-padded to M = B + L) against the M samples of ``y`` that start at
    the same time gives, by circular correlation of length M, exactly the
    lag 0 … L−1 products of that block (no wrap-around because the reference
    block is followed by L zeros). The per-frequency sums over blocks are one
    batched complex matmul ``Σ_b Y_b(f) R_b(f)ᴴ`` (l × r per frequency), and one
    inverse FFT of length M gives all lags. Blocks go in chunks of at most
    ``_FFT_COV_CHUNK_BYTES`` of spectra.
    """
    from scipy.fft import next_fast_len

    y = np.ascontiguousarray(y)
    l, n = y.shape
    m = next_fast_len(3 * lags, real=True)  # blocks of B = M − L ≈ 2L samples: ~4·(1 + L/B) flops per product
    b = m - lags
    nb = -(-n // b)
    full = min(nb, max(0, (n - m) // b + 1))  # blocks whose M samples lie inside the record: read in place
    tail = np.zeros((l, (nb - full) * b + lags))  # the last blocks, zero-padded (a short copy)
    tail[:, : n - full * b] = y[:, full * b:]
    ref_rows = slice(None) if refs is None else np.asarray(refs)
    r = y[ref_rows].shape[0]
    nf = m // 2 + 1
    acc = np.zeros((nf, l, r), dtype=np.complex128)
    chunk = max(32, int(_FFT_COV_CHUNK_BYTES // (2 * 16 * nf * (l + r))))  # >= 32 blocks: efficient GEMMs
    for src, count in ((y, full), (tail, nb - full)):
        ref_src = src if refs is None else np.ascontiguousarray(src[ref_rows])
        for start in range(0, count, chunk):
            cnt = min(count, start + chunk) - start
            seg = np.lib.stride_tricks.as_strided(
                src[:, start * b:], shape=(cnt, l, m), strides=(b * 8, src.strides[0], 8), writeable=False)
            ref = np.lib.stride_tricks.as_strided(
                ref_src[:, start * b:], shape=(cnt, r, b), strides=(b * 8, ref_src.strides[0], 8), writeable=False)
            fy = np.ascontiguousarray(np.fft.rfft(seg, axis=-1).transpose(2, 1, 0))  # (F, l, blocks)
            fr = np.ascontiguousarray(np.fft.rfft(ref, n=m, axis=-1).transpose(2, 0, 1))  # (F, blocks, r)
            np.conjugate(fr, out=fr)
            acc += np.matmul(fy, fr)
    out = np.empty((lags, l, r))
    rows = max(1, int(_FFT_COV_CHUNK_BYTES // (8 * m * r)))
    for i in range(0, l, rows):  # inverse FFT in slabs of channels: only the first L of M lags are kept
        out[:, i:i + rows] = np.fft.irfft(acc[:, i:i + rows], n=m, axis=0)[:lags]
    return out


def block_hankel(cov: np.ndarray, block_rows: int, block_cols: int | None = None) -> np.ndarray:
    """Block Hankel matrix of covariances ``H[i, j] = Λ_{i+j+1}`` (seed eq. 8).

    **Arguments:** ``cov`` of shape ``(lags, l, r)`` with lags ≥ p + q;
    ``block_rows`` p; ``block_cols`` q (default p).

    **Returns:** shape ``(p·l, q·r)`` (one copy from a strided view of ``cov``).
    """
    p = int(block_rows)
    q = p if block_cols is None else int(block_cols)
    lags, l, r = cov.shape
    if lags < p + q:
        raise InputError(f"need covariances up to lag {p + q - 1}; have {lags - 1}")
    cov = np.ascontiguousarray(cov)
    s0, s1, s2 = cov.strides
    view = np.lib.stride_tricks.as_strided(cov[1:], shape=(p, l, q, r), strides=(s0, s1, s0, s2), writeable=False)
    return view.reshape(p * l, q * r)


class BlockHankelOperator:
    """The block Hankel matrix ``H[i, j] = Λ_{i+j+1}`` (p·l × q·r) as an operator: ``H @ X`` and ``H.T @ Z``.

    ``(H X)_i = Σ_j Λ_{i+j+1} X_j`` is a block correlation over the lag axis:
    with the lag FFT ``Λ̂(f)`` (length M ≥ p + q − 1, computed once) it costs
    one batched complex matmul ``Λ̂(f) X̂(f)`` over M/2 + 1 frequencies, about
    8·(M/2)·l·r·k flops for k columns instead of 2·p·q·l·r·k, and H (p·q·l·r
    numbers) is never formed. Exact up to FFT round-off (~1e-15 relative).

    **Arguments:** ``cov`` of shape ``(lags, l, r)`` with lags ≥ p + q; p, q as
    in :func:`block_hankel`.
    """

    def __init__(self, cov: np.ndarray, block_rows: int, block_cols: int | None = None, *, _spec=None):
        from scipy.fft import next_fast_len

        self.p = int(block_rows)
        self.q = self.p if block_cols is None else int(block_cols)
        lags, self.l, self.r = cov.shape
        if lags < self.p + self.q:
            raise InputError(f"need covariances up to lag {self.p + self.q - 1}; have {lags - 1}")
        self._cov = cov
        self._m = next_fast_len(self.p + self.q - 1, real=True)
        self._spec = np.fft.rfft(cov[1:self.p + self.q], n=self._m, axis=0) if _spec is None else _spec  # (F, l, r)
        self.shape = (self.p * self.l, self.q * self.r)

    @property
    def T(self) -> "BlockHankelOperator":
        """Hᵀ: again a block Hankel matrix, of the transposed covariances."""
        cov_t = self._cov.transpose(0, 2, 1)
        return BlockHankelOperator(cov_t, self.q, self.p, _spec=self._spec.transpose(0, 2, 1))

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        """``H @ x`` for x of shape ``(q·r, k)``; returns ``(p·l, k)``.

        Columns go in chunks of ``_HANKEL_CHUNK_COLS``: cache-sized
        temporaries; one BLAS thread, 200 columns, p = 30: 4.3 ms instead of
        7.5 ms at 32 channels, 28 ms instead of 36 ms (16-column chunks) at 128.
        """
        x = np.asarray(x, dtype=np.float64)
        k = x.shape[1]
        out = np.empty((self.p * self.l, k))
        step = _HANKEL_CHUNK_COLS
        for a in range(0, k, step):
            b = min(k, a + step)
            xf = np.fft.rfft(x[:, a:b].reshape(self.q, self.r, b - a)[::-1], n=self._m, axis=0)  # reversed: convolution
            conv = np.fft.irfft(np.matmul(self._spec, xf), n=self._m, axis=0)[self.q - 1:self.q - 1 + self.p]
            out[:, a:b] = conv.reshape(self.p * self.l, b - a)
        return out

    def toarray(self) -> np.ndarray:
        """The dense matrix (:func:`block_hankel`)."""
        return block_hankel(self._cov, self.p, self.q)


#: How :func:`truncated_svd` factors the block Hankel matrix.
SvdMethod = Literal["randomized", "svds", "full"]


def truncated_svd(
    h,
    rank: int,
    *,
    method: SvdMethod = "randomized",
    n_iter: int = 2,
    oversample: int | None = None,
    seed: int = 0,
    workers: int = 1,
    return_v: bool = False,
):
    """Leading ``rank`` left singular vectors and values of ``h`` (and the right vectors on request).

    **Arguments:**

    - ``h``: a matrix, or an operator with ``shape``, ``h @ X``, ``h.T @ Z``
      and ``toarray()`` (:class:`BlockHankelOperator`).
    - ``method``: ``"randomized"`` (Halko–Martinsson–Tropp range finder with
      ``n_iter`` power iterations and QR re-orthonormalisation, then the exact
      SVD of the small projected matrix), ``"svds"`` (ARPACK via
      ``scipy.sparse.linalg.svds``) or ``"full"`` (LAPACK ``gesdd``).
    - ``oversample``: extra random vectors (default ``max(20, rank // 4)``).
    - ``workers``: threads for the randomized method's products ``H X``,
      ``Hᵀ Z`` (column blocks, one BLAS thread each); 1 = BLAS's own threading.
    - ``return_v``: also return ``V = Hᵀ U S⁻¹`` (the right factor of the
      rank-``rank`` projection ``U Uᵀ H = U S Vᵀ``; the randomized method gets
      it from the ``Hᵀ Q`` it forms anyway, at n·k·rank more flops).

    Accuracy: singular triplets above the noise floor of H come out to
    round-off (~1e-13 relative on the benchmark data); those inside a flat
    noise floor (σ_k/σ_{k+1} ≈ 1) are not resolved individually by any
    iterative method — the rank-``rank`` approximation error stays ≈ σ_{rank+1}.

    **Returns:** ``(u, s)`` with shapes ``(rows, rank)`` and ``(rank,)``, s descending;
    ``(u, s, v)`` with v of shape ``(columns, rank)`` when ``return_v``.
    """
    m, n = h.shape
    rank = int(min(rank, m, n))
    if method == "full" or rank >= min(m, n) - 1:
        dense = h.toarray() if hasattr(h, "toarray") else h
        u, s, vt = scipy.linalg.svd(dense, full_matrices=False, check_finite=False)
        return (u[:, :rank], s[:rank]) + ((vt[:rank].T,) if return_v else ())
    if method == "svds":
        from scipy.sparse.linalg import svds

        dense = h.toarray() if hasattr(h, "toarray") else h
        u, s, vt = svds(dense, k=rank, random_state=seed)
        order = np.argsort(s)[::-1]
        return (u[:, order], s[order]) + ((vt[order].T,) if return_v else ())
    if method != "randomized":
        raise ValueError(f"unknown SVD method {method!r}; expected randomized, svds or full")
    k = min(rank + (max(20, rank // 4) if oversample is None else int(oversample)), min(m, n))
    rng = np.random.default_rng(seed)
    with _column_blocks(max(1, int(workers))) as apply:
        basis = apply(h, rng.standard_normal((n, k)))
        for _ in range(int(n_iter)):  # power iterations, LU-normalised (same subspace as QR, ~4x cheaper)
            basis = apply(h, _lu_normalise(apply(h.T, _lu_normalise(basis))))
        qmat = scipy.linalg.qr(basis, mode="economic", check_finite=False, overwrite_a=True)[0]
        # SVD of the k × n projection B = QᵀH through the R factor of Bᵀ = Q₂R (B = RᵀQ₂ᵀ: same U and s, and
        # the k × k SVD of Rᵀ is half the work of gesdd on B, which would also form the unused right vectors)
        z = apply(h.T, qmat)  # HᵀQ (n × k)
        r_b = scipy.linalg.qr(z, mode="r", check_finite=False, overwrite_a=not return_v)[0][:k]
    ub, s, _ = scipy.linalg.svd(r_b.T, check_finite=False, overwrite_a=True)
    u = qmat @ ub[:, :rank]
    if return_v:  # HᵀU S⁻¹ = (HᵀQ) U_b S⁻¹
        return u, s[:rank], (z @ ub[:, :rank]) / np.where(s[:rank] > 0, s[:rank], 1.0)
    return u, s[:rank]


@contextlib.contextmanager
def _column_blocks(workers: int):
    """Context giving ``apply(op, x) = op @ x``, computed in ``workers`` threads over column blocks of x.

    With more than one worker BLAS runs one thread per worker (:func:`_own_threads`);
    with one it is the plain product and BLAS keeps its own threading.
    """
    if workers <= 1:
        yield lambda op, x: op @ x
        return
    from concurrent.futures import ThreadPoolExecutor

    with _own_threads(workers), ThreadPoolExecutor(max_workers=workers) as pool:
        def apply(op, x):
            if x.shape[1] < 32 * workers:
                return op @ x
            edges = np.linspace(0, x.shape[1], workers + 1).astype(int)
            parts = pool.map(lambda i: op @ x[:, edges[i]:edges[i + 1]], range(workers))
            return np.concatenate(list(parts), axis=1)

        yield apply


def _lu_normalise(a: np.ndarray) -> np.ndarray:
    """A well-conditioned basis of the column space of ``a`` (rows, k): the permuted unit-lower L of ``a = P L U``."""
    return scipy.linalg.lu(a, permute_l=True, check_finite=False, overwrite_a=True)[0]


def poles_from_svd(
    u: np.ndarray,
    s: np.ndarray,
    n_channels: int,
    orders: Sequence[int],
    dt: float,
    *,
    max_damping: float = 0.3,
    progress: bool = False,
    workers: int | None = None,
) -> PoleSet:
    """Poles and shapes of every model order from one SVD (seed eq. 10–15).

    One QR ``O↑ = Q R`` of the largest shifted observability matrix and one
    triangular solve give ``G = QᵀO↓R⁻¹`` and ``C R⁻¹``; order n is the
    eigen-decomposition of the leading block ``G_n`` (similar to
    ``A_n = R_n⁻¹(QᵀO↓)_n``, see the module docstring): per order one
    Hessenberg–Schur reduction with the rotations applied to the l rows of
    ``C R⁻¹`` instead of an n × n basis, and eigenvectors of the kept poles
    only (:func:`ringfit.targets.eigen.eig_shapes`; same poles and shapes as
    ``dgeev``), the orders spread over ``workers`` threads.

    **Arguments:**

    - ``u``, ``s``: leading left singular vectors ``(p·l, k)`` and values ``(k,)``, k ≥ max(orders).
    - ``n_channels``: l, rows per block of the Hankel matrix.
    - ``orders``: model orders (state dimensions) to evaluate.
    - ``dt``: sample interval [s].
    - ``max_damping``: poles with ζ outside (0, max_damping) are dropped.
    - ``progress``: show a tqdm bar over the orders (stderr).
    - ``workers``: threads for the order sweep (default :func:`default_workers`;
      1 = serial). Results do not depend on it.

    **Returns:** :class:`PoleSet`.
    """
    orders = np.asarray(sorted(set(int(o) for o in orders)), dtype=np.int64)
    kmax = int(orders[-1])
    l = int(n_channels)
    if orders[0] < 1 or kmax > s.shape[0]:
        raise InputError(f"--orders: model orders must lie in 1..{s.shape[0]} (the rank of the block Hankel matrix; "
                         f"more --block-rows raise it); got {orders[0]}..{kmax}")
    if u.shape[0] - l < kmax:
        raise InputError(
            f"model order {kmax} needs at least {kmax // l + 2} block rows for {l} channels; "
            f"have {u.shape[0] // l}"
        )
    obs = u[:, :kmax] * np.sqrt(s[:kmax])
    q, r = scipy.linalg.qr(obs[:-l], mode="economic", check_finite=False)
    # G = (QᵀO↓) R⁻¹ and C R⁻¹ in one triangular solve: Xᵀ = R⁻ᵀ [QᵀO↓; C]ᵀ
    rhs = np.concatenate([q.T @ obs[l:], obs[:l]], axis=0)
    sol = scipy.linalg.solve_triangular(r, rhs.T, trans="T", check_finite=False).T
    g, c_r = np.asfortranarray(sol[:kmax]), np.asfortranarray(sol[kmax:])
    workers = _workers(workers)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=orders.size, desc="SSI orders", unit="order", leave=False)
    try:
        with small_matrix_threads():
            out = _sweep([int(o) for o in orders], g, c_r, dt, max_damping, workers, bar)
    finally:
        if bar is not None:
            bar.close()
    if not out:
        empty = np.zeros(0)
        return PoleSet(empty.astype(np.int64), empty, empty, empty.astype(complex),
                       np.zeros((0, l), complex), orders, s)
    order, lam, shape = (np.concatenate(v) for v in zip(*out))
    wn = np.abs(lam)
    return PoleSet(
        order=order,
        freq_hz=wn / (2 * np.pi),
        damping=-lam.real / wn,
        lam=lam,
        shape=shape,
        orders=orders,
        singular_values=s,
    )


def _sweep(orders, g, c_r, dt, max_damping, workers: int, bar=None) -> list:
    """Eigenvalues of each leading block ``G_n`` and shapes of its kept poles; ``(order, λ_c, φ)`` per order.

    Orders run in ``workers`` threads (largest first, for balance): the LAPACK
    calls of :func:`ringfit.targets.eigen.eig_shapes` release the GIL.
    """
    def one(n):
        try:
            lam, phi = discrete_poles(g[:n, :n], c_r[:, :n], dt, max_damping)
        except np.linalg.LinAlgError as exc:
            raise InputError(f"eigen-decomposition of model order {n} did not converge ({exc})") from None
        if lam.size == 0:
            return None
        return np.full(lam.size, n), lam, phi

    results = {}
    if workers <= 1:
        for n in orders:
            results[n] = one(n)
            if bar is not None:
                bar.update()
    else:
        from concurrent.futures import ThreadPoolExecutor, as_completed

        with ThreadPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(one, n): n for n in sorted(orders, reverse=True)}
            for fut in as_completed(futures):
                results[futures[fut]] = fut.result()
                if bar is not None:
                    bar.update()
    return [results[n] for n in orders if results[n] is not None]


def discrete_poles(a: np.ndarray, c: np.ndarray, dt: float, max_damping: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """Continuous poles and unit-norm shapes of one state matrix (seed eq. 13–15).

    **Arguments:** ``a`` ``(n, n)`` (A or any matrix similar to it), ``c``
    ``(l, n)`` the output matrix in the same basis, ``dt`` [s]; poles with ζ
    outside (0, ``max_damping``) and the lower member of each complex pair are
    dropped.

    **Returns:** ``(lam, phi)``: λ_c = ln(μ)/Δt [rad/s] ``(poles,)`` and φ = Cψ
    ``(poles, l)``, complex. **Raises** ``np.linalg.LinAlgError`` when the
    eigen-decomposition does not converge.
    """
    from ringfit.targets.eigen import eig_shapes

    def continuous(wr, wi):  # λ_c = ln(μ)/Δt (eq. 13)
        return np.log(wr + 1j * wi) / dt

    def keep(wr, wi):
        up = np.flatnonzero(wi > 0)  # first of each complex pair
        lam = continuous(wr[up], wi[up])
        zeta = -lam.real / np.abs(lam)
        return up[(zeta > 0) & (zeta < max_damping)]

    wr, wi, j, phi = eig_shapes(a, c, keep)
    if j.size == 0:
        return np.zeros(0, complex), np.zeros((0, c.shape[0]), complex)
    phi = phi / np.linalg.norm(phi, axis=0, keepdims=True)
    return continuous(wr[j], wi[j]), phi.T


def default_workers() -> int:
    """Default ``workers`` of :func:`ssi_cov`: the CPUs this process may use (affinity mask), at most 8."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not on Linux
        cpus = os.cpu_count() or 1
    return max(1, min(8, cpus))


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
    svd_method: SvdMethod = "randomized",
    max_damping: float = 0.3,
    unbiased: bool = True,
    progress: bool = False,
    workers: int | None = None,
) -> PoleSet:
    """Covariance-driven SSI (SSI-cov/ref) over a sweep of model orders (seed §2.4).

    **Arguments:**

    - ``y``: outputs, shape ``(channels, samples)`` [any unit].
    - ``fs_hz``: sample rate [Hz].
    - ``orders``: model orders (state dimensions), e.g. ``range(2, 161, 2)``.
    - ``block_rows``: p (= q block columns); default :func:`default_block_rows`.
    - ``refs``: reference channel indices (SSI-cov/ref); default all channels.
    - ``svd_method``: see :func:`truncated_svd`.
    - ``unbiased``: covariance normalisation (:func:`output_covariances`);
      ``False`` for free decays.
    - ``workers``: threads for the SVD's products and the order sweep
      (default :func:`default_workers`; 1 = serial). Results do not depend on it
      beyond round-off in the SVD.

    **Returns:** :class:`PoleSet`.
    """
    return _ssi_cov(y, fs_hz, orders, block_rows, refs, svd_method, max_damping, unbiased, progress, workers,
                    factors=False)[0]


@dataclass
class HankelFactors:
    """The rank-k factorisation ``H ≈ U S Vᵀ`` of the block Hankel matrix of one SSI run (:func:`ssi_cov_factors`).

    **Fields:** ``u`` ``(p·l, k)`` (row ``i·l + c``: block row i, channel c),
    ``s`` ``(k,)``, ``v`` ``(q·r, k)`` (column ``j·r + m``: block column j,
    reference m), ``v = Hᵀ u / s``; ``block_rows`` p; ``n_channels`` l;
    ``refs`` the channel index of each reference ``(r,)``; ``dt`` [s].
    """

    u: np.ndarray
    s: np.ndarray
    v: np.ndarray
    block_rows: int
    n_channels: int
    refs: np.ndarray
    dt: float


def ssi_cov_factors(y: np.ndarray, fs_hz: float, *, orders: Sequence[int] = range(2, 161, 2),
                    block_rows: int | None = None, refs: np.ndarray | None = None, svd_method: SvdMethod = "randomized",
                    max_damping: float = 0.3, unbiased: bool = True, progress: bool = False,
                    workers: int | None = None) -> tuple[PoleSet, HankelFactors]:
    """:func:`ssi_cov`, also returning the SVD factors of H (:class:`HankelFactors`) for re-identifications.

    Used by :func:`ringfit.targets.uncertainty.jackknife_modes`; the extra
    cost is one n·k·max(orders) product (V from the ``Hᵀ Q`` the SVD forms).
    """
    return _ssi_cov(y, fs_hz, orders, block_rows, refs, svd_method, max_damping, unbiased, progress, workers,
                    factors=True)


def _ssi_cov(y, fs_hz, orders, block_rows, refs, svd_method, max_damping, unbiased, progress, workers, *, factors):
    """Body of :func:`ssi_cov` and :func:`ssi_cov_factors`: ``(poles, factors or None)``."""
    y = np.asarray(y, dtype=np.float64)
    if y.ndim != 2:
        raise InputError(f"outputs have shape {y.shape}; expected (channels, samples)")
    if not np.isfinite(y).all():
        raise InputError("outputs contain NaN or inf")
    orders = list(orders)
    l = y.shape[0]
    r = l if refs is None else len(refs)
    p = default_block_rows(max(orders), l, r) if block_rows is None else int(block_rows)
    workers = _workers(workers)
    with _own_threads(workers):
        h = hankel_for_svd(output_covariances(y, 2 * p - 1, refs, unbiased=unbiased), p)
        if not factors:
            return poles_from_hankel(h, l, orders, 1.0 / fs_hz, svd_method=svd_method, max_damping=max_damping,
                                     progress=progress, workers=workers), None
        u, s, v = truncated_svd(h, max(orders), method=svd_method, workers=workers, return_v=True)
        poles = poles_from_svd(u, s, l, orders, 1.0 / fs_hz, max_damping=max_damping, progress=progress,
                               workers=workers)
    ref_index = np.arange(l) if refs is None else np.asarray(refs, dtype=np.int64)
    return poles, HankelFactors(u, s, v, p, l, ref_index, 1.0 / fs_hz)


def poles_from_hankel(
    h,
    n_channels: int,
    orders: Sequence[int],
    dt: float,
    *,
    svd_method: SvdMethod = "randomized",
    max_damping: float = 0.3,
    progress: bool = False,
    workers: int | None = None,
) -> PoleSet:
    """Steps 3–4 for any block Hankel matrix (or :class:`BlockHankelOperator`) with n_channels rows per block.

    :func:`truncated_svd` of rank ``max(orders)`` and :func:`poles_from_svd`,
    with one BLAS thread throughout when ``workers`` > 1 (:func:`_own_threads`).
    Used by :func:`ssi_cov`, :func:`ssi_cov_multi_setup` and the data-driven
    SSI of :mod:`ringfit.targets.rolling_modes`.
    """
    workers = _workers(workers)
    with _own_threads(workers):
        u, s = truncated_svd(h, max(orders), method=svd_method, workers=workers)
        return poles_from_svd(u, s, n_channels, orders, dt, max_damping=max_damping, progress=progress,
                              workers=workers)


def _workers(workers: int | None) -> int:
    """``workers`` argument → thread count (None: :func:`default_workers`)."""
    return default_workers() if workers is None else max(1, int(workers))


def _own_threads(workers: int):
    """One BLAS thread for the whole SSI when ringfit runs its own ``workers`` threads.

    A multi-threaded BLAS call (the covariances) leaves OpenBLAS's threads
    spinning for a while; they then compete with the order sweep's threads
    (measured: 32 channels × 4 s, 2 cores, 0.18 → 0.23 s). With one worker
    BLAS keeps its own threading.
    """
    return small_matrix_threads() if workers > 1 else contextlib.nullcontext()


def hankel_for_svd(cov: np.ndarray, block_rows: int):
    """The block Hankel matrix in the cheaper form for :func:`truncated_svd`.

    :class:`BlockHankelOperator` (FFT products, H never formed) when
    l·r ≥ ``FFT_HANKEL_MIN_LR`` (one BLAS thread, 200 columns, p = 30: equal
    cost at 32 × 32 channels, 2.7× cheaper at 64 × 64, 3.6× at 128 × 128) and
    p·q·l·r numbers of memory are saved; the dense :func:`block_hankel` for
    fewer channels, where one real GEMM beats many small complex ones
    (16 × 16: dense 1.7× cheaper).
    """
    _, l, r = cov.shape
    if l * r >= FFT_HANKEL_MIN_LR:
        return BlockHankelOperator(cov, block_rows)
    return block_hankel(cov, block_rows)


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
    hs = []
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
    svd_method: SvdMethod = "randomized",
    max_damping: float = 0.3,
    progress: bool = False,
    workers: int | None = None,
) -> tuple[PoleSet, list[tuple[int, int]]]:
    """SSI-cov/ref over several setups sharing references (see :func:`multi_setup_hankel`).

    Other arguments as in :func:`ssi_cov`.

    **Returns:** ``(poles, channel_map)``; the shapes of ``poles`` follow ``channel_map``.
    """
    orders = list(orders)
    r = len(ref_index[0])
    l_total = r + sum(np.asarray(y).shape[0] - len(ri) for y, ri in zip(setups, ref_index))
    p = default_block_rows(max(orders), l_total, r) if block_rows is None else int(block_rows)
    workers = _workers(workers)
    with _own_threads(workers):
        h, channel_map = multi_setup_hankel(setups, ref_index, p)
        poles = poles_from_hankel(h, l_total, orders, 1.0 / fs_hz, svd_method=svd_method, max_damping=max_damping,
                                  progress=progress, workers=workers)
    return poles, channel_map
