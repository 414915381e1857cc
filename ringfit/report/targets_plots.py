"""Plots of the modal identification: stabilization diagram, polar mode shapes, FRF with peaks.

The stabilization diagram uses the source's symbols (seed §2.5, figure 2):
small squares where frequency and damping are stable, circles where only the
frequency is; frequency on the horizontal axis, model order on the vertical.
Mode shapes are drawn on a circle as in the source's figures 25–26: the
undeformed tyre plus radial and tangential deflections. matplotlib is
imported inside each function (Agg backend).
"""

from __future__ import annotations

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_stabilization(result, *, f_range=(0.0, 400.0), ax=None, source_symbols: bool = False):
    """Stabilization diagram of an SSI :class:`~ringfit.targets.identify.ModeIdentification`.

    Squares: frequency, damping (and shape) stable; circles: frequency (and
    shape) stable only; ``source_symbols=True`` ignores the shape check, as
    the source did. Identified modes are marked by vertical lines labelled
    with n (``ac`` for acoustic candidates). **Returns:** the figure.
    """
    plt = _plt()
    fig, ax = (plt.subplots(figsize=(9, 5)) if ax is None else (ax.figure, ax))
    poles, stab = result.poles, result.stability
    label = stab.source_label if source_symbols else stab.label
    band = (poles.freq_hz >= f_range[0]) & (poles.freq_hz <= f_range[1])
    sq, ci = band & (label == 2), band & (label == 1)
    ax.plot(poles.freq_hz[sq], poles.order[sq], "s", ms=3, mfc="none", mec="tab:blue", label="freq. & damping stable")
    ax.plot(poles.freq_hz[ci], poles.order[ci], "o", ms=3, mfc="none", mec="tab:orange", label="freq. stable")
    t = result.table
    for i in range(len(t)):
        ax.axvline(t.freq_hz[i], color="0.6", lw=0.6, zorder=0)
        txt = "ac" if t.kind[i] == "acoustic" else f"n={t.n[i]}"
        ax.text(t.freq_hz[i], poles.orders[-1] * 1.02, txt, rotation=90, ha="center", va="bottom", fontsize=7)
    ax.set_xlim(*f_range)
    ax.set_xlabel("f_n (Hz)")
    ax.set_ylabel("Model order")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    return fig


def plot_mode_shapes(result, *, rows=None, scale: float = 0.25, real: str = "principal", cols: int = 3):
    """Polar plots of the identified shapes around the tyre (radial and tangential).

    **Arguments:** ``rows`` table rows to draw (default all); ``scale`` the
    largest deflection as a fraction of the radius; ``real``: ``"principal"``
    (most-real rotation) or ``"source"`` (v_r = sign(Im v)|v|).
    **Returns:** the figure.
    """
    from ringfit.targets.shapes import real_shape_principal, real_shape_source

    plt = _plt()
    t = result.table
    rows = list(range(len(t))) if rows is None else list(rows)
    nrow = int(np.ceil(len(rows) / cols))
    fig, axes = plt.subplots(nrow, cols, figsize=(3 * cols, 3 * nrow), subplot_kw={"projection": "polar"}, squeeze=False)
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
        kind = "acoustic" if t.kind[i] == "acoustic" else f"n = {t.n[i]}"
        ax.set_title(f"{kind}, {t.freq_hz[i]:.1f} Hz", fontsize=9)
    fig.tight_layout()
    return fig


def plot_frf(result, *, f_range=(0.0, 400.0), ax=None):
    """Summed FRF magnitude (accelerance) with the picked peaks, from an FRF identification. **Returns:** the figure."""
    plt = _plt()
    fig, ax = (plt.subplots(figsize=(9, 4.5)) if ax is None else (ax.figure, ax))
    frf = result.frf
    f = frf.freq_hz
    band = (f >= f_range[0]) & (f <= f_range[1])
    mag = np.sqrt(np.mean(np.abs(frf.h1) ** 2, axis=(0, 1)))
    ax.semilogy(f[band], mag[band], color="k", lw=1, label="rms |H1| over angles and axes")
    coh = np.mean(frf.coherence, axis=(0, 1))
    t = result.table
    for i in range(len(t)):
        k = int(np.argmin(np.abs(f - t.freq_hz[i])))
        ax.plot(f[k], mag[k], "v", color="tab:red" if t.kind[i] == "structural" else "tab:green", ms=7)
        txt = "ac" if t.kind[i] == "acoustic" else f"n={t.n[i]}"
        ax.annotate(txt, (f[k], mag[k]), textcoords="offset points", xytext=(0, 8), ha="center", fontsize=8)
    ax2 = ax.twinx()
    ax2.plot(f[band], coh[band], color="tab:blue", lw=0.6, alpha=0.6)
    ax2.set_ylim(0, 1.05)
    ax2.set_ylabel("mean coherence", color="tab:blue")
    ax.set_xlabel("f (Hz)")
    ax.set_ylabel("|H1| (m/s² / N)")
    ax.set_xlim(*f_range)
    fig.tight_layout()
    return fig


def plot_ssi_summary(result, *, f_range=(0.0, 400.0)):
    """The figure `ringfit ssi --plot` writes (placeholder: the stabilization diagram)."""
    return plot_stabilization(result, f_range=f_range)
