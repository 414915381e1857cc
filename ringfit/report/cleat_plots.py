"""Plots of cleat tests: coverage of the angle–time plane, polar snapshots and animations.

* :func:`plot_coverage` — the samples of the first passes in polar
  coordinates, angle = sensor angle, radius = time since the cleat's arrival
  (the source's figure 23), one panel per number of passes.
* :func:`plot_polar_snapshots` — radial acceleration around the tyre at
  chosen instants after the impact (the source's figure 37), one polar panel each.
* :func:`animate_field` — the same as a GIF (matplotlib ``PillowWriter``).

Orientation as in the source: the patch centre at the bottom, the tyre
rolling to the left and turning anticlockwise, so the leading edge (φ < 0)
is left of the bottom. A point at angle φ is drawn at radius
``r0 + a(φ, τ)/scale`` (acceleration toward the wheel centre pulls inward).
matplotlib is imported inside each function (Agg backend).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ringfit.io.record_types import Axis
from ringfit.report.figures import pyplot
from ringfit.units import GRAVITY as G


def _orient(ax):
    ax.set_theta_zero_location("S")
    ax.set_theta_direction(1)


def plot_coverage(phi_tau_by_passes: dict, path=None, *, title: str = ""):
    """Figure 23: samples of the first passes on the (angle, time) plane.

    **Arguments:** ``phi_tau_by_passes`` maps a number of passes to ``(phi_deg,
    tau_s)`` arrays (from :func:`ringfit.targets.cleat.coverage_points`);
    ``path`` — write a PNG there (else return the figure).
    """
    plt = pyplot()
    k = len(phi_tau_by_passes)
    fig, axes = plt.subplots(1, k, subplot_kw={"projection": "polar"}, figsize=(4.2 * k, 4.4), squeeze=False)
    for ax, (passes, (phi, tau)) in zip(axes[0], phi_tau_by_passes.items()):
        _orient(ax)
        ax.scatter(np.radians(phi), 1e3 * tau, s=0.3, lw=0, c="k")
        ax.set_title(f"{passes} cleat passes", fontsize=10)
        ax.set_rlabel_position(90)
        ax.tick_params(labelsize=7)
    fig.suptitle(title or "samples in the angle–time plane (radius: ms after the cleat's arrival)", fontsize=10)
    fig.tight_layout()
    return _finish(fig, path)


def _polar_curve(field, axis, index, scale, r0):
    a = field.channel(axis)[:, index]
    phi = np.radians(field.sector_deg)
    ok = np.isfinite(a)
    a = np.interp(phi, phi[ok], a[ok], period=2 * np.pi) if ok.any() else np.zeros_like(phi)
    phi = np.append(phi, phi[0] + 2 * np.pi)
    a = np.append(a, a[0])
    return phi, r0 + a / scale


#: Default end of the window [s] that sets the common scale of snapshots and animation.
SCALE_WINDOW_S = 0.1


def field_scale(field, axis: Axis = "radial", tau_max_s: float | None = None) -> float:
    """m/s² per unit radius shared by :func:`plot_polar_snapshots` and :func:`animate_field`.

    The 99.5 % peak of |a| over τ ≤ ``tau_max_s`` (default
    min(field length, :data:`SCALE_WINDOW_S`)) moves the curve by 80 % of the
    reference radius, so that snapshots and animation of one field look alike.
    """
    tau_max = min(float(field.tau_s[-1]), SCALE_WINDOW_S) if tau_max_s is None else float(tau_max_s)
    a = field.channel(axis)[:, field.tau_s <= tau_max]
    peak = np.nanpercentile(np.abs(a), 99.5) if np.isfinite(a).any() else 1.0
    return max(peak, 1e-9) / 0.8


def _frame(ax, scale):
    """Polar axes in the patch-down orientation: reference circle (no acceleration), patch centre, φ ticks."""
    _orient(ax)
    ring = np.linspace(0, 2 * np.pi, 361)
    ax.plot(ring, np.ones_like(ring), color="k", lw=0.9, ls="--", zorder=1, label="no acceleration")
    ax.plot([0.0], [2.0], marker="^", color="tab:red", ms=9, clip_on=False, zorder=3)
    ax.annotate("contact patch (φ = 0)", (0.0, 2.0), xytext=(0, -16), textcoords="offset points", ha="center",
                va="top", fontsize=7, color="tab:red")
    ax.set_ylim(0, 2.0)
    ax.set_yticks([0.5, 1.0, 1.5], [])
    ticks = np.arange(0, 360, 45)
    phi = (ticks + 180) % 360 - 180
    ax.set_xticks(np.radians(ticks), [f"{p:+d}°" if p not in (0, -180) else f"{abs(p)}°" for p in phi], fontsize=7)
    ax.set_thetalim(0, 2 * np.pi)
    ax.grid(alpha=0.25)


def plot_polar_snapshots(field, times_s, path=None, *, axis: Axis = "radial", scale: float | None = None,
                         ncols: int = 3, baseline=None):
    """Figure 37: radial acceleration around the tyre at chosen times after the impact.

    **Arguments:** ``field`` an :class:`~ringfit.targets.cleat.AngleTimeField`;
    ``times_s`` instants [s]; ``scale`` m/s² per unit radius (default
    :func:`field_scale`, the same as the animation's); ``baseline`` optional
    (S,) reading added back (the source's figure shows the static pattern
    too); ``path`` PNG output. Each panel: the dashed reference circle is zero
    acceleration, the patch centre φ = 0 at the bottom, angles φ from it.
    """
    plt = pyplot()
    times_s = list(times_s)
    ncols = min(ncols, len(times_s))
    nrows = -(-len(times_s) // ncols)
    scale = scale or field_scale(field, axis)
    fig, axes = plt.subplots(nrows, ncols, subplot_kw={"projection": "polar"}, figsize=(3.6 * ncols, 3.7 * nrows),
                             squeeze=False)
    for ax in axes.ravel()[len(times_s):]:
        ax.set_visible(False)
    for ax, t in zip(axes.ravel(), times_s):
        i = int(np.clip(np.round(t / field.time_step_s), 0, field.tau_s.size - 1))
        phi, r = _polar_curve(field, axis, i, scale, 1.0)
        if baseline is not None:
            r = r + np.append(baseline, baseline[0]) / scale
        _frame(ax, scale)
        ax.plot(phi, r, lw=1.2, color="tab:blue", zorder=2)
        ax.set_title(f"τ = {1e3 * field.tau_s[i]:.1f} ms after the cleat's arrival", fontsize=9)
    fig.suptitle(f"{axis} acceleration around the tyre after the cleat impact — radius = 1 + a / {scale:.3g} m/s² "
                 f"({scale / G:.3g} g per unit; inward reading pulls inward); dashed circle: a = 0", fontsize=9)
    fig.tight_layout()
    return _finish(fig, path)


def animate_field(field, path, *, axis: Axis = "radial", tau_max_s: float | None = None, frames: int = 120,
                  fps: int = 15, scale: float | None = None) -> Path:
    """Polar animation (GIF) of the acceleration around the tyre after the cleat impact.

    **Arguments:** ``tau_max_s`` end of the animation (default the whole
    field); ``frames`` frames spread evenly over [0, tau_max]; ``fps``;
    ``scale`` as in :func:`plot_polar_snapshots`. Writes ``path`` (via a
    temporary file, so no partial GIF is left) and returns it.
    """
    plt = pyplot()
    from matplotlib.animation import FuncAnimation, PillowWriter

    from ringfit.io.files import atomic_write

    tau_max = float(field.tau_s[-1] if tau_max_s is None else tau_max_s)
    idx = np.unique(np.clip(np.round(np.linspace(0, tau_max, frames) / field.time_step_s).astype(int), 0,
                            field.tau_s.size - 1))
    scale = scale or field_scale(field, axis)
    fig = plt.figure(figsize=(4.8, 5.2))
    ax = fig.add_subplot(projection="polar")
    _frame(ax, scale)
    (line,) = ax.plot([], [], lw=1.2, color="tab:blue", zorder=2)
    title = ax.set_title("", fontsize=9)
    fig.text(0.5, 0.02, f"radius = 1 + a / {scale:.3g} m/s² ({scale / G:.3g} g per unit); dashed circle: a = 0",
             ha="center", fontsize=7)

    def update(i):
        phi, r = _polar_curve(field, axis, i, scale, 1.0)
        line.set_data(phi, r)
        title.set_text(f"{axis} acceleration, τ = {1e3 * field.tau_s[i]:6.2f} ms after the cleat")
        return line, title

    anim = FuncAnimation(fig, update, frames=idx, blit=False)
    path = Path(path)
    atomic_write(path, lambda tmp: _save_gif(anim, tmp, fps, PillowWriter))
    plt.close(fig)
    return path


def _save_gif(anim, tmp, fps, writer):
    gif = Path(str(tmp) + ".gif")  # PillowWriter picks the format from the suffix
    try:
        anim.save(str(gif), writer=writer(fps=fps))
        gif.replace(tmp)
    finally:
        if gif.exists():
            gif.unlink()


def plot_field_map(field, path=None, *, axis: Axis = "radial", tau_max_s: float | None = None):
    """The field as an image: sector angle (x) × time since arrival (y) [m/s²]."""
    plt = pyplot()
    tau_max = float(field.tau_s[-1] if tau_max_s is None else tau_max_s)
    sel = field.tau_s <= tau_max
    a = field.channel(axis)[:, sel]
    lim = np.nanpercentile(np.abs(a), 99) if np.isfinite(a).any() else 1.0
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    im = ax.imshow(a.T, origin="lower", aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim,
                   extent=[-180, 180, 0, 1e3 * tau_max])
    ax.set_xlabel("sensor angle from the patch centre [deg]")
    ax.set_ylabel("time since the cleat's arrival [ms]")
    fig.colorbar(im, ax=ax, label=f"{axis} acceleration [m/s²]")
    fig.tight_layout()
    return _finish(fig, path)


def plot_stabilization(modes, path=None, *, f_max: float | None = None):
    """Stabilization diagram of :func:`ringfit.targets.rolling_modes.identify_rolling_modes` (order vs frequency)."""
    plt = pyplot()
    poles, stab = modes.poles, modes.stability
    fig, ax = plt.subplots(figsize=(7, 4))
    lab = stab.label
    for value, marker, color, name in ((0, ".", "0.7", "new"), (1, "o", "tab:orange", "f, shape stable"),
                                       (2, "s", "tab:blue", "f, ζ, shape stable")):
        sel = lab == value
        ax.scatter(poles.freq_hz[sel], poles.order[sel], s=8 if value else 3, marker=marker,
                   facecolors="none" if value else color, edgecolors=color, lw=0.7, label=name)
    for f in modes.table.freq_hz:
        ax.axvline(f, color="k", lw=0.4, alpha=0.5)
    if f_max:
        ax.set_xlim(0, f_max)
    ax.set_xlabel("frequency, fixed frame [Hz]")
    ax.set_ylabel("model order")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    return _finish(fig, path)


def _finish(fig, path):
    if path is None:
        return fig
    from ringfit.io.files import atomic_write

    import matplotlib.pyplot as plt

    path = Path(path)
    fmt = path.suffix.lstrip(".") or "png"
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format=fmt))
    plt.close(fig)
    return path
