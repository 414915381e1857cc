"""Modes of the rolling tyre from the cleat field (source §4.6; docs/physics.md §9 *rolling tyre modes*).

The angle–time field after the cleat has left the patch is a free decay observed at fixed places round the
wheel, so its poles are the rolling tyre's modes in the fixed frame. :func:`identify_rolling_modes` takes sectors
as channels, decimates, runs subspace identification on the decay (``method="decay"``, ERA-like) or on its
covariances (``"cov"``), builds the stabilization diagram and reads each stable pole's winding round the wheel
(:func:`winding`: n, backward or forward, or a standing wave's cos/sin tag about the patch): a mode table of
state ``rolling``, frame ``fixed``. Which branch of the rolling, loaded tyre each row is belongs to the model's
side (:mod:`ringfit.gap.campbell`); this module stays NumPy only.

Example (a synthetic drum test, 100 s at 40 km/h; about 5 s CPU)::

    bench = CleatBench(steady="analytic", fs_hz=6400.0, noise_ms2=5.0)
    rec = bench.record(100.0)
    field = angle_time_field(rec, sectors=128, duration_s=0.12, arrivals=detect_cleat_arrivals(rec))
    table = identify_rolling_modes(field, channels=32, orders=range(4, 61, 2)).table
    table.freq_hz[:3], table.n[:3], table.branch[:3], table.tag[:3]
    # [107.06, 113.25, 126.96] Hz; n 1, 2, 3; '', 'backward', 'backward'; 'vert', '', ''
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ringfit.errors import InputError
from ringfit.io.record_types import Axis

#: Default band of interest [Hz] (the source's 0–400 Hz).
DEFAULT_F_MAX = 400.0
#: A shape whose leading winding beats the opposite one by this factor is a travelling wave.
TRAVELLING_RATIO = 3.0


@dataclass
class RollingModes:
    """Identified modes of the rolling tyre.

    **Fields:**

    - ``table``: :class:`~ringfit.io.modes.ModeTable` (extra columns ``winding``,
      ``travelling_ratio``, ``n_orders``).
    - ``shapes``: (modes, channels) complex shapes at ``channel_deg``, unit norm.
    - ``channel_deg``: (channels,) sector angles of the channels [deg].
    - ``poles``: the :class:`~ringfit.targets.ssi.PoleSet`; ``stability``: its labels.
    - ``pole_winding``: (poles,) signed winding of every pole.
    - ``fs_hz``: sample rate after decimation; ``skip_s``: τ where the data start.
    """

    table: object
    shapes: np.ndarray
    channel_deg: np.ndarray
    poles: object
    stability: object
    pole_winding: np.ndarray
    fs_hz: float
    skip_s: float


def field_channels(field, *, channels: int = 128, axis: Axis = "radial", skip_s: float | None = None):
    """Sector subset of a field as SSI channels.

    **Returns** ``(y, channel_deg, tau_s, filled)``: y (channels, T) [m/s²] over
    the whole τ axis (empty bins filled along τ), the channel angles, the τ
    axis and the number of filled bins in τ ≥ skip_s.
    """
    data = field.channel(axis)
    s = data.shape[0]
    channels = int(min(channels, s))
    pick = np.round(np.arange(channels) * s / channels).astype(int)
    y = data[pick].copy()
    tau = field.tau_s
    start = 0.0 if skip_s is None else skip_s
    filled = 0
    for i in range(channels):
        bad = ~np.isfinite(y[i])
        if bad.all():
            raise InputError(f"sector {field.sector_deg[pick[i]]:.2f} deg has no samples; more passes needed")
        if bad.any():
            filled += int((bad & (tau >= start)).sum())
            y[i, bad] = np.interp(tau[bad], tau[~bad], y[i, ~bad])
    return y, field.sector_deg[pick], tau, filled


def winding(shapes: np.ndarray, angle_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed circumferential order of complex shapes sampled at ``angle_deg``.

    **Arguments:** ``shapes`` (k, channels); ``angle_deg`` (channels,), evenly spaced.

    **Returns** ``(m, ratio, phase)``: m (k,) the harmonic with the largest
    |c_m|, ``c_m = Σ_j shape_j e^{−imφ_j}`` (m > 0: backward wave for a
    positive-frequency pole, see module docstring); ratio (k,) |c_m|/|c_−m|;
    phase (k,) the standing wave's orientation φ0 [rad] (mod π/|m|): a shape
    ``cos(m(φ − φ0))`` times any complex factor has ``c_−m/c_m = e^{2imφ0}``, so
    ``φ0 = arg(c_−m/c_m)/2m``; a cos-type shape about φ = 0 has |cos(mφ0)| = 1,
    a sin-type one |cos(mφ0)| = 0, whatever the pole's complex scaling.
    """
    phi = np.radians(np.asarray(angle_deg, dtype=np.float64))
    l = phi.size
    m = np.arange(-(l // 2) + 1, l // 2)
    basis = np.exp(-1j * m[:, None] * phi[None, :])  # (harmonics, channels)
    c = np.asarray(shapes) @ basis.T  # (k, harmonics)
    best = np.argmax(np.abs(c), axis=1)
    mm = m[best]
    opp = np.array([np.abs(c[i, np.flatnonzero(m == -mm[i])[0]]) if mm[i] != 0 else np.abs(c[i, best[i]])
                    for i in range(len(mm))])
    ratio = np.abs(c[np.arange(len(mm)), best]) / np.maximum(opp, 1e-300)
    cm = c[np.arange(len(mm)), best]
    cn = np.array([c[i, np.flatnonzero(m == -mm[i])[0]] for i in range(len(mm))])
    phase = 0.5 * np.angle(cn / np.where(cm != 0, cm, 1.0)) / np.where(mm != 0, mm, 1)
    return mm, ratio, phase


def identify_rolling_modes(
    field,
    *,
    channels: int = 128,
    axis: Axis = "radial",
    skip_s: float | None = None,
    f_max: float = DEFAULT_F_MAX,
    orders=range(4, 81, 2),
    method: Literal["decay", "cov"] = "decay",
    block_rows: int | None = None,
    min_orders: float = 0.3,
    freq_tol: float = 0.005,
    progress: bool = False,
) -> RollingModes:
    """Covariance-type SSI on the reconstructed field → mode table of the rolling tyre.

    **Arguments:**

    - ``field``: :class:`~ringfit.targets.cleat.AngleTimeField`.
    - ``channels``: sectors used as channels (evenly spread).
    - ``skip_s``: τ before which the data are dropped (the cleat contact);
      default the time the wheel takes to turn 30°.
    - ``f_max``: top of the band [Hz] (decimation keeps Nyquist ≥ 2 f_max; poles above are dropped).
    - ``orders``: model orders of the sweep; ``method``: ``"decay"`` or ``"cov"``.
    - ``min_orders``: a mode must appear (stable) in this share of the orders.
    - ``freq_tol``: relative frequency gap that separates modes of one winding.

    **Returns:** :class:`RollingModes`.
    """
    from ringfit.io.modes import ModeTable
    from ringfit.targets.decimation import decimate, decimation_factor
    from ringfit.targets.ssi import block_hankel, poles_from_hankel, ssi_cov
    from ringfit.targets.stabilization import stabilization_diagram

    if method not in ("decay", "cov"):
        raise InputError(f"method {method!r}; expected 'decay' or 'cov'")
    rot = field.rotation_hz
    if skip_s is None:
        skip_s = 30.0 / (360.0 * rot)
    y, ch_deg, tau, _ = field_channels(field, channels=channels, axis=axis, skip_s=skip_s)
    fs = 1.0 / field.time_step_s
    q = decimation_factor(fs, f_max)
    y, fs_d = decimate(y, fs, q)
    start = int(math.ceil(skip_s * fs_d))
    y = y[:, start:]
    orders = sorted(int(o) for o in orders)
    l = y.shape[0]
    if y.shape[1] < 3 * max(10, max(orders) // l + 2):
        raise InputError(f"only {y.shape[1]} samples after τ = {skip_s:.4g} s at {fs_d:g} Hz; "
                         "lengthen duration_s or lower the model orders")
    if method == "cov":
        poles = ssi_cov(y, fs_d, orders=orders, block_rows=block_rows, progress=progress)
    else:
        n = y.shape[1]
        p = block_rows or max(10, max(orders) // l + 2)
        qcols = n - p - 1
        if qcols < max(orders):
            raise InputError(f"{n} samples are too few for model order {max(orders)} with {p} block rows")
        h = block_hankel(y.T[:, :, None], p, qcols)
        poles = poles_from_hankel(h, l, orders, 1.0 / fs_d, progress=progress)
    stability = stabilization_diagram(poles)
    m, ratio, phase = winding(poles.shape, ch_deg) if len(poles) else (np.zeros(0, int),) * 3

    # --- group stable poles by (winding, frequency) ------------------------------
    keep = (stability.label >= 1) & (poles.freq_hz <= f_max) if len(poles) else np.zeros(0, bool)
    groups = []
    for mm in np.unique(np.abs(m[keep])):
        # standing waves (ratio < TRAVELLING_RATIO) of ±mm are one family; travelling ones split by sign
        for sign in (1, -1, 0):
            sel = keep & (np.abs(m) == mm)
            if sign == 0:
                sel &= ratio < TRAVELLING_RATIO
            else:
                sel &= (np.sign(m) == sign) & (ratio >= TRAVELLING_RATIO)
            idx = np.flatnonzero(sel)
            if idx.size == 0:
                continue
            idx = idx[np.argsort(poles.freq_hz[idx])]
            cuts = np.flatnonzero(np.diff(poles.freq_hz[idx]) > freq_tol * poles.freq_hz[idx][1:]) + 1
            groups.extend((sign, mm, g) for g in np.split(idx, cuts))
    need = max(2, int(math.ceil(min_orders * len(poles.orders))))
    rows = []
    for sign, mm, g in groups:
        n_orders = len(np.unique(poles.order[g]))
        if n_orders < need:
            continue
        f = poles.freq_hz[g]
        z = poles.damping[g]
        best = g[np.argmax(poles.order[g])]
        shape = poles.shape[best]
        shape = shape * np.exp(-1j * np.angle(shape[np.argmax(np.abs(shape))]))
        if sign == 0:
            cos_type = abs(math.cos(mm * phase[best])) >= abs(math.sin(mm * phase[best]))
            if mm == 1:
                tag = "vert" if cos_type else "hort"
            else:
                tag = "extr" if cos_type else "0"
            branch = ""
        else:
            tag, branch = "", ("backward" if sign > 0 else "forward")
        rows.append(dict(freq=float(np.median(f)), std=float(np.std(f)), zeta=float(np.median(z)), n=int(mm),
                         tag=tag, branch=branch, winding=int(sign * mm), ratio=float(np.median(ratio[g])),
                         n_orders=n_orders, shape=shape))
    rows.sort(key=lambda r: r["freq"])
    cond = {"state": "rolling", "frame": "fixed", "rotation_hz": float(rot)}
    for k in ("speed_kmh", "load_n", "pressure_bar"):
        if field.condition.get(k) is not None:
            cond[k] = float(field.condition[k])
    table = ModeTable(
        freq_hz=np.array([r["freq"] for r in rows]),
        n=np.array([r["n"] for r in rows], dtype=np.int64),
        tag=np.array([r["tag"] for r in rows], dtype=object),
        kind=np.array(["structural"] * len(rows), dtype=object),
        freq_std_hz=np.array([r["std"] for r in rows]),
        damping_pct=np.array([100.0 * r["zeta"] for r in rows]),
        branch=np.array([r["branch"] for r in rows], dtype=object),
        extra={
            "winding": np.array([str(r["winding"]) for r in rows], dtype=object),
            "travelling_ratio": np.array([f"{r['ratio']:.3g}" for r in rows], dtype=object),
            "n_orders": np.array([str(r["n_orders"]) for r in rows], dtype=object),
        },
        condition=cond,
    )
    shapes = np.array([r["shape"] for r in rows]) if rows else np.zeros((0, l), complex)
    return RollingModes(table=table, shapes=shapes, channel_deg=ch_deg, poles=poles, stability=stability,
                        pole_winding=m, fs_hz=fs_d, skip_s=float(skip_s))
