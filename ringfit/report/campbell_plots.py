"""Campbell diagram plot: the rolling tyre's branches against speed, measured rows overlaid (docs/physics.md §3.7).

One panel per frame shown: the requested frame, plus the other one when
measured rows were observed in it (a row is drawn only in the frame it was
observed in). Each branch is one unbroken curve of one colour, that of its
prevailing travelling direction (the branches are tracked by shape, so a
curve is one mode; in the sensor frame it is the branch's one principal line
ω + kΩ). Its dominant order n at the highest speed labels it on the right
edge, the labels spread so that none overlaps another (a thin leader joins a
moved label to its curve); measured rows are marked by their match status.
The legend (below the panel, so it hides no curve) names only the directions
drawn in that panel.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ringfit.report.figures import new_figure, save_figure

if TYPE_CHECKING:  # the physics (JAX) is imported on first use
    from ringfit.physics.campbell import FrameChoice

_DIRECTION_COLOUR = {"backward": "tab:blue", "forward": "tab:red", "standing": "0.45"}
_STATUS_STYLE = {
    "matched": dict(marker="o", color="tab:green", label="matched"),
    "label_conflict": dict(marker="^", color="tab:orange", label="label contradicts the branches"),
    "trend_conflict": dict(marker="D", color="tab:purple", label="speed trend contradicts the branches"),
    "unexplained": dict(marker="X", color="black", label="unexplained"),
}


def plot_campbell(diagram, path=None, *, frame: FrameChoice = "fixed", match=None, title: str = "",
                  f_max: float | None = None, overwrite: bool = True):
    """Draw a :class:`~ringfit.physics.campbell.CampbellDiagram` (and the rows of a ``CampbellMatch``).

    **Arguments:** ``frame`` — ``fixed`` or ``sensor``/``rotating``; ``match`` —
    optional :class:`~ringfit.gap.campbell.CampbellMatch` whose rows are overlaid;
    ``f_max`` — top of the frequency axis [Hz] (default: a little above the rows, or 400 Hz).

    **Returns:** the figure, or the path when ``path`` is given.
    """
    from ringfit.physics.campbell import frame_name

    frame = frame_name(frame)
    rows = list(match.rows) if match is not None else []
    frames = [frame] + [f for f in ("fixed", "rotating") if f != frame and any(r["frame"] == f for r in rows)]
    fig, axes = new_figure(1, len(frames), figsize=(6.5 * len(frames), 5.8), squeeze=False, layout="constrained")
    axes = axes[0]
    top = f_max or max([400.0] + [1.15 * r["freq_hz"] for r in rows])
    direction = diagram.branch_direction()
    v = diagram.speed_kmh
    bottom = 0.9 * max(0.0, float(np.nanmin(diagram.fixed_hz)))
    x_right = v[-1] + 0.08 * max(v[-1] - v[0], 10.0)
    for ax, fr in zip(axes, frames):
        f = diagram.frequencies(fr)
        labels = []
        drawn = set()  # the directions with a curve in this panel: only those get a legend entry
        for b in range(diagram.branches):
            if np.nanmin(f[:, b]) > top:
                continue
            colour = _DIRECTION_COLOUR[direction[b]]
            drawn.add(direction[b])
            ax.plot(v, f[:, b], color=colour, lw=1.1, alpha=0.85, marker="_" if len(v) == 1 else None, ms=12)
            if bottom <= f[-1, b] <= top:
                labels.append((float(f[-1, b]), f"{diagram.order[-1, b]}", colour))
        ax.set_ylim(bottom, top)
        _edge_labels(ax, labels, v[-1], x_right, (bottom, top))
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
            if name in drawn:
                ax.plot([], [], color=colour, lw=1.1, label=f"{name} branch")
        ax.set_xlim(v[0] - 1.0, x_right)
        ax.set_xlabel("speed [km/h]")
        ax.set_ylabel("frequency [Hz]")
        where = "fixed observer" if fr == "fixed" else "co-rotating sensor (each branch's principal line ω + kΩ)"
        ax.set_title(f"{where}", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncols=3)  # below: no curve hidden
    road = "flat road" if diagram.drum_diameter_m is None else f"drum {diagram.drum_diameter_m:g} m"
    load = f"{diagram.load_n:g} N, {road}" if diagram.contact else "free spinning ring"
    fig.suptitle(title or f"Campbell diagram of the rolling tyre ({load}); labels: dominant order n", fontsize=11)
    if path is None:
        return fig
    return save_figure(fig, path, overwrite=overwrite)


#: Smallest vertical distance between two edge labels, as a share of the axis height.
LABEL_GAP = 0.028


def spread_labels(y, lo: float, hi: float, gap: float) -> np.ndarray:
    """Label positions near ``y`` within [lo, hi], every two at least ``gap`` apart, in the order of ``y``.

    Overlapping labels are pushed apart as little as possible: clusters of labels closer than
    ``gap`` are spaced by ``gap`` around their mean and merged with neighbouring clusters until
    none overlap, within [lo, hi] (the least-squares placement under the order, gap and axis
    constraints: isotonic regression of ``y_i − i·gap``, clipped); labels that need more room than
    the axis has keep the gap and start at lo.
    """
    y = np.asarray(y, dtype=np.float64)
    order = np.argsort(y, kind="stable")
    ys = y[order]
    # pool-adjacent-violators on z_i = y_i - i·gap (non-decreasing z means gaps of at least `gap`)
    z = ys - gap * np.arange(ys.size)
    blocks: list[list[float]] = []  # [sum, count]
    for val in z:
        blocks.append([val, 1.0])
        while len(blocks) > 1 and blocks[-2][0] / blocks[-2][1] > blocks[-1][0] / blocks[-1][1]:
            s2, c2 = blocks.pop()
            blocks[-1][0] += s2
            blocks[-1][1] += c2
    fitted = np.concatenate([np.full(int(c), s_ / c) for s_, c in blocks]) if blocks else z
    # the axis as bounds: clipping the isotonic solution is the bounded one (if the labels fit at all)
    fitted = np.clip(fitted, lo, max(lo, hi - gap * (ys.size - 1)))
    pos = fitted + gap * np.arange(ys.size)
    out = np.empty_like(pos)
    out[order] = pos
    return out


def _edge_labels(ax, labels, x_end, x_right, ylim) -> None:
    """Each branch's n at the right edge, spread by :func:`spread_labels`; a leader where a label moved."""
    if not labels:
        return
    lo, hi = ylim
    gap = LABEL_GAP * (hi - lo)
    y = np.array([lab[0] for lab in labels])
    pos = spread_labels(y, lo + 0.5 * gap, hi - 0.5 * gap, gap)
    x_text = x_end + 0.45 * (x_right - x_end)
    for (yi, text, colour), yp in zip(labels, pos):
        moved = abs(yp - yi) > 0.1 * gap
        ax.annotate(text, (x_end, yi), xytext=(x_text, yp), textcoords="data", fontsize=7, va="center",
                    ha="left", color=colour, annotation_clip=False,
                    arrowprops=dict(arrowstyle="-", lw=0.4, color=colour, alpha=0.6, shrinkA=0, shrinkB=1)
                    if moved else None)


__all__ = ["plot_campbell", "spread_labels"]
