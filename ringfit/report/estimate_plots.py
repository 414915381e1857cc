"""Figures of a load estimate (``ringfit estimate``): the fit to the radial reading, the load against time.

Each function returns a matplotlib Figure (Agg backend via :func:`ringfit.report.figures.new_figure`).
"""

from __future__ import annotations

import numpy as np

from ringfit.report.figures import new_figure

from ringfit.units import GRAVITY as G


def draw_profile_fit(ax_fit, ax_res, est) -> None:
    """The radial reading and the model at the estimate, both in the fitted band (k = 2…k_max), and the residual.

    ``est``: a :class:`ringfit.fit.estimate.LoadEstimate`; the patch edges of the model are marked
    at the recorded angle (φ − angle offset).
    """
    angle = np.asarray(est.angle_deg)
    order = np.argsort(angle)
    offset = est.nuisances["angle_offset_deg"]["value"]
    ax_fit.plot(angle[order], np.asarray(est.measured)[order] / G, color="C1", lw=0.9, label="measured (band)")
    ax_fit.plot(angle[order], np.asarray(est.model)[order] / G, color="C0", lw=1.0, label="model at the estimate")
    for edge in (est.patch["leading_deg"], est.patch["trailing_deg"]):
        ax_fit.axvline(edge - offset, color="k", lw=0.6, ls="--")
    ax_fit.set_ylabel("radial reading [g]")
    ax_fit.set_title(f"load {est.load_n:.0f} N (95 %: {est.lo:.0f} … {est.hi:.0f}); patch "
                     f"{est.patch['length_mm']:.1f} mm (dashed: edges); harmonics 2…{est.k_max}", fontsize=9)
    ax_fit.legend(fontsize=8, loc="lower right")
    ax_fit.grid(alpha=0.3)
    ax_res.plot(angle[order], (np.asarray(est.measured) - np.asarray(est.model))[order] / G, color="C3", lw=0.7)
    ax_res.set_ylabel("residual [g]")
    ax_res.set_xlabel("recorded sensor angle [deg]")
    ax_res.set_title(f"residual RMS {est.rms:.3g} m/s², noise {est.noise:.3g} m/s²", fontsize=9)
    ax_res.grid(alpha=0.3)
    for ax in (ax_fit, ax_res):
        ax.set_xlim(-90, 90)


def draw_load_against_time(ax, revs, est=None) -> None:
    """Per-revolution load [kN] against time with its 95 % band; the feature method as dots; the averaged
    profile's estimate as a line (``est``)."""
    t = np.asarray(revs.t_s)
    ok = np.asarray(revs.converged, dtype=bool)
    load = np.asarray(revs.load_n, dtype=np.float64)
    # the axis spans the accepted revolutions' loads (and their finite bands, within ±50 % of them):
    # an unbounded or huge interval, or a rejected revolution at a bound, must not flatten the plot
    good = load[ok & np.isfinite(load)]
    if good.size:
        span = max(float(good.max() - good.min()), 0.05 * float(np.median(good)))
        y_lo, y_hi = float(good.min()) - span, float(good.max()) + span
    else:
        y_lo, y_hi = 0.0, 1e4
    lo = np.clip(np.where(np.isfinite(revs.lo), revs.lo, y_lo), y_lo, y_hi)
    hi = np.clip(np.where(np.isfinite(revs.hi), revs.hi, y_hi), y_lo, y_hi)
    lo, hi = np.where(ok, lo, np.nan), np.where(ok, hi, np.nan)
    ax.fill_between(t, lo / 1e3, hi / 1e3, color="C0", alpha=0.3, lw=0, label="95 % interval (clipped)")
    ax.plot(t, np.where(ok, load, np.nan) / 1e3, color="C0", lw=1.0, label="model fit per revolution")
    if (~ok).any():
        ax.plot(t[~ok], np.clip(load[~ok], y_lo, y_hi) / 1e3, "x", color="C3", ms=4,
                label=f"rejected ({int((~ok).sum())}: not converged, on a bound or an outlier)")
    ax.set_ylim(y_lo / 1e3, y_hi / 1e3)
    feat = np.asarray(revs.feature_load_n)
    ax.plot(t, feat / 1e3, ".", color="C2", ms=2, label="edge-peak feature method")
    if est is not None:
        ax.axhline(est.load_n / 1e3, color="k", lw=0.7, ls=":", label="averaged profile")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("wheel load [kN]")
    ax.set_title(f"load per revolution ({len(revs)} revolutions)", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)


def estimate_figure(est, revs=None, *, title: str = ""):
    """The fit (and, for a recording, the load against time) of a load estimate.

    **Arguments:** ``est`` :class:`ringfit.fit.estimate.LoadEstimate`; ``revs``
    :class:`ringfit.fit.estimate.RevolutionEstimates` or None; ``title``.
    """
    rows = 3 if revs is not None else 2
    fig, axes = new_figure(rows, 1, figsize=(9, 2.8 * rows + 0.4), squeeze=False,
                           gridspec_kw={"height_ratios": [2, 1] + ([2] if revs is not None else [])})
    draw_profile_fit(axes[0, 0], axes[1, 0], est)
    if revs is not None:
        draw_load_against_time(axes[2, 0], revs, est)
    fig.suptitle(f"load estimate{': ' + title if title else ''}")
    fig.tight_layout()
    return fig


#: The state quantities plotted against time (docs/formats.md §7.1), in panel order.
STATE_PANELS = ("load_n", "pressure_bar", "fx_n", "slip", "speed_kmh", "tread_depth_mm")


def state_figure(state, revs=None, *, title: str = ""):
    """The tyre's state (docs/physics.md §13): for a recording each quantity against time with its 95 % band and the
    averaged profile's estimate (dotted, its interval shaded grey); for a profile each quantity's value and interval.

    **Arguments:** ``state`` :class:`ringfit.fit.estimate.StateEstimate`; ``revs``
    :class:`ringfit.fit.estimate.StateRevolutions` or None; ``title``.
    """
    keys = [k for k in STATE_PANELS if k in state.quantities]
    fig, axes = new_figure(len(keys), 1, figsize=(9, 1.9 * len(keys) + 0.6), squeeze=False, sharex=revs is not None)
    for ax, key in zip(axes[:, 0], keys):
        q = state.quantities[key]
        label = f"{key} [{q['unit']}]"
        if revs is not None:
            t = np.asarray(revs.t_s)
            ax.fill_between(t, revs.lo[key], revs.hi[key], color="C0", alpha=0.3, lw=0, label="95 % per revolution")
            ax.plot(t, revs.values[key], color="C0", lw=0.9, label="per revolution")
            ax.axhspan(q["lo"], q["hi"], color="0.5", alpha=0.2, lw=0)
            ax.axhline(q["value"], color="k", lw=0.7, ls=":", label="averaged profile")
        else:
            ax.errorbar([0.0], [q["value"]], yerr=[[q["value"] - q["lo"]], [q["hi"] - q["value"]]], fmt="o",
                        color="C0", capsize=4)
            ax.set_xticks([])
        ax.set_ylabel(label, fontsize=8)
        ax.set_title(f"{q['what']}: {q['value']:.4g} (95 %: {q['lo']:.4g} … {q['hi']:.4g}) — {q['status']}", fontsize=8)
        ax.grid(alpha=0.3)
    if revs is not None:
        axes[-1, 0].set_xlabel("time [s]")
        axes[0, 0].legend(fontsize=7, loc="upper right")
    fig.suptitle(f"tyre state{': ' + title if title else ''}")
    fig.tight_layout()
    return fig


__all__ = ["estimate_figure", "draw_profile_fit", "draw_load_against_time", "state_figure", "STATE_PANELS"]
