"""Figures for the free-tyre fit: data vs model, corner plot, identifiability, traces.

Each function returns a matplotlib Figure (Agg backend, imported lazily).
"""

from __future__ import annotations

import numpy as np

from ringfit.report.figures import blank_figure, new_figure

SYMBOLS = {"rho_a": "ρA", "ei": "EI", "kw": "k_w", "kv": "k_v", "damping_ratio": "ζ", "k_tread": "k_tread",
           "ea": "EA", "chi": "χ"}
UNITS = {"rho_a": "kg/m", "ei": "N m²", "kw": "N/m²", "kv": "N/m²", "damping_ratio": "-", "k_tread": "N/m²",
         "ea": "N", "chi": "-"}
#: Axis label of each ring parameter: symbol and unit.
LABELS = {k: f"{SYMBOLS[k]} [{UNITS[k]}]" for k in SYMBOLS}


def modes_figure(n, freq_hz, sigma_hz, lsq_hz=None, predictive=None, credible=None, other=None):
    """Measured vs fitted natural frequency per mode, with residuals.

    **Arguments:** ``n``, ``freq_hz``, ``sigma_hz``: data ``(m,)``; ``lsq_hz``:
    least-squares model ``(m,)``; ``predictive``/``credible``: dicts with ``n``,
    ``lo``, ``median``, ``hi`` ``(p,)`` (95 % posterior predictive / credible
    band); ``other``: label -> ``(m,)`` frequencies of another model (e.g. Table 9).
    """
    fig, (ax, axr) = new_figure(2, 1, figsize=(7.5, 6.5), sharex=True, height_ratios=(2.2, 1))
    if predictive is not None:
        ax.fill_between(predictive["n"], predictive["lo"], predictive["hi"], color="C0", alpha=0.18,
                        label="95 % posterior predictive")
        ax.plot(predictive["n"], predictive["median"], "-", color="C0", lw=1, label="posterior median")
    ax.errorbar(n, freq_hz, yerr=sigma_hz, fmt="ko", ms=4, capsize=3, label="measured ± σ")
    if lsq_hz is not None:
        ax.plot(n, lsq_hz, "s", mfc="none", color="C3", label="least squares")
    for i, (label, f) in enumerate((other or {}).items()):
        ax.plot(n, f, "x", color=f"C{i + 4}", label=label)
    ax.set_ylabel("natural frequency [Hz]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ref = np.interp(n, predictive["n"], predictive["median"]) if predictive is not None else lsq_hz
    if predictive is not None:
        band_n = predictive["n"]
        axr.fill_between(band_n, predictive["lo"] - predictive["median"], predictive["hi"] - predictive["median"],
                         color="C0", alpha=0.18)
    axr.errorbar(n, freq_hz - ref, yerr=sigma_hz, fmt="ko", ms=4, capsize=3)
    if lsq_hz is not None:
        axr.plot(n, lsq_hz - ref, "s", mfc="none", color="C3")
    for i, (label, f) in enumerate((other or {}).items()):
        axr.plot(n, np.asarray(f) - ref, "x", color=f"C{i + 4}")
    axr.axhline(0, color="0.5", lw=0.8)
    axr.set_xlabel("circumferential index n")
    axr.set_ylabel("minus posterior median [Hz]")
    axr.grid(alpha=0.3)
    fig.tight_layout()
    return fig


#: Parameters drawn on a log axis in the corner plot (their posterior spans decades when the data barely fix them).
LOG_AXES = ("ei", "ea")


def _prefix(values) -> tuple[float, str]:
    """(divisor, SI prefix) that puts the median of ``values`` in [0.1, 1000) for k, M, G (no offset text)."""
    med = float(np.nanmedian(np.abs(values))) if np.size(values) else 1.0
    for div, pre in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if med >= div:
            return div, pre
    return 1.0, ""


def corner_figure(samples, names, truths=None):
    """Corner plot of posterior draws ``(draws, k)`` (SI units) with the ``corner`` package.

    Stiffnesses are shown with an SI prefix (k_w in MN/m², ...) so no axis
    carries an offset text; EI (and EA) on a log axis; short titles
    (symbol = median and the 95 % interval) that fit their panel.
    """
    import corner

    samples = np.array(samples, dtype=np.float64)
    truths = None if truths is None else np.array(truths, dtype=np.float64)
    labels, titles, scales = [], [], []
    for j, k in enumerate(names):
        div, pre = (1.0, "") if k in LOG_AXES else _prefix(samples[:, j])
        samples[:, j] /= div
        if truths is not None:
            truths[j] /= div
        unit = UNITS.get(k, "")
        labels.append(f"{SYMBOLS.get(k, k)} [{pre}{unit}]" if unit != "-" else f"{SYMBOLS.get(k, k)} [-]")
        titles.append(SYMBOLS.get(k, k))
        scales.append("log" if k in LOG_AXES else "linear")
    size = 2.1 * len(names) + 0.8
    fig = blank_figure(figsize=(size, size))
    corner.corner(samples, labels=labels, truths=truths, fig=fig, axes_scale=scales,
                  quantiles=[0.025, 0.5, 0.975], show_titles=False, max_n_ticks=4,
                  label_kwargs={"fontsize": 9}, labelpad=0.12)
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    plain = FuncFormatter(lambda v, _: f"{v:.3g}")
    k = len(names)
    for j, title in enumerate(titles):  # median and 95 % interval to the digits the interval warrants
        lo, med, hi = np.quantile(samples[:, j], [0.025, 0.5, 0.975])
        fig.axes[j * k + j].set_title(corner_title(title, med, lo, hi), fontsize=8)
    for idx, ax in enumerate(fig.axes[: k * k]):
        row, col = divmod(idx, k)
        for axis, scale, lim, shown in ((ax.xaxis, ax.get_xscale(), ax.get_xlim(), row == k - 1),
                                        (ax.yaxis, ax.get_yscale(), ax.get_ylim(), col == 0 and row > 0)):
            if scale == "log":  # a few plainly written ticks per decade, where corner labels the axis
                decades = np.log10(max(lim) / max(min(lim), 1e-300))
                subs = (1, 2, 3, 4, 5, 6, 8) if decades <= 1 else ((1, 2, 5) if decades <= 2.5 else (1,))
                axis.set_major_locator(LogLocator(base=10, subs=subs))
                axis.set_major_formatter(plain if shown else NullFormatter())
                axis.set_minor_formatter(NullFormatter())
        ax.tick_params(which="both", labelsize=7)
    fig.suptitle("posterior of the ring parameters (median and 95 % interval in each title)", fontsize=9)
    fig.subplots_adjust(left=0.14, bottom=0.14, top=0.92, wspace=0.08, hspace=0.08)
    return fig


def corner_title(symbol: str, median: float, lo: float, hi: float) -> str:
    """``"ρA = 2.543 (2.457 – 2.678)"``: the median and its 95 % interval, each to the decimal place of the
    interval's narrower half-width's second significant digit (:func:`ringfit.report.numbers.fmt_interval`)."""
    from ringfit.report.numbers import fmt_interval

    m, a, b = fmt_interval(median, lo, hi)
    return f"{symbol} = {m}\n({a} – {b})"


#: Largest σ(log) a Fisher bar is drawn to; a longer bar is clipped there and marked with an arrow and its value.
FISHER_CLIP = 1e3


def identifiability_figure(ident, profile_name=None, prior=None):
    """Fisher eigen-spectrum (log-std per direction) and, if computed, a profile likelihood.

    ``ident``: :class:`ringfit.fit.identifiability.Identifiability`; ``prior``:
    optional LogNormal-like dict (median, sigma_ln) drawn on the profile panel.
    """
    has_profile = profile_name is not None and profile_name in ident.profiles
    fig, axes = new_figure(1, 2 if has_profile else 1, figsize=(10 if has_profile else 5.5, 3.8))
    axes = np.atleast_1d(axes)
    ax = axes[0]
    k = len(ident.names)
    full = np.asarray(ident.log_std, dtype=float)
    s = np.minimum(np.nan_to_num(full, nan=np.inf), FISHER_CLIP)
    ax.bar(np.arange(k), s, color=["C3" if x > 0.5 else "C0" for x in s])
    ax.set_yscale("log")
    for i in np.flatnonzero(~(full < FISHER_CLIP)):  # clipped bars: an arrow past the top and the true value
        value = "∞" if not np.isfinite(full[i]) else f"{full[i]:.2g}"
        ax.annotate(f"σ = {value}\n(clipped)", xy=(i, FISHER_CLIP), xytext=(i, FISHER_CLIP * 8), ha="center",
                    va="bottom", fontsize=7, arrowprops={"arrowstyle": "<|-", "color": "C3", "lw": 1.2},
                    gid="clipped-bar")
    if np.any(~(full < FISHER_CLIP)):
        ax.set_ylim(top=FISHER_CLIP * 200)
    ax.axhline(0.5, color="0.4", ls="--", lw=0.8)
    ax.set_xticks(np.arange(k))
    ax.set_xticklabels(["\n".join(f"{v:+.2f} {nm}" for v, nm in zip(vec, ident.names) if abs(v) > 0.3)
                        for vec in ident.eigenvectors.T], fontsize=7)
    ax.set_ylabel("σ of log-parameter combination")
    ax.set_title("Fisher information eigen-directions (data only)", fontsize=9)
    if has_profile:
        grid, chi2 = ident.profiles[profile_name]
        ax2 = axes[1]
        ax2.semilogx(grid, chi2 - np.min(chi2), "o-", ms=3, label="profile Δχ² (data only)")
        ax2.axhline(3.84, color="0.4", ls="--", lw=0.8, label="95 % (Δχ² = 3.84)")
        if prior is not None:
            pri = ((np.log(grid) - np.log(prior["median"])) / prior["sigma_ln"]) ** 2
            ax2.semilogx(grid, pri, "-", color="C2", label="prior −2 log p (physical)")
        ax2.set_ylim(-0.5, max(10.0, min(float(np.max(chi2 - np.min(chi2))), 60.0)))
        ax2.set_xlabel(LABELS.get(profile_name, profile_name))
        ax2.set_ylabel("Δχ²")
        ax2.legend(fontsize=8)
        ax2.grid(alpha=0.3)
        ax2.set_title(f"profile likelihood of {profile_name}", fontsize=9)
    fig.tight_layout()
    return fig


def trace_figure(chain, names, burn=0):
    """Walker traces of log-parameters ``chain (steps, walkers, k)``; burn-in shaded."""
    k = chain.shape[2]
    fig, axes = new_figure(k, 1, figsize=(7.5, 1.4 * k + 0.6), sharex=True)
    axes = np.atleast_1d(axes)
    for i, ax in enumerate(axes):
        ax.plot(chain[:, :, i], color="k", alpha=0.08, lw=0.5)
        ax.axvspan(0, burn, color="C1", alpha=0.15)
        ax.set_ylabel(f"log {names[i]}", fontsize=8)
    axes[-1].set_xlabel("step")
    fig.tight_layout()
    return fig
