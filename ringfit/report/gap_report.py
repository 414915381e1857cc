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

The verdict is one sentence for a tyre engineer (:func:`verdict_sentence`) that
names the rows the accepted effects explain and the rows they leave; for mode
tables a per-row table follows (measured, baseline, with the effects, σ, z,
outlier flag, the model mode each row was compared with and how rows without
n were matched). Frequencies and damping ratios are separate parts with their
own figures: no damping row is drawn in a frequency plot.

One colour means one thing in every figure (:data:`COLOURS`).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ringfit.gap.ranking import COMPUTED, parts
from ringfit.report.figures import new_figure, png_data_uri
from ringfit.report.html import esc, html_document, table_html

#: Candidates drawn in the residual figures (besides the baseline).
TOP = 2
#: Colours by meaning, the same in every figure: the measurement, the baseline model, the accepted
#: chain (model with its effects), a candidate that was not accepted, the noise band.
COLOURS = {"measured": "k", "baseline": "0.35", "accepted": "C2", "candidate": "C0", "rejected": "C3",
           "noise": "C2"}
#: Rows listed by name in the verdict sentence before "and k more".
NAMED_ROWS = 6
#: What each part's rows are, for titles and axes.
PART_TITLE = {"modes": "mode frequencies", "damping": "modal damping", "profiles": "profiles"}


def _row_list(rows: list[str]) -> str:
    rows = [r.replace(" damping", "") for r in rows]
    head = ", ".join(rows[:NAMED_ROWS])
    return head + (f" and {len(rows) - NAMED_ROWS} more" if len(rows) > NAMED_ROWS else "")


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
    rows = ""
    if v.get("explains"):
        rows += f" It explains {_row_list(v['explains'])}"
        rows += f" and leaves {_row_list(v['leaves'])}." if v.get("leaves") else "."
    if v.get("outliers"):
        rows += f" Outliers (|z| > 3 after the effects): {_row_list(v['outliers'])}."
    return (f"Adding {chain} to the model explains the gap: it removes {v['heldout_shrink_pct']:.0f} % of the "
            f"held-out weighted sum of squared residuals (1 − SS_after/SS_before){tail}.{rows}")


def _top_fits(part):
    """(label, FitResult) of the baseline's top refitted candidates (accepted first), at most :data:`TOP`."""
    cands = [c for c in part.summary["candidates"] if not c.get("screened_out")]
    cands.sort(key=lambda c: (not c.get("accepted"), -(c["heldout_shrink_pct"] or 0.0)))
    out = []
    for c in cands[:TOP]:
        computed = c.get("variant") == "computed"
        fit = part.fits.get(parts(c["element"]) if "element" in c else (c["effect"] + (COMPUTED if computed else ""),))
        if fit is not None:
            out.append((f"+ {c['effect']}" + (" (computed)" if computed else ""), fit))
    if part.chain_fit is not None and len(part.chain_fit.extra["chain"]) > 1:
        out.append(("+ " + " + ".join(_element_label(e) for e in part.chain_fit.extra["chain"]), part.chain_fit))
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


def _element_label(element: str) -> str:
    return element.removesuffix(COMPUTED) + (" (computed)" if element.endswith(COMPUTED) else "")


def _fit_colour(name: str, part) -> str:
    if name == "baseline":
        return COLOURS["baseline"]
    accepted = {c["effect"] + (" (computed)" if c.get("variant") == "computed" else "")
                for c in part.summary["candidates"] if c.get("accepted")}
    effects = name.removeprefix("+ ").split(" + ")
    return COLOURS["accepted"] if set(effects) <= accepted else COLOURS["candidate"]


def _modal_residual_figure(part):
    """Held-out residual / σ per row: short labels (state, n, tag), the baseline drawn on top."""
    prob = part.problem
    fits = [("baseline", part.baseline)] + _top_fits(part)
    fig, ax = new_figure(figsize=(max(6.0, 0.22 * prob.m), 3.6))
    x = np.arange(prob.m)
    sigma = prob.sigma_heldout if prob.sigma_heldout is not None else prob.sigma
    markers = ["o", "s", "^", "D"]
    for i, (name, fit) in enumerate(fits):
        pred = fit.extra.get("heldout_pred")
        pred = fit.extra["pred"] if pred is None else pred
        base = i == 0
        ax.plot(x + (0.0 if base else 0.14 * i), (prob.y - pred) / sigma, markers[i % len(markers)],
                color=_fit_colour(name, part), ms=5 if base else 4, mfc="none" if base else None,
                mew=1.2 if base else 1.0, zorder=5 if base else 3, label=name)
    ax.axhspan(-1, 1, color=COLOURS["noise"], alpha=0.12, lw=0, label="±1 noise σ")
    ax.axhline(0.0, color="k", lw=0.4)
    ax.set_xticks(x, prob.labels["short"], rotation=90, fontsize=6)
    ax.set_xlabel("row (state, n, tag)")
    ax.set_ylabel("held-out residual / noise σ [–]")
    ax.legend(fontsize=7, ncols=2)
    ax.set_title(f"{PART_TITLE.get(prob.domain, prob.domain)} [{prob.unit}]: held-out residual per mode", fontsize=9)
    return fig


def _forest_figure(part):
    allc = part.summary["candidates"]
    fig, ax = new_figure(figsize=(6, 0.38 * len(allc) + 1.2))
    for i, c in enumerate(allc):
        lo, hi = c["heldout_shrink_interval_pct"]
        ax.plot([lo, hi], [i, i], "-", color=COLOURS["candidate"], lw=2)
        ax.plot([c["heldout_shrink_pct"]], [i], "o", color=COLOURS["accepted"] if c.get("accepted")
                else COLOURS["rejected"])
    ax.set_yticks(range(len(allc)), [c["effect"] + (f" @{c['variant']}" if c.get("variant") == "computed" else "")
                                     + (" (screened)" if c.get("screened_out") else "") for c in allc], fontsize=8)
    ax.invert_yaxis()
    ax.axvline(0, color="k", lw=0.5)
    ideal = part.summary["baseline"].get("ideal_shrink_pct")
    if ideal is not None:
        ax.axvline(ideal, color="k", ls="--", lw=0.8, label=f"ideal shrink {ideal:.0f} %")
        ax.legend(fontsize=7, loc="lower right")
    ax.set_xlabel("held-out shrink 1 − SS_after/SS_before [%] (interval; green = accepted, red = not)")
    ax.set_ylabel("candidate effect")
    ax.set_title(PART_TITLE.get(part.problem.domain, part.problem.domain), fontsize=9)
    return fig


def _modal_heldout_figure(part):
    prob = part.problem
    y = prob.y
    fit = part.chain_fit if part.chain_fit is not None else part.baseline
    fig, ax = new_figure(figsize=(4.6, 4.6))
    if fit.extra.get("heldout_pred") is not None and fit is not part.baseline:
        ax.plot(y, fit.extra["heldout_pred"], "s", ms=4, color=COLOURS["accepted"],
                label="+ " + " + ".join(_element_label(e) for e in fit.extra["chain"]))
    ax.plot(y, part.baseline.extra["heldout_pred"], "o", mfc="none", ms=5, color=COLOURS["baseline"], zorder=5,
            label="baseline")
    lim = [np.nanmin(y), np.nanmax(y)]
    ax.plot(lim, lim, "-", color=COLOURS["measured"], lw=0.5)
    ax.set_xlabel(f"measured [{prob.unit}]")
    ax.set_ylabel(f"held-out predicted [{prob.unit}]")
    ax.set_title(PART_TITLE.get(prob.domain, prob.domain), fontsize=9)
    ax.legend(fontsize=7)
    return fig


def _null_candidates(summary: dict) -> list[dict]:
    """Every candidate of a part (first round and chain rounds) that was tested against a null."""
    rounds = [summary.get("candidates", [])] + [r["candidates"] for r in summary.get("chain", [])]
    return [c for r in rounds for c in r if c.get("null_draws")]


def _null_figure(cands: list[dict], title: str):
    """Histogram of each null's selection statistic with the observed value marked (docs/formats.md §5 ``null``)."""
    cols = max(len(c["null_draws"]) for c in cands)
    fig, axes = new_figure(figsize=(4.2 * cols, 2.6 * len(cands)), nrows=len(cands), ncols=cols, squeeze=False)
    for i, c in enumerate(cands):
        for j, (kind, draws) in enumerate(sorted(c["null_draws"].items())):
            ax = axes[i][j]
            d = 100 * np.asarray(draws)
            s = c["null"][kind]
            ax.hist(d, bins=30, color=COLOURS["baseline"], alpha=0.7, label=f"null ({s['draws']} draws)")
            ax.axvline(s["observed_pct"], color=COLOURS["accepted"] if c.get("accepted") else COLOURS["rejected"],
                       lw=2, label=f"observed {s['observed_pct']:.0f} %, p = {s['p_value']:.3g}")
            ax.axvline(s["q95_pct"], color="k", ls=":", lw=0.8, label="95 % of the null")
            ax.set_xlabel("selection statistic: held-out shrink [%]")
            ax.set_ylabel("draws")
            ax.set_title(f"{c['effect']} ({c.get('variant', '')}): {kind.replace('_', '-')} null", fontsize=8)
            ax.legend(fontsize=6)
    fig.suptitle(title, fontsize=9)
    return fig


def figures(diag) -> list[tuple[str, str]]:
    """``(title, data URI)`` of every figure of the report."""
    out = []
    for part in diag.parts:
        tested = _null_candidates(part.summary)
        if tested:
            t = f"{PART_TITLE.get(part.problem.domain, part.problem.domain)}: held-out shrink against chance"
            out.append((t, png_data_uri(_null_figure(tested, t))))
        dom = part.problem.domain
        if dom == "profiles":
            out.append(("profiles: residual vs angle before/after, per channel and speed",
                        png_data_uri(_profile_residual_figure(part))))
        else:
            out.append((f"{PART_TITLE.get(dom, dom)}: held-out residual per mode, baseline and effects",
                        png_data_uri(_modal_residual_figure(part))))
        out.append((f"{PART_TITLE.get(dom, dom)}: ranked candidates (forest plot)", png_data_uri(_forest_figure(part))))
        if dom == "profiles":
            out.append(("profiles: held-out predicted vs measured", png_data_uri(_profile_heldout_figure(part))))
        else:
            out.append((f"{PART_TITLE.get(dom, dom)}: held-out predicted vs measured",
                        png_data_uri(_modal_heldout_figure(part))))
    return out


def _params_text(candidate: dict) -> str:
    return ", ".join(f"{k} {v.get('value')} [{v.get('lo')}, {v.get('hi')}]"
                     for k, v in candidate.get("params", {}).items())


def _row_sections(content: dict) -> list[tuple[str, str]]:
    """Per part of mode tables: one row per measured mode (held-out predictions; docs/formats.md §5 ``rows``)."""
    out = []
    for pc in content.get("parts") or [content]:
        rows = pc.get("rows") or []
        if not rows:
            continue
        unit = pc["baseline"].get("unit", "")
        body = [[esc(r["row"]), esc(r.get("model_mode", "")), esc(r["measured"]), esc(r["baseline"]),
                 esc(r["with_effects"]), esc(r["sigma"]), esc(r["z_baseline"]), esc(r["z_with_effects"]),
                 "<b>outlier</b>" if r["outlier"] else "", esc(r.get("match", ""))] for r in rows]
        family = pc.get("family", "")
        out.append((f"Rows — {family}" if family else "Rows",
                    table_html(["row", "model mode", f"measured [{unit}]", f"baseline [{unit}]",
                                f"with effects [{unit}]", f"σ [{unit}]", "z baseline", "z with effects", "outlier",
                                "match"], body)))
    return out


def _drift_html(drift: dict | None) -> str:
    """How far the baseline moved from its prior or reference fit (docs/formats.md §5 ``baseline.drift``)."""
    if not drift:
        return ""
    against = {"prior": "its prior (independent data)", "reference_fit": "the reference fit"}.get(drift["against"],
                                                                                                 drift["against"])
    each = ", ".join(f"{esc(k)} {v['pct']:+.1f} % ({v['sigma']:+.2f} σ)" for k, v in drift["parameters"].items())
    pd = drift.get("prior_distance")
    where = ""
    if pd:
        where = (f" D² = {pd['d2']} against χ²<sub>{pd['k']}</sub>(0.999) = {pd['limit']}: "
                 + ("<b>outside</b> — the baseline may be absorbing an unmodelled effect; where candidates are "
                    "refitted, each is also refitted from the reference baseline (nonlinear screen)."
                    if pd["outside"] else "inside."))
    return f"<p><b>Baseline moved</b> from {esc(against)}: {each}.{where}</p>"


def write_gap_report(diag, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write the HTML report of a :class:`ringfit.gap.Diagnosis` (atomic; refuses to overwrite unless asked)."""
    from ringfit.io.files import atomic_write_text, check_output_path

    path = check_output_path(path, overwrite=overwrite)
    c = diag.content
    rows = [[esc(x["effect"]), esc(x.get("variant", "")), esc(x["heldout_shrink_pct"]), esc(x["heldout_shrink_interval_pct"]),
             esc(x["evidence"].get("delta_bic")), esc(x.get("p_value", "")), esc(_params_text(x)),
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
    st = b.get("rolling_structure")
    if st:  # the model structure the rolling rows were assigned to, chosen by the data (docs/physics.md §6.4)
        name = {"rolling_loaded": "the rolling, loaded model", "free_spinning": "the free spinning ring (no contact)"}
        costs = ", ".join(f"{esc(name.get(k, k))} {v}" for k, v in st["cost"].items())
        summary += (f"<p><b>Rolling rows</b> assigned to {esc(name.get(st['chosen'], st['chosen']))}, chosen by "
                    f"their lines' fit (cost −2 ln L, lower wins: {costs}).</p>")
    lab = c["verdict"].get("labels")
    if lab:  # labels are evidence: kept, overridden, and whether shuffled labels fit as well (docs/formats.md §5)
        summary += f"<p><b>Labels:</b> {esc(lab['sentence'])}.</p>"
    summary += _drift_html(b.get("drift"))
    cal = c["verdict"].get("calibration") or []
    if cal:
        summary += "<p><b>Against chance:</b></p><ul>" + "".join(f"<li>{esc(x['sentence'])}</li>" for x in cal) + "</ul>"
    sections = [("Verdict", summary), ("Where", f"<ul>{where}</ul>"),
                ("Which", table_html(["effect", "variant", "held-out shrink %", "95 % interval", "ΔBIC",
                                      "p (vs chance)", "parameters [95 % interval]", "accepted"], rows)),
                ("Rules", f"<ul>{rule_items}</ul>")]
    sections += _row_sections(c)
    sections += [(title, f'<figure><img src="{src}" alt="{esc(title)}"></figure>') for title, src in figures(diag)]
    return atomic_write_text(path, html_document("Sim-to-real gap diagnosis", sections))
