"""Self-contained HTML report of a gap diagnosis (embedded PNGs): verdict, where, ranked candidates, held-out fit.

Figures: residual per mode (or vs angle) before/after for the top
candidates, a forest plot of held-out shrink with bootstrap intervals, and
held-out predicted vs measured. The verdict is one sentence for a tyre engineer.
"""

from __future__ import annotations

import base64
import html
import io
import os
from pathlib import Path

import numpy as np


def _png(fig) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(fig)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


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


def figures(diag) -> list[tuple[str, str]]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = []
    for part in diag.parts:
        prob = part.problem
        y = prob.y
        cands = [c for c in part.summary["candidates"] if not c.get("screened_out")][:3]
        # residual before/after
        fig, ax = plt.subplots(figsize=(8, 3.2))
        x = np.arange(prob.m)
        ax.plot(x, (y - part.baseline.pred) / prob.sigma, "k.", label="baseline")
        for c in cands:
            fit = part.fits.get((c["effect"],))
            if fit is not None:
                ax.plot(x, (y - fit.pred) / prob.sigma, ".", label=f"+ {c['effect']}")
        ax.set_xlabel("observation (rows: " + ("modes, by table" if prob.domain == "modes" else "angle, by speed") + ")")
        ax.set_ylabel("residual / noise σ")
        ax.legend(fontsize=7)
        out.append((f"{prob.domain}: residual before/after", _png(fig)))
        # forest plot
        allc = part.summary["candidates"]
        fig, ax = plt.subplots(figsize=(6, 0.4 * len(allc) + 1))
        for i, c in enumerate(allc):
            lo, hi = c["heldout_shrink_interval_pct"]
            ax.plot([lo, hi], [i, i], "-", color="C0")
            ax.plot([c["heldout_shrink_pct"]], [i], "o", color="C2" if c.get("accepted") else "C3")
        ax.set_yticks(range(len(allc)), [c["effect"] for c in allc])
        ax.invert_yaxis()
        ax.axvline(0, color="k", lw=0.5)
        ax.set_xlabel("held-out shrink [%] (95 % bootstrap interval; green = accepted)")
        out.append((f"{prob.domain}: ranked candidates", _png(fig)))
        # held-out predicted vs measured
        fit = part.chain_fit if part.chain_fit is not None else part.baseline
        fig, ax = plt.subplots(figsize=(4.5, 4.5))
        ax.plot(y, part.baseline.heldout_pred, "k.", label="baseline")
        if fit.heldout_pred is not None and fit is not part.baseline:
            ax.plot(y, fit.heldout_pred, ".", color="C2", label=" + ".join(fit.chain))
        lim = [np.nanmin(y), np.nanmax(y)]
        ax.plot(lim, lim, "k-", lw=0.5)
        ax.set_xlabel("measured")
        ax.set_ylabel("held-out predicted")
        ax.legend(fontsize=7)
        out.append((f"{prob.domain}: held-out predicted vs measured", _png(fig)))
    return out


def write_gap_report(diag, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write the HTML report of a :class:`ringfit.gap.Diagnosis` (atomic; refuses to overwrite unless asked)."""
    from ringfit.io.files import atomic_write_text, check_output_path

    path = check_output_path(path, overwrite=overwrite)
    c = diag.content
    rows = "".join(
        f"<tr><td>{html.escape(x['effect'])}</td><td>{x['heldout_shrink_pct']}</td>"
        f"<td>{x['heldout_shrink_interval_pct']}</td><td>{x['evidence'].get('delta_bic')}</td>"
        f"<td>{'yes' if x.get('accepted') else html.escape('; '.join(x.get('rejected_because', [])))}</td></tr>"
        for x in c["candidates"])
    where = "".join(f"<li>{html.escape(w['region'])}: {100 * w['share']:.0f} %</li>" for w in c["where"])
    figs = "".join(f"<h3>{html.escape(t)}</h3><img src='{src}'/>" for t, src in figures(diag))
    doc = f"""<!doctype html><html><head><meta charset="utf-8"><title>ringfit gap diagnosis</title>
<style>body{{font-family:sans-serif;max-width:60em;margin:auto}}td,th{{border:1px solid #ccc;padding:2px 6px}}</style>
</head><body><h1>Sim-to-real gap diagnosis</h1>
<p><b>Verdict:</b> {html.escape(verdict_sentence(c))}</p>
<p>Data: {html.escape(', '.join(c['data']))}. Baseline {html.escape(c['baseline']['model'])}: RMS {c['baseline']['rms']}
{html.escape(c['baseline']['unit'])}, held-out {c['baseline']['heldout_rms']}; noise {html.escape(c['baseline'].get('noise_method', ''))}.</p>
<h2>Where</h2><ul>{where}</ul>
<h2>Which</h2><table><tr><th>effect</th><th>held-out shrink %</th><th>95 % interval</th><th>ΔBIC</th><th>accepted</th></tr>{rows}</table>
<p>Rules: {html.escape(str(c['verdict'].get('rule', '')))}</p>
{figs}</body></html>"""
    return atomic_write_text(path, doc)
