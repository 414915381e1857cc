"""How uncertain is each SSI mode: a leave-one-group-out jackknife over the sensor angles (docs/physics.md §9).

``freq_std_hz`` and ``damping_std_pct`` of ``ringfit ssi`` (docs/formats.md §2) come from here. The sensor angles
of a roving test are dealt into at most :data:`JACKKNIFE_GROUPS` groups (:func:`angle_groups`); each replicate is
the SSI without one group, at :data:`JACKKNIFE_ORDERS` model orders, computed from the run's own rank-K Hankel
factors (:class:`~ringfit.targets.ssi.HankelFactors`: no new pass over the data); the reported σ² is the
jackknife's variance plus (:data:`ORDER_SPREAD_SHARE` × the spread over model orders)², which the jackknife cannot
see. Fewer than :data:`MIN_GROUPS` angles: σ is the order spread alone, and the method text says so. Why each
choice, and the coverage measured on synthetic records: docs/physics.md §9 *uncertainty of an SSI mode*.

Example (the jackknife runs inside the SSI; its figures land in the mode table, ``ringfit example records``)::

    from ringfit.io.records import read_records
    from ringfit.targets.identify import ssi_modes

    table = ssi_modes(read_records("ex/impact.records.npz")).table
    print(table.freq_hz, table.freq_std_hz, table.extra_floats("damping_std_pct"))
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import scipy.linalg

from ringfit._threads import small_matrix_threads
from ringfit.targets.ssi import HankelFactors, PoleSet, discrete_poles

#: Most groups of sensor angles (replicates) of the jackknife.
JACKKNIFE_GROUPS = 12
#: Fewest groups for a jackknife; below, σ is the order spread alone.
MIN_GROUPS = 6
#: Model orders per mode at which the replicates are identified.
JACKKNIFE_ORDERS = 2
#: Share of the model-order spread added in quadrature (rule 5 of the module docstring).
ORDER_SPREAD_SHARE = 0.5


@dataclass
class ModeUncertainty:
    """One standard deviation per mode (shape ``(modes,)``, the modes in the order given).

    - ``freq_std_hz`` [Hz], ``damping_std`` [-]: the reported σ (rule 5).
    - ``freq_jack_hz``, ``damping_jack``: the jackknife part (NaN where not estimated).
    - ``freq_orders_hz``, ``damping_orders``: the model-order spread.
    - ``replicates``: replicates in which the mode was found (0 without jackknife).
    - ``orders``: the model orders of each mode's statistic (list of arrays).
    - ``groups``: G, the number of replicates (0: no jackknife).
    - ``method``: one line saying how σ was obtained (goes into the sidecar).
    """

    freq_std_hz: np.ndarray
    damping_std: np.ndarray
    freq_jack_hz: np.ndarray
    damping_jack: np.ndarray
    freq_orders_hz: np.ndarray
    damping_orders: np.ndarray
    replicates: np.ndarray
    orders: list
    groups: int
    method: str


def angle_groups(angle_rad: np.ndarray, max_groups: int = JACKKNIFE_GROUPS) -> tuple[np.ndarray, int]:
    """Group of each channel: its sensor angle's rank (in angle order), dealt round robin into G groups.

    G = the number of angles when there are at most ``max_groups``; else the
    largest G ≤ ``max_groups`` (and ≥ ``MIN_GROUPS``) that divides them (equal
    groups: 36 angles → 12 groups of 3), else ``max_groups`` (sizes differ by one angle).

    **Arguments:** ``angle_rad`` ``(channels,)`` [rad]. **Returns:** ``(group, G)``, group ``(channels,)`` int.
    """
    a = np.round(np.mod(np.asarray(angle_rad, dtype=np.float64), 2 * np.pi), 9)
    if a.size == 0:
        return np.zeros(0, np.int64), 0
    _, rank = np.unique(a, return_inverse=True)
    n = int(rank.max()) + 1
    if n <= max_groups:
        g = n
    else:
        even = [k for k in range(int(max_groups), MIN_GROUPS - 1, -1) if n % k == 0]
        g = even[0] if even else int(max_groups)
    return (rank % g).astype(np.int64), g


def jackknife_modes(
    factors: HankelFactors,
    poles: PoleSet,
    modes: Sequence,
    groups: np.ndarray,
    *,
    n_orders: int = JACKKNIFE_ORDERS,
    max_order: int | None = None,
    freq_tol: float = 0.01,
    mac_tol: float = 0.6,
    order_share: float = ORDER_SPREAD_SHARE,
    max_damping: float = 0.3,
    workers: int = 1,
) -> ModeUncertainty:
    """σ of every mode's frequency and damping by the rule of the module docstring.

    **Arguments:**

    - ``factors``: the SSI run's :class:`~ringfit.targets.ssi.HankelFactors`.
    - ``poles``: its :class:`~ringfit.targets.ssi.PoleSet`.
    - ``modes``: :class:`~ringfit.targets.clustering.PhysicalMode` list
      (``pole_index`` into ``poles``; ``basis`` on the run's channels).
    - ``groups``: group of each channel ``(channels,)`` (:func:`angle_groups`);
      fewer than ``MIN_GROUPS`` groups: σ = σ_orders.
    - ``n_orders``, ``max_order``: orders of each mode's statistic (rule 3).
    - ``freq_tol`` (relative), ``mac_tol``: matching in the replicates.
    - ``order_share``: share of σ_orders added in quadrature (rule 5).
    - ``workers``: threads over the replicates (LAPACK releases the GIL).

    **Returns:** :class:`ModeUncertainty`.
    """
    modes = list(modes)
    m = len(modes)
    f_ord = np.array([md.freq_std_hz for md in modes], dtype=np.float64)
    z_ord = np.array([md.damping_std for md in modes], dtype=np.float64)
    groups = np.asarray(groups, dtype=np.int64)
    n_groups = int(np.unique(groups).size) if groups.size else 0
    if n_groups < MIN_GROUPS or m == 0:
        why = ("no modes" if m == 0 else "jackknife not asked for" if groups.size == 0
               else f"{n_groups} group(s) of sensor angles, fewer than {MIN_GROUPS}")
        return ModeUncertainty(f_ord, z_ord, np.full(m, np.nan), np.full(m, np.nan), f_ord, z_ord,
                               np.zeros(m, np.int64), [np.zeros(0, np.int64)] * m, 0,
                               f"spread over the model orders only ({why})")
    orders = _statistic_orders(poles, modes, n_orders, max_order)
    need = np.unique(np.concatenate(orders))
    k = int(need.max())
    ref = [[_pair_centre(poles, md.pole_index[poles.order[md.pole_index] == o]) for o in os_]
           for md, os_ in zip(modes, orders)]

    grams = _Grams(factors, k)
    bases = np.zeros((m, factors.n_channels, 2), complex)  # each mode's shape basis (1 or 2 columns), zero-padded
    for i, md in enumerate(modes):
        bases[i, :, :md.basis.shape[1]] = md.basis[:, :2]
    users = {int(o): [(i, j) for i in range(m) for j, oi in enumerate(orders[i]) if oi == o] for o in need}

    def replicate(gid):
        out = _replicate_poles(grams, groups != gid, need, max_damping)
        if out is None:
            return None
        keep, by_order = out
        b = bases[:, keep]
        ginv = np.linalg.pinv(np.conj(b.transpose(0, 2, 1)) @ b, hermitian=True)  # (BᴴB)⁺ per mode, (m, 2, 2)
        per = np.full((m, n_orders, 2), np.nan)
        for o, use in users.items():
            if int(o) not in by_order:
                continue
            freq, damping, shape = by_order[int(o)]
            rows = np.array([i for i, _ in use])
            proj = np.einsum("mcd,pc->mpd", np.conj(b[rows]), shape)  # Bᴴφ per mode and pole
            mac = np.real(np.einsum("mpd,mde,mpe->mp", np.conj(proj), ginv[rows], proj))
            mac /= np.sum(np.abs(shape) ** 2, axis=1)[None, :]  # subspace MAC ‖P_B φ‖²/‖φ‖²
            for r, (i, j) in enumerate(use):
                f0, _, count = ref[i][j]
                near = np.flatnonzero((np.abs(freq - f0) <= freq_tol * f0) & (mac[r] >= mac_tol))
                if near.size:
                    near = near[np.argsort(np.abs(freq[near] - f0))][:count]
                    per[i, j] = freq[near].mean(), damping[near].mean()
        vals = np.full((m, 2), np.nan)
        for i in range(m):
            v = per[i, :len(orders[i])]
            if np.isfinite(v).all():
                vals[i] = v.mean(axis=0)
        return vals

    gids = np.unique(groups)
    with small_matrix_threads():
        if workers <= 1:
            results = [replicate(g) for g in gids]
        else:
            from concurrent.futures import ThreadPoolExecutor

            with ThreadPoolExecutor(max_workers=int(workers)) as pool:
                results = list(pool.map(replicate, gids))
    reps = np.stack([r for r in results if r is not None]) if any(r is not None for r in results) \
        else np.full((0, m, 2), np.nan)
    found = np.sum(np.isfinite(reps[..., 0]), axis=0).astype(np.int64)
    jack = np.full((m, 2), np.nan)
    for i in range(m):
        v = reps[np.isfinite(reps[:, i, 0]), i]
        g = v.shape[0]
        if g >= max(3, -(-n_groups // 2)):
            jack[i] = np.sqrt((g - 1) / g * np.sum((v - v.mean(axis=0)) ** 2, axis=0))
    f_std = np.hypot(jack[:, 0], order_share * f_ord)
    z_std = np.hypot(jack[:, 1], order_share * z_ord)
    method = (f"leave-one-group-out jackknife over {n_groups} groups of sensor angles at {n_orders} model orders "
              f"per mode, plus {order_share:g} x the spread over the model orders, in quadrature")
    return ModeUncertainty(f_std, z_std, jack[:, 0], jack[:, 1], f_ord, z_ord, found, orders, n_groups, method)


def _statistic_orders(poles: PoleSet, modes, n_orders: int, max_order: int | None) -> list:
    """The model orders of each mode's statistic (rule 3).

    Common orders (one eigen-decomposition per order and replicate serves
    every mode): the quantiles (i + ½)/n_orders of the orders (≤ max_order) at
    which modes were found, pooled; each mode uses those at which it was
    found, and a mode found at none of them the same quantiles of its own orders.
    """
    q = (np.arange(n_orders) + 0.5) / n_orders

    def own(md):
        have = np.unique(poles.order[md.pole_index])
        if max_order is not None and np.any(have <= max_order):
            have = have[have <= max_order]
        return have

    sets = [own(md) for md in modes]
    pooled = np.sort(np.concatenate(sets))
    common = np.unique(pooled[np.round(q * (pooled.size - 1)).astype(np.int64)])
    out = []
    for have in sets:
        hit = common[np.isin(common, have)]
        out.append(hit if hit.size else np.unique(have[np.round(q * (have.size - 1)).astype(np.int64)]))
    return out


def _pair_centre(poles: PoleSet, idx: np.ndarray) -> tuple[float, float, int]:
    """Frequency [Hz], damping [-] and count of the poles ``idx`` of one order (the pair centre)."""
    return float(poles.freq_hz[idx].mean()), float(poles.damping[idx].mean()), int(idx.size)


class _Grams:
    """The rank-k factors of one SSI run and their Gram matrices, computed once for all replicates.

    U and V have orthonormal columns (as :func:`~ringfit.targets.ssi.truncated_svd`
    returns them), so ``UᵀU = VᵀV = I``; ``o_up = O↑ᵀO↑ = I − U_lastᵀU_last``
    and ``o_dn = O↑ᵀO↓`` with O = U (↑: all block rows but the last, ↓: all
    but the first), each k × k.
    """

    def __init__(self, f: HankelFactors, k: int):
        self.l, self.p, self.dt, self.refs = f.n_channels, f.block_rows, f.dt, f.refs
        self.u, self.s, self.v = f.u[:, :k], f.s[:k], f.v[:, :k]
        last = self.u[-self.l:]
        self.eye = np.eye(k)
        self.o_up = self.eye - last.T @ last
        self.o_dn = self.u[:-self.l].T @ self.u[self.l:]


def _replicate_poles(gr: _Grams, keep: np.ndarray, orders: np.ndarray, max_damping: float):
    """Poles of the SSI without the channels ``~keep`` at ``orders`` (rule 2): ``(keep, {order: (f, ζ, φ)})``.

    None when the replicate cannot be formed (a Gram matrix not positive definite).
    """
    l, p, u, s, v = gr.l, gr.p, gr.u, gr.s, gr.v
    rows = np.flatnonzero(~np.tile(keep, p))  # rows i·l + c of the dropped channels
    cols = np.flatnonzero(~np.tile(keep[gr.refs], v.shape[0] // gr.refs.size))
    up = rows[rows < (p - 1) * l]  # dropped rows of O↑; their partners in O↓ are up + l
    ug, vg, uu = u[rows], v[cols], u[up]
    try:
        ru = scipy.linalg.cholesky(gr.eye - ug.T @ ug, lower=False, check_finite=False)  # U_keptᵀU_kept = R_UᵀR_U
        rv = scipy.linalg.cholesky(gr.eye - vg.T @ vg, lower=False, check_finite=False)
    except np.linalg.LinAlgError:
        return None
    a, _, _ = scipy.linalg.svd((ru * s) @ rv.T, check_finite=False)
    w = scipy.linalg.solve_triangular(ru, a, check_finite=False)  # U_kept W: the replicate's left singular vectors
    n1 = w.T @ (gr.o_up - uu.T @ uu) @ w
    n2 = w.T @ (gr.o_dn - uu.T @ u[up + l]) @ w
    c = u[:l][keep] @ w
    by_order = {}
    for n in orders:
        n = int(n)
        try:
            a_n = scipy.linalg.solve(n1[:n, :n], n2[:n, :n], assume_a="pos", check_finite=False)
            lam, phi = discrete_poles(a_n, np.ascontiguousarray(c[:, :n]), gr.dt, max_damping)
        except (np.linalg.LinAlgError, ValueError):
            continue
        wn = np.abs(lam)
        by_order[n] = (wn / (2 * np.pi), -lam.real / np.where(wn > 0, wn, 1.0), phi)
    return keep, by_order
