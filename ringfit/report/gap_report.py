"""Self-contained HTML report of a gap diagnosis (embedded PNGs), in the order a modal engineer reads it.

1. **Verdict** — one sentence (:func:`verdict_headline`), then the rows the accepted effects explain and
   leave;
2. **Residual per mode, before and after** — per kind of data: for mode tables the held-out residual / σ
   per row (before: the baseline; after: the accepted chain; the best other candidates beside them); for
   rolling profiles the residual vs angle, one panel per channel and speed (the contact patch at 0°);
3. **Against chance** — per tested candidate the histogram of the null that *binds* (:func:`binding_null`:
   the larger p, on a tie the higher 95 % quantile, docs/formats.md §5 ``null_sentence``) with the observed
   statistic marked, the other nulls' p beside it; one labelled line (effect, fitted or computed, round)
   per tested candidate;
4. **Tables** — the candidates with their parameters in physical units (the contact patch's half-angle in
   degrees and length in mm, the wheel speed in rad/s: ``params.<p>.physical``), where the residual sits,
   one row per measured mode (values at the precision their σ warrants, damping as ζ in %), the forest plot
   and the held-out predicted vs measured figures, the baseline's own figures;
5. **Method** — folded (``<details>``): how σ was estimated, how rows were held out, every rule.

The report draws what the diagnosis saved (its JSON and the fits kept with it) and recomputes nothing.
Each section is one function returning ``(heading, html)`` pairs (:data:`SECTIONS`), so a new line of the
diagnosis (a count, another null) goes into one place; a null kind the report does not know is drawn and
listed like the others. One colour means one thing in every figure (:data:`COLOURS`).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ringfit.gap.ranking import COMPUTED, parts
from ringfit.report.figures import new_figure, png_data_uri
from ringfit.report.html import esc, html_document, table_html
from ringfit.report.numbers import fmt_interval, fmt_pm, fmt_sigma, fmt_value

#: Candidates drawn in the residual figures (besides the baseline and the accepted chain).
TOP = 2
#: Colours by meaning, the same in every figure: the measurement, the baseline model, the accepted
#: chain (model with its effects), a candidate that was not accepted, the noise band.
COLOURS = {"measured": "k", "baseline": "0.35", "accepted": "C2", "candidate": "C0", "rejected": "C3",
           "noise": "C2"}
#: Rows listed by name in the verdict before "and k more".
NAMED_ROWS = 6
#: What each part's rows are, for titles and axes.
PART_TITLE = {"modes": "mode frequencies", "damping": "modal damping", "profiles": "profiles"}
#: The same by the JSON's ``family`` key (docs/formats.md §5).
FAMILY_TITLE = {"frequency": "mode frequencies", "damping": "modal damping", "profile": "profiles"}
#: Histogram panels per row of the null figure.
NULL_COLUMNS = 2


# --------------------------------------------------------------------------- words
def _row_list(rows: list[str]) -> str:
    rows = [r.replace(" damping", "") for r in rows]
    head = ", ".join(rows[:NAMED_ROWS])
    return head + (f" and {len(rows) - NAMED_ROWS} more" if len(rows) > NAMED_ROWS else "")


def _variant_label(variant: str | None) -> str:
    return f" ({variant})" if variant in ("computed", "fitted") else ""


def verdict_headline(content: dict) -> str:
    """The verdict in one sentence a tyre engineer understands (what is missing from the model, and how much
    of the gap it removes)."""
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
    variants = list(v.get("variants") or [])
    named = [e.replace("_", " ") + _variant_label(variants[i] if i < len(variants) else None)
             for i, e in enumerate(x for x in effs if x != "unexplained")]
    tail = "; a structured residual still remains" if "unexplained" in effs else ""
    return (f"Adding {' and then '.join(named)} to the model explains the gap: it removes "
            f"{v['heldout_shrink_pct']:.0f} % of the held-out residual{tail}.")


def verdict_rows(content: dict) -> str:
    """The rows the accepted effects explain, leave and the outliers after them (may be empty)."""
    v = content["verdict"]
    rows = ""
    if v.get("explains"):
        rows += f"It explains {_row_list(v['explains'])}"
        rows += f" and leaves {_row_list(v['leaves'])}." if v.get("leaves") else "."
    if v.get("outliers"):
        rows += f" Outliers (|z| > 3 after the effects): {_row_list(v['outliers'])}."
    return rows.strip()


def verdict_sentence(content: dict) -> str:
    """The headline and the rows it explains and leaves (the verdict as the CLI and the report state it)."""
    rows = verdict_rows(content)
    return verdict_headline(content) + (f" {rows}" if rows else "")


def binding_null(candidate: dict) -> str | None:
    """The key of the null that binds a tested candidate (docs/formats.md §5 ``null_sentence``): the larger
    p-value, and on a tie the higher 95 % quantile (the stricter null); ``None`` when it was not tested."""
    nulls = candidate.get("null") or {}
    if not nulls:
        return None
    return max(nulls, key=lambda k: (nulls[k].get("p_value", 0.0), nulls[k].get("q95_pct", -math.inf)))


def _null_line(kind: str, s: dict) -> str:
    what = {"parametric": "data with no effect in it (the current model plus its noise)",
            "random_line": "random tables of this line density"}.get(kind, kind.replace("_", "-") + " null draws")
    return (f"{what} get {s['mean_pct']:.0f} % ± {s['sd_pct']:.0f} % (95 % quantile {s['q95_pct']:.0f} %); "
            f"this candidate gets {s['observed_pct']:.0f} %: p = {s['p_value']:.3g} over {s['draws']} draws")


# --------------------------------------------------------------------------- figures
def _element_label(element: str, part=None) -> str:
    """A chain element in words: ``ground_contact (computed)``; ``(fitted)`` where the part also tried the
    effect's computed variant (so the two read apart)."""
    if element.endswith(COMPUTED):
        return element.removesuffix(COMPUTED) + " (computed)"
    both = part is not None and any(c["effect"] == element and c.get("variant") == "computed"
                                    for c in part.summary.get("candidates", []))
    return element + (" (fitted)" if both else "")


def _chain_label(fit, part) -> str:
    return " + ".join(_element_label(e, part) for e in fit.extra["chain"])


def _candidate_label(c: dict) -> str:
    return f"+ {c['effect']}" + _variant_label(c.get("variant"))


def _fits_before_after(part):
    """``(label, FitResult, colour)``: before (the baseline), after (the accepted chain, if any), then the best
    other refitted candidates (accepted first), at most :data:`TOP`."""
    out = [("before: baseline", part.baseline, COLOURS["baseline"])]
    chain = part.chain_fit if part.chain_fit is not None and part.chain_fit is not part.baseline else None
    if chain is not None:
        out.append(("after: + " + _chain_label(chain, part), chain,
                    COLOURS["accepted"]))
    cands = [c for c in part.summary["candidates"] if not c.get("screened_out")]
    cands.sort(key=lambda c: (not c.get("accepted"), -(c["heldout_shrink_pct"] or 0.0)))
    for c in cands:
        if len(out) >= TOP + 1 + (chain is not None):
            break
        computed = c.get("variant") == "computed"
        fit = part.fits.get(parts(c["element"]) if "element" in c else (c["effect"] + (COMPUTED if computed else ""),))
        if fit is not None and fit is not chain:
            out.append((_candidate_label(c), fit, COLOURS["candidate"] if c.get("accepted") else COLOURS["rejected"]))
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
    fig, axes = new_figure(2, P, figsize=(3.0 * P, 4.6), sharex=True, squeeze=False, layout="constrained")
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


def _legend_below(fig, ax) -> None:
    """One legend for all panels, below them (it hides no curve)."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncols=min(len(labels), 4), fontsize=7)


def _profile_residual_figure(part):
    """Residual vs angle per channel and speed: before (the baseline) and after (the accepted chain, or else the
    best candidate) only — dense curves, a third would hide the first."""
    prob = part.problem
    fits = _fits_before_after(part)[:2]

    def draw(ax, angle, sl):
        for i, (name, fit, colour) in enumerate(fits):
            ax.plot(angle, (prob.y - fit.extra["pred"])[sl], lw=0.7, color=colour, label=name, zorder=2 + i)
        ax.axhline(0.0, color="k", lw=0.4)
        sigma = float(prob.sigma[sl][0])
        ax.axhspan(-sigma, sigma, color=COLOURS["noise"], alpha=0.12, lw=0)

    fig, axes = _profile_panels(prob, "residual [m/s²]", "angle from patch centre [deg]", draw)
    _legend_below(fig, axes[0, 0])
    fig.suptitle("residual vs angle, before and after (measured − model; band = ±1 noise σ)", fontsize=9)
    return fig


def _profile_heldout_figure(part):
    prob = part.problem
    chain = part.chain_fit if part.chain_fit is not None and part.chain_fit is not part.baseline else None

    def draw(ax, angle, sl):
        ax.plot(angle, prob.y[sl], color=COLOURS["measured"], lw=0.6, label="measured")
        ax.plot(angle, part.baseline.extra["heldout_pred"][sl], color=COLOURS["baseline"], lw=0.8,
                label="baseline, held out")
        if chain is not None and chain.extra.get("heldout_pred") is not None:
            ax.plot(angle, chain.extra["heldout_pred"][sl], color=COLOURS["accepted"], lw=0.8,
                    label=_chain_label(chain, part) + ", held out")
        ax.set_xlim(-60, 60)

    fig, axes = _profile_panels(prob, "acceleration [m/s²]", "angle [deg]", draw)
    _legend_below(fig, axes[0, 0])
    fig.suptitle("held-out: each speed predicted by the fit to the other speeds (|angle| ≤ 60°)", fontsize=9)
    return fig


def _modal_residual_figure(part):
    """Held-out residual / σ per row, before (baseline, open circles) and after (the accepted chain)."""
    prob = part.problem
    fits = _fits_before_after(part)
    fig, ax = new_figure(figsize=(max(6.0, 0.22 * prob.m), 3.8), layout="constrained")
    x = np.arange(prob.m)
    sigma = prob.sigma_heldout if prob.sigma_heldout is not None else prob.sigma
    markers = ["o", "s", "^", "D"]
    for i, (name, fit, colour) in enumerate(fits):
        pred = fit.extra.get("heldout_pred")
        pred = fit.extra["pred"] if pred is None else pred
        base = i == 0
        ax.plot(x + (0.0 if base else 0.14 * i), (prob.y - pred) / sigma, markers[i % len(markers)],
                color=colour, ms=5 if base else 4, mfc="none" if base else None,
                mew=1.2 if base else 1.0, zorder=5 if base else 3, label=name)
    ax.axhspan(-1, 1, color=COLOURS["noise"], alpha=0.12, lw=0, label="±1 noise σ")
    ax.axhline(0.0, color="k", lw=0.4)
    ax.set_xticks(x, prob.labels["short"], rotation=90, fontsize=6)
    ax.set_xlabel("row (state, n, tag)")
    ax.set_ylabel("held-out residual / noise σ [–]")
    ax.legend(fontsize=7, ncols=2)
    what = ("damping ratio ζ" if prob.domain == "damping"
            else f"{PART_TITLE.get(prob.domain, prob.domain)} [{prob.unit}]")
    ax.set_title(f"{what}: held-out residual per mode, before and after", fontsize=9)
    return fig


def _forest_figure(part):
    allc = part.summary["candidates"]
    fig, ax = new_figure(figsize=(6, 0.38 * len(allc) + 1.2), layout="constrained")
    for i, c in enumerate(allc):
        lo, hi = c["heldout_shrink_interval_pct"]
        ax.plot([lo, hi], [i, i], "-", color=COLOURS["candidate"], lw=2)
        ax.plot([c["heldout_shrink_pct"]], [i], "o", color=COLOURS["accepted"] if c.get("accepted")
                else COLOURS["rejected"])
    ax.set_yticks(range(len(allc)), [c["effect"] + _variant_label(c.get("variant"))
                                     + (" (screened out)" if c.get("screened_out") else "") for c in allc], fontsize=8)
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
    """Held-out predicted vs measured; damping rows (ln ζ) drawn as ζ in % on log axes."""
    prob = part.problem
    damping = prob.domain == "damping"
    show = (lambda v: 100.0 * np.exp(np.asarray(v, dtype=float))) if damping else (lambda v: np.asarray(v, dtype=float))
    unit = "%" if damping else prob.unit
    y = show(prob.y)
    fit = part.chain_fit if part.chain_fit is not None else part.baseline
    fig, ax = new_figure(figsize=(4.6, 4.6), layout="constrained")
    if fit.extra.get("heldout_pred") is not None and fit is not part.baseline:
        ax.plot(y, show(fit.extra["heldout_pred"]), "s", ms=4, color=COLOURS["accepted"],
                label="after: + " + _chain_label(fit, part))
    ax.plot(y, show(part.baseline.extra["heldout_pred"]), "o", mfc="none", ms=5, color=COLOURS["baseline"], zorder=5,
            label="before: baseline")
    lim = [np.nanmin(y), np.nanmax(y)]
    ax.plot(lim, lim, "-", color=COLOURS["measured"], lw=0.5)
    if damping and lim[1] > 5 * lim[0] > 0:  # ζ spanning a wide range: log axes, ticks written plainly
        from matplotlib.ticker import FuncFormatter

        plain = FuncFormatter(lambda v, _: f"{v:.3g}")
        for axis, scale in ((ax.xaxis, ax.set_xscale), (ax.yaxis, ax.set_yscale)):
            scale("log")
            axis.set_major_formatter(plain)
            axis.set_minor_formatter(plain)
    what = "damping ratio ζ" if damping else "frequency"
    ax.set_xlabel(f"measured {what} [{unit}]")
    ax.set_ylabel(f"held-out predicted {what} [{unit}]")
    ax.set_title(PART_TITLE.get(prob.domain, prob.domain), fontsize=9)
    ax.legend(fontsize=7)
    return fig


def _null_candidates(summary: dict) -> list[tuple[int, dict]]:
    """``(round, candidate)`` of every candidate of a part (first round and chain rounds) tested against a null."""
    rounds = [summary.get("candidates", [])] + [r["candidates"] for r in summary.get("chain", [])]
    return [(i + 1, c) for i, r in enumerate(rounds) for c in r if c.get("null_draws")]


def _null_figure(cands: list, title: str):
    """Per tested candidate, the histogram of the null that binds (:func:`binding_null`) with the observed
    statistic marked; the other nulls' p-values in the legend. ``cands``: ``(round, candidate)`` pairs (or
    bare candidate dicts)."""
    cands = [c if isinstance(c, tuple) else (1, c) for c in cands]
    multi_round = len({r for r, _ in cands}) > 1
    cols = min(NULL_COLUMNS, len(cands))
    nrows = math.ceil(len(cands) / cols)
    fig, axes = new_figure(nrows=nrows, ncols=cols, figsize=(4.6 * cols, 2.9 * nrows + 0.5), squeeze=False,
                           layout="constrained")
    for k, (rnd, c) in enumerate(cands):
        ax = axes[k // cols][k % cols]
        kind = binding_null(c) or next(iter(c["null_draws"]))
        s = c["null"][kind]
        d = 100 * np.asarray(c["null_draws"][kind], dtype=float)
        ax.hist(d, bins=30, color=COLOURS["baseline"], alpha=0.7,
                label=f"{kind.replace('_', '-')} null, {s['draws']} draws")
        ax.axvline(s["observed_pct"], color=COLOURS["accepted"] if c.get("accepted") else COLOURS["rejected"],
                   lw=2, label=f"observed {s['observed_pct']:.0f} %, p = {s['p_value']:.3g}")
        ax.axvline(s["q95_pct"], color="k", ls=":", lw=0.8, label=f"95 % of the null ({s['q95_pct']:.0f} %)")
        for other, so in sorted(c["null"].items()):
            if other != kind:  # the null that does not bind: its p only (its histogram would not decide)
                ax.plot([], [], " ", label=f"{other.replace('_', '-')} null: p = {so['p_value']:.3g}, "
                                            f"95 % at {so['q95_pct']:.0f} %")
        ax.set_xlabel("held-out shrink (selection statistic) [%]", fontsize=8)
        ax.set_ylabel("draws", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_title(f"{c['effect']}{_variant_label(c.get('variant'))}" + (f", round {rnd}" if multi_round else "")
                     + f": binding null {kind.replace('_', '-')}", fontsize=8)
        ax.legend(fontsize=6, loc="upper center")
    for k in range(len(cands), nrows * cols):
        axes[k // cols][k % cols].remove()
    fig.suptitle(title, fontsize=9)
    return fig


def _figure(title: str, fig) -> str:
    return f'<figure><img src="{png_data_uri(fig)}" alt="{esc(title)}"><figcaption>{esc(title)}</figcaption></figure>'


# --------------------------------------------------------------------------- tables
def _table_short(name: str) -> str:
    return name.split(" (")[0]


def _physical_text(param: str, v: dict) -> str:
    """A parameter in physical units per table (docs/formats.md §5 ``params.<p>.physical``); tables with the same
    value are named together."""
    groups: dict[str, list[str]] = {}
    for table, ph in v["physical"].items():
        if "half_angle_deg" in ph:
            # the length's σ scales with the half-angle's (length ∝ sin θ ≈ θ at these angles)
            length_sd = (ph.get("half_angle_sd_deg") or 0.0) * ph["length_mm"] / max(ph["half_angle_deg"], 1e-12)
            sd = ph.get("half_angle_sd_deg") or None
            text = (f"patch half-angle {fmt_value(ph['half_angle_deg'], sd)}°"
                    + (f" ± {fmt_sigma(sd)}°" if sd else "")
                    + f", length {fmt_value(ph['length_mm'], length_sd or None)} mm")
        elif "omega_rad_s" in ph:
            sd = ph.get("omega_sd_rad_s") or None
            text = "wheel speed Ω " + (fmt_pm(ph["omega_rad_s"], sd, "rad/s") if sd else
                                       f"{fmt_value(ph['omega_rad_s'])} rad/s")
        else:
            text = ", ".join(f"{k} {x}" for k, x in ph.items())
        groups.setdefault(text, []).append(_table_short(table))
    return "; ".join(f"{t} ({', '.join(tabs)})" for t, tabs in groups.items())


def _params_text(candidate: dict) -> str:
    """Each parameter: in physical units where the diagnosis saved them (then the raw value in brackets),
    else value [95 % interval] unit; "fixed by the measured condition" for a computed variant."""
    out = []
    for k, v in candidate.get("params", {}).items():
        if None in (v.get("value"), v.get("lo"), v.get("hi")):
            raw = f"{k} {v.get('value')} [{v.get('lo')}, {v.get('hi')}]"
        else:
            val, lo, hi = fmt_interval(v["value"], v["lo"], v["hi"])
            raw = f"{k} {val} [{lo}, {hi}]"
        unit = v.get("unit")
        if unit and unit != "-":
            raw += f" {unit}"
        if v.get("fixed_by"):
            raw = f"{k} {v.get('value')}, fixed by {v['fixed_by']}"
        out.append(f"{_physical_text(k, v)} <small>({esc(raw)})</small>" if v.get("physical") else esc(raw))
    return "; ".join(out)


def _pct(x) -> str:
    return "—" if x is None else f"{x:.1f}"


def _candidate_rows(pc: dict) -> list[list[str]]:
    out = []
    for x in pc["candidates"]:
        kind = binding_null(x)
        p = f"{x['p_value']:.3g} ({kind.replace('_', '-')})" if kind and x.get("p_value") is not None else ""
        lo, hi = x.get("heldout_shrink_interval_pct") or (None, None)
        out.append([esc(x["effect"]), esc(x.get("variant", "")), _pct(x.get("heldout_shrink_pct")),
                    f"{_pct(lo)} – {_pct(hi)}", esc(x["evidence"].get("delta_bic")), esc(p), _params_text(x),
                    "yes" if x.get("accepted") else esc("; ".join(x.get("rejected_because", []))
                                                        or ("screened out" if x.get("screened_out") else ""))])
    return out


def _parts(content: dict) -> list[dict]:
    return content.get("parts") or [content]


def _family_title(pc: dict) -> str:
    return FAMILY_TITLE.get(pc.get("family", ""), pc.get("family", "")) or "candidates"


def _rows_body(pc: dict) -> tuple[list[str], list[list[str]]]:
    """Header and body of one part's per-row table: values at the precision their σ warrants; damping rows
    (stored as ln ζ) as ζ in %."""
    unit = pc["baseline"].get("unit", "")
    damping = pc.get("family") == "damping" or unit.startswith("ln(")
    if damping:  # ζ = exp(ln ζ) in %, its σ relative (σ of ln ζ ≈ σ_ζ/ζ)
        def val(x, s):
            z = 100.0 * math.exp(x)
            return esc(fmt_value(z, z * s if s else None))
        head = ["row", "model mode", "measured ζ [%]", "baseline ζ [%]", "with effects ζ [%]", "σ [% of ζ]"]
    else:
        def val(x, s):
            return esc(fmt_value(x, s))
        head = ["row", "model mode", f"measured [{unit}]", f"baseline [{unit}]", f"with effects [{unit}]",
                f"σ [{unit}]"]
    body = []
    for r in pc.get("rows") or []:
        s = r.get("sigma")
        sig = esc(fmt_sigma(100 * s) if damping and s is not None else fmt_sigma(s))
        body.append([esc(r["row"]), esc(r.get("model_mode", "")), val(r["measured"], s), val(r["baseline"], s),
                     val(r["with_effects"], s), sig, esc(r["z_baseline"]), esc(r["z_with_effects"]),
                     "<b>outlier</b>" if r["outlier"] else "", esc(r.get("match", ""))])
    return head + ["z baseline", "z with effects", "outlier", "match"], body


def _row_sections(content: dict) -> list[tuple[str, str]]:
    """Per part of mode tables: one row per measured mode (held-out predictions; docs/formats.md §5 ``rows``)."""
    out = []
    for pc in _parts(content):
        if not pc.get("rows"):
            continue
        head, body = _rows_body(pc)
        family = pc.get("family", "")
        out.append((f"Rows — {family}" if family else "Rows", table_html(head, body)))
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


def _baseline_html(b: dict) -> str:
    """The baseline's figures a reader checks (RMS, noise, reduced χ²), without the method's wording."""
    unit = b.get("unit", "")
    if unit.startswith("ln("):
        rms = (f"RMS of ln ζ {fmt_value(b['rms'], None)} (≈ {100 * b['rms']:.0f} % of ζ), held-out "
               f"{fmt_value(b['heldout_rms'], None)}, noise {fmt_value(b.get('noise_rms'), None)}")
    else:
        rms = (f"RMS {fmt_value(b['rms'], None)} {esc(unit)}, held-out {fmt_value(b['heldout_rms'], None)} "
               f"{esc(unit)}, noise {fmt_value(b.get('noise_rms'), None)} {esc(unit)}")
    chi = b.get("reduced_chi2")
    return (f"<p>Baseline {esc(b['model'])}: {rms}; held-out reduced χ² {fmt_value(chi, None)}"
            + (f" (effective dof {b.get('noise_dof')})" if b.get("noise_dof") is not None else "")
            + (f"; a perfect model would remove {b['ideal_shrink_pct']:.0f} %" if b.get("ideal_shrink_pct") is not None
               else "") + ".</p>")


# --------------------------------------------------------------------------- sections
def _verdict_section(c: dict, diag) -> list[tuple[str, str]]:
    v = c["verdict"]
    good = v["effects"] == ["none"] or (v["effects"][0] != "unexplained" and "unexplained" not in v["effects"])
    body = f'<div class="{"ok" if good else "flag"}"><b>{esc(verdict_headline(c))}</b></div>'
    rows = verdict_rows(c)
    if rows:
        body += f"<p>{esc(rows)}</p>"
    dv = v.get("damping")
    if dv:
        effs = " + ".join(dv.get("effects", []))
        body += (f"<p>Damping (judged apart): {esc(effs)}"
                 + (f" — {esc(dv['note'])}" if dv.get("note") else "") + ".</p>")
    near = v.get("nearest")
    if near:  # an unexplained verdict names the candidate that came closest (docs/formats.md §5 verdict.nearest)
        why = "; ".join(near.get("rejected_because") or [])
        body += (f"<p>Nearest candidate: {esc(near.get('effect'))} (held-out shrink "
                 f"{esc(_pct(near.get('heldout_shrink_pct')))} %" + (f"; not accepted: {esc(why)}" if why else "")
                 + ").</p>")
    lab = v.get("labels")
    if lab and lab.get("sentence"):  # labels are evidence: kept, overridden, permutation test (§5 verdict.labels)
        body += f"<p><b>Labels:</b> {esc(lab['sentence'])}.</p>"
    pd = (c["baseline"].get("drift") or {}).get("prior_distance") or {}
    if pd.get("outside"):
        body += f'<div class="flag">{_drift_html(c["baseline"]["drift"])}</div>'
    return [("Verdict", body)]


def _residual_sections(c: dict, diag) -> list[tuple[str, str]]:
    out = []
    for part in diag.parts:
        dom = part.problem.domain
        if dom == "profiles":
            t = "profiles: residual vs angle before/after, per channel and speed"
            out.append(("Residual before and after — profiles", _figure(t, _profile_residual_figure(part))))
        else:
            t = f"{PART_TITLE.get(dom, dom)}: held-out residual per mode, before and after"
            out.append((f"Residual per mode before and after — {PART_TITLE.get(dom, dom)}",
                        _figure(t, _modal_residual_figure(part))))
    return out


def _chance_sections(c: dict, diag) -> list[tuple[str, str]]:
    """Per part: the binding null's histogram of each tested candidate and one labelled line per candidate
    (effect, fitted or computed, round): the binding null's figures and the other nulls' p."""
    out = []
    alpha = c["verdict"].get("alpha")
    for part in diag.parts:
        tested = _null_candidates(part.summary)
        if not tested:
            continue
        name = PART_TITLE.get(part.problem.domain, part.problem.domain)
        multi_round = len({r for r, _ in tested}) > 1
        items = []
        for rnd, cand in tested:
            kind = binding_null(cand)
            s = cand["null"][kind]
            outcome = "accepted" if cand.get("accepted") else "not accepted"
            others = "; ".join(f"{k.replace('_', '-')} null p = {so['p_value']:.3g} (95 % quantile "
                               f"{so['q95_pct']:.0f} %)" for k, so in sorted(cand["null"].items()) if k != kind)
            items.append(f"<li><b>{esc(cand['effect'])}{esc(_variant_label(cand.get('variant')))}</b>"
                         + (f", round {rnd}" if multi_round else "")
                         + f" — binding null: {esc(kind.replace('_', '-'))}; {esc(_null_line(kind, s))} "
                         f"(α = {esc(alpha)}, <b>{outcome}</b>)"
                         + (f". <small>Not binding: {esc(others)}.</small>" if others else "") + "</li>")
        t = f"{name}: held-out shrink against chance (binding null per candidate)"
        out.append((f"Against chance — {name}",
                    "<p>Each accepted effect must beat what the diagnosis's own selection finds in data with no "
                    "effect in it; the null that binds (the larger p) is drawn.</p>"
                    + _figure(t, _null_figure(tested, t)) + f"<ul>{''.join(items)}</ul>"))
    return out


def _table_sections(c: dict, diag) -> list[tuple[str, str]]:
    out = []
    header = ["effect", "variant", "held-out shrink [%]", "95 % interval [%]", "ΔBIC", "p vs chance (binding null)",
              "parameters", "accepted"]
    for pc in _parts(c):
        out.append((f"Candidates — {_family_title(pc)}", table_html(header, _candidate_rows(pc))))
    where = "".join(f"<li>{esc(w['region'])}: {100 * w['share']:.0f} %</li>" for w in c["where"])
    out.append(("Where the residual sits", f"<ul>{where}</ul>"))
    out += _row_sections(c)
    for part in diag.parts:
        dom = part.problem.domain
        name = PART_TITLE.get(dom, dom)
        t = f"{name}: ranked candidates (forest plot)"
        out.append((f"Ranked candidates — {name}", _figure(t, _forest_figure(part))))
        t = f"{name}: held-out predicted vs measured"
        out.append((f"Held-out predicted vs measured — {name}",
                    _figure(t, _profile_heldout_figure(part) if dom == "profiles" else _modal_heldout_figure(part))))
    b = c["baseline"]
    body = f"<p>Data: {esc(', '.join(c['data']))}.</p>" + "".join(_baseline_html(pc["baseline"]) for pc in _parts(c))
    st = b.get("rolling_structure")
    if st:  # the model structure the rolling rows were assigned to, chosen by the data (docs/physics.md §6.4)
        names = {"rolling_loaded": "the rolling, loaded model", "free_spinning": "the free spinning ring (no contact)"}
        costs = ", ".join(f"{esc(names.get(k, k))} {v:.1f}" for k, v in st["cost"].items())
        body += (f"<p><b>Rolling rows</b> assigned to {esc(names.get(st['chosen'], st['chosen']))}, chosen by "
                 f"their lines' fit (cost −2 ln L, lower wins: {costs}).</p>")
    body += _drift_html(b.get("drift"))
    out.append(("Baseline", body))
    return out


def _method_sections(c: dict, diag) -> list[tuple[str, str]]:
    """How σ was estimated, how rows were held out and every rule: folded, for the reader who asks how."""
    items = ""
    for pc in _parts(c):
        b = pc["baseline"]
        items += (f"<li><b>{esc(_family_title(pc))}</b>: noise — {esc(b.get('noise_method', ''))}; held out — "
                  f"{esc(b.get('heldout_method', ''))}.</li>")
    rules = "".join(f"<li><b>{esc(k)}</b>: {esc(v)}</li>" for k, v in c["verdict"].get("rule", {}).items())
    body = ("<details><summary>How σ was estimated, how rows were held out, and the rules applied</summary>"
            "<p>Held-out shrink = 1 − SS_after/SS_before over rows that took no part in the fit, "
            "SS = Σ ψ(r/σ)² (docs/formats.md §5).</p>"
            f"<ul>{items}</ul><p>Rules:</p><ul>{rules}</ul></details>")
    return [("Method", body)]


#: The report's sections in reading order; each ``(content, diag) -> [(heading, html), …]``.
SECTIONS = (_verdict_section, _residual_sections, _chance_sections, _table_sections, _method_sections)


def build_gap_report(diag) -> str:
    """The report page of a :class:`ringfit.gap.Diagnosis` (its saved content and the fits kept with it)."""
    sections = [s for make in SECTIONS for s in make(diag.content, diag)]
    return html_document("Sim-to-real gap diagnosis", sections)


def write_gap_report(diag, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write the HTML report of a :class:`ringfit.gap.Diagnosis` (atomic; refuses to overwrite unless asked)."""
    from ringfit.io.files import atomic_write_text, check_output_path

    path = check_output_path(path, overwrite=overwrite)
    return atomic_write_text(path, build_gap_report(diag))
