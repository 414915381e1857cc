"""Campbell diagram plot: the rolling tyre's branches against speed, measured rows overlaid (docs/physics.md §3.7).

One panel per frame shown: the requested frame, plus the other one when
measured rows were observed in it (a row is drawn only in the frame it was
observed in). Branches are coloured by their travelling direction (the
direction can change along a branch where rotation and contact mix the
waves) and labelled with their dominant order n at the highest speed;
measured rows are marked by their match status.
"""

from __future__ import annotations

import numpy as np

from ringfit.report.figures import new_figure, save_figure

_DIRECTION_COLOUR = {"backward": "tab:blue", "forward": "tab:red", "standing": "0.45"}
_STATUS_STYLE = {
    "matched": dict(marker="o", color="tab:green", label="matched"),
    "label_conflict": dict(marker="^", color="tab:orange", label="label contradicts the branches"),
    "trend_conflict": dict(marker="D", color="tab:purple", label="speed trend contradicts the branches"),
    "unexplained": dict(marker="X", color="black", label="unexplained"),
}


def plot_campbell(diagram, path=None, *, frame: str = "fixed", match=None, title: str = "", f_max: float | None = None,
                  overwrite: bool = True):
    """Draw a :class:`~ringfit.gap.campbell.CampbellDiagram` (and the rows of a ``CampbellMatch``).

    **Arguments:** ``frame`` — ``fixed`` or ``sensor``/``rotating``; ``match`` —
    optional :class:`~ringfit.gap.campbell.CampbellMatch` whose rows are overlaid;
    ``f_max`` — top of the frequency axis [Hz] (default: a little above the rows, or 400 Hz).

    **Returns:** the figure, or the path when ``path`` is given.
    """
    from ringfit.gap.campbell import frame_name

    frame = frame_name(frame)
    rows = list(match.rows) if match is not None else []
    frames = [frame] + [f for f in ("fixed", "rotating") if f != frame and any(r["frame"] == f for r in rows)]
    fig, axes = new_figure(1, len(frames), figsize=(6.5 * len(frames), 5.2), squeeze=False)
    axes = axes[0]
    top = f_max or max([400.0] + [1.15 * r["freq_hz"] for r in rows])
    direction = diagram.direction()
    v = diagram.speed_kmh
    for ax, fr in zip(axes, frames):
        f = diagram.frequencies(fr)
        for b in range(diagram.branches):
            if np.nanmin(f[:, b]) > top:
                continue
            for s in range(len(v) - 1):  # colour each segment by the direction at its start
                ax.plot(v[s:s + 2], f[s:s + 2, b], color=_DIRECTION_COLOUR[direction[s, b]], lw=1.1, alpha=0.85)
            if len(v) == 1:
                ax.plot(v, f[:, b], "_", color=_DIRECTION_COLOUR[direction[0, b]], ms=12)
            if f[-1, b] <= top:
                ax.annotate(f"{diagram.order[-1, b]}", (v[-1], f[-1, b]), xytext=(3, 0), textcoords="offset points",
                            fontsize=7, va="center", color=_DIRECTION_COLOUR[direction[-1, b]])
        if fr == "rotating":  # secondary lines ω + kΩ of each branch (≥ 20 % of the mode's strongest line)
            w = np.nan_to_num(diagram.line_weight)
            strong = w >= 0.2 * w.max(axis=-1, keepdims=True)
            main = w >= w.max(axis=-1, keepdims=True)
            s_idx, b_idx, k_idx = np.nonzero(strong & ~main)
            ax.scatter(v[s_idx], np.abs(diagram.line_hz[s_idx, b_idx, k_idx]), s=3, color="0.6", zorder=1,
                       label="secondary lines ω + kΩ (≥ 20 %)")
        for status, style in _STATUS_STYLE.items():
            sel = [r for r in rows if r["frame"] == fr and r["status"] == status]
            if sel:
                ax.scatter([r["speed_kmh"] for r in sel], [r["freq_hz"] for r in sel], s=38, zorder=5,
                           edgecolor="white", linewidth=0.6, **style)
        for name, colour in _DIRECTION_COLOUR.items():
            ax.plot([], [], color=colour, label=f"{name} branch")
        ax.set_ylim(0.9 * max(0.0, np.nanmin(diagram.fixed_hz)), top)
        ax.set_xlim(v[0] - 1.0, v[-1] + 0.08 * max(v[-1] - v[0], 10.0))
        ax.set_xlabel("speed [km/h]")
        ax.set_ylabel("frequency [Hz]")
        where = "fixed observer" if fr == "fixed" else "co-rotating sensor (strongest line ω + kΩ)"
        ax.set_title(f"{where}", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper left")
    road = "flat road" if diagram.drum_diameter_m is None else f"drum {diagram.drum_diameter_m:g} m"
    load = f"{diagram.load_n:g} N, {road}" if diagram.contact else "free spinning ring"
    fig.suptitle(title or f"Campbell diagram of the rolling tyre ({load}); labels: dominant order n", fontsize=11)
    if path is None:
        return fig
    return save_figure(fig, path, overwrite=overwrite)


__all__ = ["plot_campbell"]
