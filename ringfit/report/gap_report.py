"""Self-contained HTML report of a gap diagnosis (embedded PNGs): verdict, where, ranked candidates, held-out fit.

Figures, per kind of data in the diagnosis:

- **residual before/after** for the baseline and the top candidates: for
  rolling profiles vs angle, one panel per channel and speed (the contact
  patch at 0°); for mode tables per mode (row labels);
- **forest plot**: every candidate's held-out shrink with its 95 % bootstrap
  interval (green = accepted), the ideal shrink (the part of the residual
  that is not noise) as a dashed line;
- **held-out predicted vs measured**: for profiles, each speed as predicted
  by the fit to the *other* speeds (baseline and the accepted chain) over the
  measurement; for mode tables a scatter.

The verdict is one sentence for a tyre engineer (:func:`verdict_sentence`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ringfit.report.figures import new_figure, png_data_uri
from ringfit.report.html import esc, html_document, table_html

#: Candidates drawn in the residual figures (besides the baseline).
TOP = 2


def verdict_sentence(content: dict) -> str:
    """One sentence a tyre engineer understands."""
    v = content["verdict"]
    b = content["baseline"]
    effs = v["effects"]
    if effs == ["none"]:
        return (f"The baseline model matches the measurements to within their noise "
                f"(RMS {b['rms']:.3g} {b['unit']}); no missing effect is needed.")
    if effs[0] == "unexplained":
        where = content["where"][0]["region"] if content["where"] else "the data"
        return (f"The model misses something real (mostly at {where}), but none of the candidate effects "
                f"removes it on held-out data: the cause lies outside the library.")
    chain = " and then ".join(e.replace("_", " ") for e in effs if e != "unexplained")
    tail = "; a structured residual still remains" if "unexplained" in effs else ""
    return (f"Adding {chain} to the model explains the gap: it removes {v['heldout_shrink_pct']:.0f} % of the "
            f"residual RMS on data that took no part in the fit{tail}.")


def _top_fits(part):
    """(label, FitResult) of the baseline's top refitted candidates (accepted first), at most :data:`TOP`."""
    cands = [c for c in part.summary["candidates"] if not c.get("screened_out")]
    cands.sort(key=lambda c: (not c.get("accepted"), -(c["heldout_shrink_pct"] or 0.0)))
    out = []
    for c in cands[:TOP]:
        fit = part.fits.get((c["effect"],))
        if fit is not None:
            out.append((f"+ {c['effect']}", fit))
    if part.chain_fit is not None and len(part.chain_fit.extra["chain"]) > 1:
        out.append(("+ " + " + ".join(part.chain_fit.extra["chain"]), part.chain_fit))
    return out


def _profile_grid(prob):
    """(P, channels, M), angle [deg] and speed labels of a profile problem's rows."""
    lab = prob.labels
    P = int(lab["profile"].max()) + 1
    M = prob.m // (2 * P)
    angle = lab["angle_deg"][:M]
    speeds = [float(lab["speed_kmh"][p * 2 * M]) for p in range(P)]
    return P, M, angle, speeds


def _profile_panels(prob, ylabel: str, xlabel: str, draw):
    """A 2 × speeds grid (radial, tangential per speed); ``draw(ax, sl)`` fills the panel of row slice ``sl``."""
    P, M, angle, speeds = _profile_grid(prob)
    fig, axes = new_figure(2, P, figsize=(3.0 * P, 4.6), sharex=True, squeeze=False)
    for p in range(P):
        for c, ch in enumerate(("radial", "tangential")):
            ax = axes[c, p]
            draw(ax, angle, slice((2 * p + c) * M, (2 * p + c + 1) * M))
            ax.set_title(f"{ch}, {speeds[p]:.0f} km/h", fontsize=8)
            ax.tick_params(labelsize=7)
            if p == 0:
                ax.set_ylabel(ylabel, fontsize=8)
            if c == 1:
                ax.set_xlabel(xlabel, fontsize=8)
    return fig, axes


def _profile_residual_figure(part):
    prob = part.problem
    fits = [("baseline", part.baseline)] + _top_fits(part)

    def draw(ax, angle, sl):
        for i, (name, fit) in enumerate(fits):
            ax.plot(angle, (prob.y - fit.extra["pred"])[sl], lw=0.8 if i else 0.6, color="0.55" if i == 0 else f"C{i}",
                    label=name)
        ax.axhline(0.0, color="k", lw=0.4)
        sigma = float(prob.sigma[sl][0])
        ax.axhspan(-sigma, sigma, color="C2", alpha=0.12, lw=0)

    fig, axes = _profile_panels(prob, "residual [m/s²]", "angle from patch centre [deg]", draw)
    axes[0, 0].legend(fontsize=6, loc="upper left")
    fig.suptitle("residual vs angle (measured − model; band = ±1 noise σ)", fontsize=9)
    return fig


def _profile_heldout_figure(part):
    prob = part.problem
    chain = part.chain_fit if part.chain_fit is not None and part.chain_fit is not part.baseline else None

    def draw(ax, angle, sl):
        ax.plot(angle, prob.y[sl], color="k", lw=0.6, label="measured")
        ax.plot(angle, part.baseline.extra["heldout_pred"][sl], color="0.55", lw=0.8, label="baseline, held out")
        if chain is not None and chain.extra.get("heldout_pred") is not None:
            ax.plot(angle, chain.extra["heldout_pred"][sl], color="C2", lw=0.8,
                    label=" + ".join(chain.extra["chain"]) + ", held out")
        ax.set_xlim(-60, 60)

    fig, axes = _profile_panels(prob, "acceleration [m/s²]", "angle [deg]", draw)
    axes[0, 0].legend(fontsize=6, loc="lower left")
    fig.suptitle("held-out: each speed predicted by the fit to the other speeds (|angle| ≤ 60°)", fontsize=9)
    return fig


def _modal_residual_figure(part):
    prob = part.problem
    fits = [("baseline", part.baseline)] + _top_fits(part)
    fig, ax = new_figure(figsize=(max(6.0, 0.18 * prob.m), 3.4))
    x = np.arange(prob.m)
    for i, (name, fit) in enumerate(fits):
        ax.plot(x + 0.12 * i, (prob.y - fit.extra["pred"]) / prob.sigma, "o" if i == 0 else ".",
                color="0.4" if i == 0 else f"C{i}", ms=4, label=name)
    ax.axhspan(-1, 1, color="C2", alpha=0.12, lw=0)
    ax.set_xticks(x, prob.labels["label"], rotation=90, fontsize=5)
    ax.set_ylabel("residual / noise σ")
    ax.legend(fontsize=7)
    ax.set_title("residual per mode (band = ±1 noise σ)", fontsize=9)
    return fig


def _forest_figure(part):
    allc = part.summary["candidates"]
    fig, ax = new_figure(figsize=(6, 0.38 * len(allc) + 1.2))
    for i, c in enumerate(allc):
        lo, hi = c["heldout_shrink_interval_pct"]
        ax.plot([lo, hi], [i, i], "-", color="C0", lw=2)
        ax.plot([c["heldout_shrink_pct"]], [i], "o", color="C2" if c.get("accepted") else "C3")
    ax.set_yticks(range(len(allc)), [c["effect"] + (" (screened)" if c.get("screened_out") else "") for c in allc],
                  fontsize=8)
    ax.invert_yaxis()
    ax.axvline(0, color="k", lw=0.5)
    ideal = part.summary["baseline"].get("ideal_shrink_pct")
    if ideal is not None:
        ax.axvline(ideal, color="k", ls="--", lw=0.8, label=f"ideal shrink {ideal:.0f} %")
        ax.legend(fontsize=7, loc="lower right")
    ax.set_xlabel("held-out RMS shrink [%] (95 % bootstrap interval; green = accepted)")
    return fig


def _modal_heldout_figure(part):
    prob = part.problem
    y = prob.y
    fit = part.chain_fit if part.chain_fit is not None else part.baseline
    fig, ax = new_figure(figsize=(4.5, 4.5))
    ax.plot(y, part.baseline.extra["heldout_pred"], "k.", label="baseline")
    if fit.extra.get("heldout_pred") is not None and fit is not part.baseline:
        ax.plot(y, fit.extra["heldout_pred"], ".", color="C2", label=" + ".join(fit.extra["chain"]))
    lim = [np.nanmin(y), np.nanmax(y)]
    ax.plot(lim, lim, "k-", lw=0.5)
    ax.set_xlabel("measured")
    ax.set_ylabel("held-out predicted")
    ax.legend(fontsize=7)
    return fig


def figures(diag) -> list[tuple[str, str]]:
    """``(title, data URI)`` of every figure of the report."""
    out = []
    for part in diag.parts:
        dom = part.problem.domain
        if dom == "profiles":
            out.append(("profiles: residual vs angle before/after, per channel and speed",
                        png_data_uri(_profile_residual_figure(part))))
        else:
            out.append(("mode tables: residual per mode before/after", png_data_uri(_modal_residual_figure(part))))
        out.append((f"{dom}: ranked candidates (forest plot)", png_data_uri(_forest_figure(part))))
        if dom == "profiles":
            out.append(("profiles: held-out predicted vs measured", png_data_uri(_profile_heldout_figure(part))))
        else:
            out.append(("mode tables: held-out predicted vs measured", png_data_uri(_modal_heldout_figure(part))))
    return out


def _params_text(candidate: dict) -> str:
    return ", ".join(f"{k} {v.get('value')} [{v.get('lo')}, {v.get('hi')}]"
                     for k, v in candidate.get("params", {}).items())


def write_gap_report(diag, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write the HTML report of a :class:`ringfit.gap.Diagnosis` (atomic; refuses to overwrite unless asked)."""
    from ringfit.io.files import atomic_write_text, check_output_path

    path = check_output_path(path, overwrite=overwrite)
    c = diag.content
    rows = [[esc(x["effect"]), esc(x["heldout_shrink_pct"]), esc(x["heldout_shrink_interval_pct"]),
             esc(x["evidence"].get("delta_bic")), esc(_params_text(x)),
             "yes" if x.get("accepted") else esc("; ".join(x.get("rejected_because", [])))]
            for x in c["candidates"]]
    where = "".join(f"<li>{esc(w['region'])}: {100 * w['share']:.0f} %</li>" for w in c["where"])
    b = c["baseline"]
    rules = c["verdict"].get("rule", {})
    rule_items = "".join(f"<li><b>{esc(k)}</b>: {esc(v)}</li>" for k, v in rules.items())
    summary = (
        f"<p><b>Verdict:</b> {esc(verdict_sentence(c))} <small>({esc(' + '.join(c['verdict']['effects']))})</small></p>"
        f"<p>Data: {esc(', '.join(c['data']))}. Baseline {esc(b['model'])}: RMS {b['rms']} {esc(b['unit'])}, "
        f"held-out {b['heldout_rms']} ({esc(b.get('heldout_method', ''))}); noise RMS {b.get('noise_rms')} — "
        f"{esc(b.get('noise_method', ''))}. Held-out reduced χ² {b.get('reduced_chi2')} (effective dof "
        f"{b.get('noise_dof')}); ideal shrink {b.get('ideal_shrink_pct')} %.</p>")
    sections = [("Verdict", summary), ("Where", f"<ul>{where}</ul>"),
                ("Which", table_html(["effect", "held-out shrink %", "95 % interval", "ΔBIC",
                                      "parameters [95 % interval]", "accepted"], rows)),
                ("Rules", f"<ul>{rule_items}</ul>")]
    sections += [(title, f'<figure><img src="{src}" alt="{esc(title)}"></figure>') for title, src in figures(diag)]
    return atomic_write_text(path, html_document("Sim-to-real gap diagnosis", sections))
