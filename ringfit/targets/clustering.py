"""Automatic clustering of stable poles into physical modes, one mode per double pole.

Rule (documented, deterministic):

1. Candidates: poles whose stabilization label is at least ``min_label``
   (2 = square: frequency, damping and pair-aware shape stable).
2. Linking: two candidates are linked when their frequencies differ by at
   most ``gap_tol`` (relative) AND their shapes have MAC ≥ ``mac_tol``;
   groups are the connected components (single linkage). Two physical modes
   at nearby frequencies (the cavity mode next to n = 6) have orthogonal
   shapes and stay apart; the two poles of a double pole are joined through
   the mixed shapes the pair shows at the orders that do not resolve it, and
   pairs that are resolved at every order are merged afterwards by n
   (:func:`merge_pairs`, which needs the sensor angles); a half whose shape
   reads another n (what a notch or the noise left of it) is merged into the
   ring-like half at its frequency (:func:`merge_twins`).
3. A group is a mode if it has poles in at least ``min_share`` of the model
   orders that can hold a mode: the orders of the sweep from the lowest one
   with any stable pole in the band upwards. A physical mode, once the model
   order can hold it, stays at every higher order; a mathematical pole that
   models the noise appears only at the top of the sweep and not at every
   order there (on the example records a pole drifting 334 → 329 Hz beside
   n = 9 appeared in 25 of the 72 orders from 18 to 160 and passed the old
   share of the whole sweep, 30 % of 80; the ring modes appear in 68–72).
4. Per mode: the pole frequencies and dampings of each order are averaged
   (the pair centre); the mode's frequency and damping are the mean of those
   per-order values and their standard deviations the spread over orders
   (these feed ``freq_std_hz``). The split is the median spread of the
   orders that resolved two poles; the shape basis is B.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ringfit.targets.ssi import PoleSet
from ringfit.targets.stabilization import Stability, mac, pair_basis


@dataclass
class PhysicalMode:
    """One physical mode (a double pole counts once).

    - ``freq_hz``, ``freq_std_hz``: mean and std of the per-order pair centre [Hz].
    - ``damping``, ``damping_std``: mean and std of the damping ratio [-].
    - ``split_hz``: frequency split of the pair [Hz] (0 when never resolved).
    - ``basis``: orthonormal shape basis (channels, 1 or 2), complex.
    - ``shape``: leading shape (channels,), complex, unit norm.
    - ``pole_index``: indices of its poles in the :class:`PoleSet`.
    - ``n_orders``: number of model orders in which it appears.
    """

    freq_hz: float
    freq_std_hz: float
    damping: float
    damping_std: float
    split_hz: float
    basis: np.ndarray
    shape: np.ndarray
    pole_index: np.ndarray
    n_orders: int


def cluster_modes(
    poles: PoleSet,
    stability: Stability,
    *,
    min_label: int = 2,
    gap_tol: float = 0.005,
    mac_tol: float = 0.6,
    min_share: float = 0.5,
    f_range: tuple[float, float] = (0.0, np.inf),
) -> list[PhysicalMode]:
    """Group stable poles into physical modes (rule in the module docstring).

    **Returns:** modes sorted by frequency.
    """
    f, phi, order = poles.freq_hz, poles.shape, poles.order
    cand = np.flatnonzero((stability.label >= min_label) & (f >= f_range[0]) & (f <= f_range[1]))
    cand = cand[np.argsort(f[cand])]
    parent = np.arange(cand.size)

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    fc_sorted = f[cand]
    for a in range(cand.size):
        hi = np.searchsorted(fc_sorted, fc_sorted[a] * (1 + gap_tol), side="right")
        if hi <= a + 1:
            continue
        nb = np.arange(a + 1, hi)
        linked = nb[mac(phi[cand[a]][None, :], phi[cand[nb]]) >= mac_tol]
        for b in linked:
            ra, rb = find(a), find(int(b))
            if ra != rb:
                parent[rb] = ra
    roots = np.array([find(i) for i in range(cand.size)], dtype=np.int64)
    groups = [cand[roots == r] for r in np.unique(roots)]
    eligible = np.asarray(poles.orders)[np.asarray(poles.orders) >= order[cand].min()] if cand.size else poles.orders
    min_orders = max(2, int(np.ceil(min_share * len(eligible))))
    modes = [summarize(poles, g) for g in groups if np.unique(order[g]).size >= min_orders]
    return sorted(modes, key=lambda m: m.freq_hz)


def summarize(poles: PoleSet, g: np.ndarray) -> PhysicalMode:
    """Statistics of one group of poles (step 4 of the module docstring)."""
    f, z, phi, order = poles.freq_hz, poles.damping, poles.shape, poles.order
    ords = np.unique(order[g])
    fc = np.array([f[g][order[g] == o].mean() for o in ords])
    zc = np.array([z[g][order[g] == o].mean() for o in ords])
    spread = [np.ptp(f[g][order[g] == o]) for o in ords if np.sum(order[g] == o) >= 2]
    basis = pair_basis(phi[g])
    return PhysicalMode(
        freq_hz=float(fc.mean()), freq_std_hz=float(fc.std(ddof=1)) if fc.size > 1 else 0.0,
        damping=float(zc.mean()), damping_std=float(zc.std(ddof=1)) if zc.size > 1 else 0.0,
        split_hz=float(np.median(spread)) if spread else 0.0,
        basis=basis, shape=basis[:, 0], pole_index=g, n_orders=int(ords.size),
    )


def merge_pairs(poles: PoleSet, modes: list[PhysicalMode], n: np.ndarray, pair_tol: float = 0.01) -> tuple[list[PhysicalMode], np.ndarray]:
    """Merge modes with the same circumferential index n within ``pair_tol`` (relative): the two halves of a double pole.

    **Returns:** ``(modes, n)`` after merging.
    """
    modes, n = list(modes), list(n)
    merged = True
    while merged:
        merged = False
        for i in range(len(modes)):
            for j in range(i + 1, len(modes)):
                if n[i] == n[j] and n[i] >= 1 and abs(modes[i].freq_hz - modes[j].freq_hz) <= pair_tol * modes[i].freq_hz:
                    modes[i] = summarize(poles, np.concatenate([modes[i].pole_index, modes[j].pole_index]))
                    del modes[j], n[j]
                    merged = True
                    break
            if merged:
                break
    return modes, np.asarray(n, dtype=np.int64)


#: The two halves of a double pole merged by :func:`merge_twins` have dampings within this factor of each other.
TWIN_DAMPING = 2.0


def merge_twins(poles: PoleSet | None, modes: list[PhysicalMode], n: np.ndarray,
                pairs: list[tuple[int, int]]) -> tuple[list[PhysicalMode], np.ndarray]:
    """Merge each ``(twin, into)`` of ``pairs``: the twin, a row that is not ring-like at the frequency of the
    ring-like row ``into``, is the other half of its double pole whose shape reads another n. With ``poles``
    (SSI) the halves' poles are summarised together (the frequency is the pair's centre, the split theirs) and
    the merged mode keeps ``into``'s shape basis (hence its n); without (FRF peaks), or when the twin's damping
    is not within a factor :data:`TWIN_DAMPING` of the mode's (the two halves of a double pole share their
    damping; a lightly damped hum residue beside a mode does not), the twin is dropped and its poles with it.

    **Returns:** ``(modes, n)`` after merging, in the order of ``modes``.
    """
    twins: dict[int, list[int]] = {}
    for i, j in pairs:
        zi, zj = modes[int(i)].damping, modes[int(j)].damping
        if zi > 0 and zj > 0 and 1 / TWIN_DAMPING <= zi / zj <= TWIN_DAMPING:
            twins.setdefault(int(j), []).append(int(i))
    drop = {int(i) for i, _ in pairs}
    modes = list(modes)
    if poles is not None:
        for j, ii in twins.items():
            union = np.concatenate([modes[j].pole_index, *(modes[i].pole_index for i in ii)])
            modes[j] = replace(summarize(poles, union), basis=modes[j].basis, shape=modes[j].shape)
    keep = [k for k in range(len(modes)) if k not in drop]
    return [modes[k] for k in keep], np.asarray(n, dtype=np.int64)[keep]
