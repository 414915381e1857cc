"""Plots of the modal identification: stabilization diagram, polar mode shapes, FRF with peaks.

The stabilization diagram uses the source's symbols (seed §2.5, figure 2):
small squares where frequency and damping are stable, circles where only the
frequency is; frequency on the horizontal axis, model order on the vertical.
Mode shapes are drawn on a circle as in the source's figures 25–26: the
undeformed tyre plus radial and tangential deflections. matplotlib is
imported inside each function (Agg backend).
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np

from ringfit.report.figures import pyplot
from ringfit.report.numbers import fmt_value


def _freq_text(t, i: int) -> str:
    """Row ``i``'s frequency to the digits its ``freq_std_hz`` warrants (4 significant digits without one)."""
    sd = None if t.freq_std_hz is None else float(t.freq_std_hz[i])
    return fmt_value(t.freq_hz[i], sd if sd is not None and np.isfinite(sd) and sd > 0 else None)


def _stagger(x, width, rows=3):
    """Row (0, 1, …) for each label at data positions ``x`` so that labels closer than ``width`` do not overlap."""
    order = np.argsort(x)
    last = [-np.inf] * rows
    out = np.zeros(len(x), dtype=int)
    for i in order:
        r = next((k for k in range(rows) if x[i] - last[k] >= width), int(np.argmin(last)))
        out[i], last[r] = r, x[i]
    return out


def _mode_label(t, i) -> str:
    return "ac" if t.kind[i] == "acoustic" else ("n=?" if t.n[i] < 0 else f"n={t.n[i]}")


def plot_stabilization(result, *, f_range=(0.0, 400.0), ax=None, source_symbols: bool = False, title=None,
                       spectrum: bool = True):
    """Stabilization diagram of an SSI :class:`~ringfit.targets.identify.ModeIdentification`.

    Squares: frequency, damping and shape stable; circles: frequency (and
    shape) stable only; grey dots: poles that are not stable from one order
    to the next (``source_symbols=True`` ignores the shape check, as the
    source did). Behind them, on a log axis, the first singular values of the
    channels' cross-power spectral matrix (a CMIF-like spectrum; each peak is
    a mode). Identified modes are marked by vertical lines labelled with n
    (``ac`` for acoustic candidates), staggered so that labels never overlap.
    **Returns:** the figure.
    """
    plt = pyplot()
    own = ax is None
    fig, ax = (plt.subplots(figsize=(10, 5.5)) if own else (ax.figure, ax))
    poles, stab = result.poles, result.stability
    label = stab.source_label if source_symbols else stab.label
    band = (poles.freq_hz >= f_range[0]) & (poles.freq_hz <= f_range[1])
    if spectrum and "psd_singular_values" in result.info:
        f, sv = result.info["psd_singular_values"]
        sel = (f >= f_range[0]) & (f <= f_range[1])
        axs = ax.twinx()
        for j in range(sv.shape[1]):
            if np.any(sv[sel, j] > 0):
                axs.semilogy(f[sel], sv[sel, j], color=str(0.45 + 0.15 * j), lw=1.0 - 0.2 * j, zorder=0,
                             label=f"PSD singular value {j + 1}")
        axs.set_ylabel("PSD singular values [(m/s²)²/Hz]", color="0.4")
        axs.tick_params(axis="y", colors="0.4", labelsize=8)
        ax.set_zorder(axs.get_zorder() + 1)
        ax.patch.set_visible(False)
    new = band & (label == 0)
    sq, ci = band & (label == 2), band & (label == 1)
    ax.plot(poles.freq_hz[new], poles.order[new], ".", ms=2, color="0.6", label="not stable")
    ax.plot(poles.freq_hz[ci], poles.order[ci], "o", ms=3, mfc="none", mec="tab:orange", label="freq. stable")
    ax.plot(poles.freq_hz[sq], poles.order[sq], "s", ms=3, mfc="none", mec="tab:blue", label="freq. & damping stable")
    t = result.table
    top = poles.orders[-1]
    rows = _stagger(t.freq_hz, 0.028 * (f_range[1] - f_range[0]))
    for i in range(len(t)):
        ax.axvline(t.freq_hz[i], color="tab:green" if t.kind[i] == "acoustic" else "0.35", lw=0.7, zorder=0)
        ax.annotate(_mode_label(t, i), (t.freq_hz[i], 1.0), xycoords=("data", "axes fraction"),
                    xytext=(0, 3 + 11 * rows[i]), textcoords="offset points", ha="center", va="bottom", fontsize=7)
    ax.set_xlim(*f_range)
    ax.set_ylim(0, top * 1.04)
    ax.set_xlabel("natural frequency f_n [Hz]")
    ax.set_ylabel("model order (state dimension) [-]")
    ax.legend(loc="lower right", fontsize=7, framealpha=0.9)
    info = result.info
    ax.set_title(title or (f"SSI stabilization diagram — {info.get('channels', '?')} channels, orders "
                           f"{int(poles.orders[0])}–{int(top)}, {len(t)} modes"
                           + ("" if info.get("credible", True) else " (NOT CREDIBLE: noise dominates)")),
                 fontsize=10, pad=12 + 11 * (int(rows.max()) if len(t) else 0))
    if own:
        fig.tight_layout()
    return fig


def plot_mac(result, *, ax=None):
    """MAC matrix between the identified modes' shapes (a well separated set is near the identity).

    **Returns:** the figure.
    """
    from ringfit.targets.stabilization import mac

    plt = pyplot()
    fig, ax = (plt.subplots(figsize=(5, 4.5)) if ax is None else (ax.figure, ax))
    t = result.table
    shapes = np.array([m.shape for m in result.modes])
    m = mac(shapes[:, None, :], shapes[None, :, :]) if len(shapes) else np.zeros((0, 0))
    im = ax.imshow(m, vmin=0, vmax=1, cmap="viridis", origin="upper")
    ticks = [f"{_mode_label(t, i)} {_freq_text(t, i)}" for i in range(len(t))]
    ax.set_xticks(range(len(t)), ticks, rotation=90, fontsize=6)
    ax.set_yticks(range(len(t)), ticks, fontsize=6)
    ax.set_xlabel("mode (n, frequency [Hz])")
    ax.set_ylabel("mode (n, frequency [Hz])")
    ax.set_title("MAC of the identified shapes", fontsize=9)
    fig.colorbar(im, ax=ax, label="MAC [-]", shrink=0.8)
    return fig


def plot_ssi_summary(result, *, f_range=(0.0, 400.0)):
    """What ``ringfit ssi --plot`` writes: stabilization diagram with the PSD singular values (top),
    MAC matrix (bottom left) and the mode shapes around the tyre (bottom right). **Returns:** the figure."""
    plt = pyplot()
    t = result.table
    cols = 4
    nrow = max(1, int(np.ceil(len(t) / cols)))
    fig = plt.figure(figsize=(14, 5.5 + 2.6 * nrow))
    outer = fig.add_gridspec(2, 1, height_ratios=(5.5, 2.6 * nrow), hspace=0.3, left=0.06, right=0.94, top=0.93,
                             bottom=0.06)
    plot_stabilization(result, f_range=f_range, ax=fig.add_subplot(outer[0]))
    bottom = outer[1].subgridspec(1, 2, width_ratios=(1, 2.4), wspace=0.2)
    plot_mac(result, ax=fig.add_subplot(bottom[0]))
    _shape_panels(result, fig, bottom[1], cols=cols)
    return fig


#: How :func:`plot_mode_shapes` makes a complex shape real: ``"principal"``
#: (:func:`~ringfit.targets.shapes.real_shape_principal`, the most-real rotation) or ``"source"``
#: (:func:`~ringfit.targets.shapes.real_shape_source`, the source's v_r = sign(Im v)|v|).
RealShape = Literal["principal", "source"]


def plot_mode_shapes(result, *, rows=None, scale: float = 0.25, real: RealShape = "principal", cols: int = 3):
    """Polar plots of the identified shapes around the tyre (radial and tangential).

    **Arguments:** ``rows`` table rows to draw (default all); ``scale`` the
    largest deflection as a fraction of the radius; ``real``: ``"principal"``
    (most-real rotation) or ``"source"`` (v_r = sign(Im v)|v|).
    **Returns:** the figure.
    """
    if real not in get_args(RealShape):
        raise ValueError(f"real = {real!r}; expected one of {get_args(RealShape)}")
    plt = pyplot()
    t = result.table
    rows = list(range(len(t))) if rows is None else list(rows)
    nrow = max(1, int(np.ceil(len(rows) / cols)))
    fig = plt.figure(figsize=(3 * cols, 3 * nrow + 0.4))
    _shape_panels(result, fig, fig.add_gridspec(1, 1, bottom=0.08, top=0.92)[0], rows=rows, scale=scale, real=real,
                  cols=cols)
    return fig


def _shape_panels(result, fig, spec, *, rows=None, scale: float = 0.25, real: RealShape = "principal",
                  cols: int = 4):
    """Polar mode-shape panels of ``result`` drawn into the gridspec cell ``spec`` of ``fig``."""
    from ringfit.targets.shapes import real_shape_principal, real_shape_source

    t = result.table
    rows = list(range(len(t))) if rows is None else list(rows)
    nrow = max(1, int(np.ceil(len(rows) / cols)))
    grid = spec.subgridspec(nrow, cols, hspace=0.35, wspace=0.15)
    axes = np.array([[fig.add_subplot(grid[r, c], projection="polar") for c in range(cols)] for r in range(nrow)])
    conv = real_shape_principal if real == "principal" else real_shape_source
    for k, ax in enumerate(axes.ravel()):
        ax.set_axis_off()
        if k >= len(rows):
            continue
        i = rows[k]
        v = conv(result.modes[i].shape)
        v = v / (np.max(np.abs(v)) or 1.0)
        ax.set_axis_on()
        th_all = np.linspace(0, 2 * np.pi, 361)
        ax.plot(th_all, np.ones_like(th_all), color="0.7", lw=0.8)
        for axis_name, color in (("radial", "tab:blue"), ("tangential", "tab:red")):
            sel = result.axis == axis_name
            if not sel.any():
                continue
            th = result.angle_rad[sel]
            order = np.argsort(np.mod(th, 2 * np.pi))
            th, val = np.mod(th[order], 2 * np.pi), v[sel][order]
            th, val = np.append(th, th[0] + 2 * np.pi), np.append(val, val[0])
            if axis_name == "radial":  # inward positive: draw the deformed circle
                ax.plot(th, 1 - scale * val, color=color, lw=1.2, label="radial")
            else:  # tangential: arrows along the circle
                ax.plot(th, 1 + scale * val, color=color, lw=0.8, ls="--", label="tangential")
        ax.set_ylim(0, 1 + 1.5 * scale)
        ax.set_yticklabels([])
        ax.set_xticks(np.radians([0, 90, 180, 270]), [])
        ax.grid(alpha=0.3)
        ax.plot([0], [1 + 1.5 * scale], marker="v", color="k", ms=5, clip_on=False)  # the impact point
        kind = "acoustic" if t.kind[i] == "acoustic" else f"n = {t.n[i]}"
        ax.set_title(f"{kind}, {_freq_text(t, i)} Hz", fontsize=8, pad=2)
    fig.text(0.99, 0.005, "mode shapes around the tyre: sensor angle from the impact point (▼, 0°), anticlockwise; "
             "grey circle = undeformed tyre; blue = radial, red dashed = tangential; largest deflection = "
             f"{100 * scale:.0f} % of the radius (normalised shapes)", ha="right", va="bottom", fontsize=7,
             color="0.25")


def plot_frf(result, *, f_range=(0.0, 400.0)):
    """FRF identification: magnitude and phase, with the picked peaks. **Returns:** the figure.

    Top: the rms over angles and axes of |H| (what the peaks are picked on,
    summed over harmonics) and the FRF of the record nearest the excitation
    point (radial axis when there is one), with the mean coherence on the
    right axis when it was estimated. Bottom: the phase of that same FRF.
    """
    plt = pyplot()
    fig, (ax, axp) = plt.subplots(2, 1, figsize=(10, 6.5), sharex=True, gridspec_kw={"height_ratios": (2.2, 1)})
    frf = result.frf
    f = frf.freq_hz
    band = (f >= f_range[0]) & (f <= f_range[1])
    mag = np.sqrt(np.mean(np.abs(frf.h1) ** 2, axis=(0, 1)))
    near = int(np.argmin(np.abs((np.asarray(frf.angle_deg) + 180.0) % 360.0 - 180.0)))
    ax_i = list(frf.axes).index("radial") if "radial" in frf.axes else 0
    h = frf.h1[near, ax_i]
    what = f"{'measured FRF' if frf.measured else 'H1'} at {frf.angle_deg[near]:g}°, {frf.axes[ax_i]}"
    ax.semilogy(f[band], mag[band], color="k", lw=1.1, label=f"rms |H| over {len(frf.angle_deg)} angles × "
                                                           f"{len(frf.axes)} axes")
    ax.semilogy(f[band], np.abs(h[band]), color="tab:purple", lw=0.8, alpha=0.8, label=f"|H| {what}")
    t = result.table
    rows = _stagger(t.freq_hz, 0.028 * (f_range[1] - f_range[0]))
    for i in range(len(t)):
        k = int(np.argmin(np.abs(f - t.freq_hz[i])))
        ax.plot(f[k], mag[k], "v", color="tab:red" if t.kind[i] == "structural" else "tab:green", ms=6)
        ax.annotate(_mode_label(t, i), (f[k], mag[k]), textcoords="offset points", xytext=(0, 7 + 10 * rows[i]),
                    ha="center", fontsize=7)
    if np.isfinite(frf.coherence).any():
        ax2 = ax.twinx()
        coh = np.nanmean(frf.coherence, axis=(0, 1))
        ax2.plot(f[band], coh[band], color="tab:blue", lw=0.6, alpha=0.6, label="mean coherence")
        ax2.set_ylim(0, 1.05)
        ax2.set_ylabel("mean coherence [-]", color="tab:blue")
        ax2.legend(loc="lower right", fontsize=7)
    ax.set_ylabel("|H| accelerance [(m/s²)/N]")
    ax.legend(loc="lower left", fontsize=7)
    ax.grid(alpha=0.3, which="both")
    ax.set_title(f"FRF peak picking ({result.info.get('indicator', '?')} indicator): {len(t)} modes", fontsize=10,
                 pad=8 + 10 * (int(rows.max()) if len(t) else 0))
    axp.plot(f[band], np.degrees(np.angle(h[band])) % 360.0, color="tab:purple", lw=0.8)  # 0-360: no flicker at ±180
    axp.set_ylim(-5, 365)
    axp.set_yticks([0, 90, 180, 270, 360])
    axp.set_ylabel(f"phase [deg]\n({what})", fontsize=8)
    axp.set_xlabel("frequency [Hz]")
    axp.grid(alpha=0.3)
    axp.set_xlim(*f_range)
    fig.tight_layout()
    return fig
