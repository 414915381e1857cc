"""Campaign table and report: many tyres of one model, from their SAVED results (docs/formats.md §13).

:func:`collect_campaign` reads, per tyre, the files ``ringfit campaign`` wrote
— the fitted tyre TOML (least squares), the posterior HDF5 (draws), the
diagnosis JSON (docs/formats.md §5) — and never refits or resamples. A file is
read only when the step that writes it succeeded in this run (or was kept by
``--skip-existing``), so a stale file from an earlier run never enters the table.

Outliers (:func:`batch_distances`): each tyre's posterior mean of the
log-parameters (of the parameters themselves where one can be ≤ 0) is compared with the batch of the *other* tyres (leave one
out, so an outlier does not widen the yardstick it is measured with):
Mahalanobis distance d² = (x − m)ᵀ S⁻¹ (x − m) with m, S the others' mean and
sample covariance. For tyres of one population, (n/(n+1))·d² is Hotelling's
T²(k, n−1) with n the other tyres and k the parameters, so
F = T²·(n−k)/(k(n−1)) follows F(k, n−k); a tyre is flagged when its p-value
is below 0.05/N (Bonferroni over the N tyres: a batch without outliers has
at most a 5 % chance of any flag). It needs n ≥ k + 2 other tyres.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ringfit.io.files import csv_text
from ringfit.report.figures import new_figure
from ringfit.report.free_plots import LABELS
from ringfit.report.html import esc, figure_html, fmt, html_document, table_html
from ringfit.report.numbers import fmt_interval

#: Family-wise false-flag rate of the outlier test (Bonferroni over the tyres).
OUTLIER_ALPHA = 0.05
#: Steps of a campaign in order (a tyre's first failed step is reported).
STEPS = ("ssi", "fit", "sample", "identify", "diagnose")


@dataclass
class Campaign:
    """A campaign's table and what the report draws.

    - ``rows``: one dict per tyre, keys = the CSV columns (:attr:`columns`).
    - ``parameters``: short names of the sampled parameters, ``(k,)``.
    - ``median``, ``lo``, ``hi``: ``(N, k)`` posterior median and 95 % interval (SI; NaN without a posterior).
    - ``distances``: what :func:`batch_distances` returned.
    - ``failures``: ``(tyre, step, state, error)`` of every step that did not succeed.
    """

    rows: list[dict]
    parameters: list[str]
    median: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    distances: dict
    failures: list[tuple[str, str, str, str]] = field(default_factory=list)

    @property
    def tyres(self) -> list[str]:
        return [r["tyre"] for r in self.rows]

    @property
    def columns(self) -> list[str]:
        cols = ["tyre", "status", "failed_step", "error", "targets", "modes"]
        for p in self.parameters:
            key = _toml_key(p)
            cols += [key, f"{key}_median", f"{key}_lo", f"{key}_hi"]
        return cols + ["sampler_converged", "verdict", "heldout_shrink_pct", "distance", "p_value", "outlier"]

    def verdict_counts(self) -> dict[str, int]:
        """How many tyres got each gap verdict, most frequent first."""
        counts: dict[str, int] = {}
        for r in self.rows:
            v = r.get("verdict") or "(no diagnosis)"
            counts[v] = counts.get(v, 0) + 1
        return dict(sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))

    def summary_line(self) -> str:
        """One line: tyres complete, tyres with a failed step, and the outliers."""
        ok = sum(r["status"] == "ok" for r in self.rows)
        flagged = [r["tyre"] for r in self.rows if r.get("outlier") is True]
        return (f"{ok} complete, {len(self.rows) - ok} with a failed step; "
                + (f"outliers: {', '.join(flagged)}" if flagged else
                   "no outlier" if self.distances.get("tested") else "too few tyres for the outlier test"))


def _toml_key(short: str) -> str:
    from ringfit.params import RING_PARAMETERS

    return RING_PARAMETERS[short][1] if short in RING_PARAMETERS else short


# ============================================================================ outliers
def batch_distances(log_means: np.ndarray, alpha: float = OUTLIER_ALPHA) -> dict:
    """Leave-one-out Mahalanobis distance of each tyre from the rest of the batch.

    **Arguments:**

    - ``log_means``: ``(N, k)`` posterior means of the log-parameters; rows
      with a NaN take no part (their results are NaN).
    - ``alpha``: family-wise false-flag rate; a tyre is flagged when its
      p-value is below ``alpha / N_used``.

    **Returns:** dict with ``distance`` ``(N,)`` (d, in units of the batch's
    spread), ``p_value`` ``(N,)``, ``outlier`` ``(N,)`` bool, ``threshold``
    (the d above which a tyre is flagged), ``tested`` (False when fewer than
    k + 3 usable tyres), ``n_used``, ``k``, ``alpha``.
    """
    from scipy import stats

    x = np.asarray(log_means, dtype=float)
    N, k = x.shape
    use = np.all(np.isfinite(x), axis=1)
    n_used = int(use.sum())
    dist = np.full(N, np.nan)
    pval = np.full(N, np.nan)
    out = dict(distance=dist, p_value=pval, outlier=np.zeros(N, bool), threshold=float("nan"),
               tested=False, n_used=n_used, k=k, alpha=alpha)
    n = n_used - 1  # the others
    if k == 0 or n < k + 2:
        return out
    idx = np.flatnonzero(use)
    for i in idx:
        others = x[idx[idx != i]]
        m = others.mean(axis=0)
        S = np.cov(others, rowvar=False, ddof=1).reshape(k, k)
        d = x[i] - m
        try:
            d2 = float(d @ np.linalg.solve(S, d))
        except np.linalg.LinAlgError:
            continue
        f_stat = (n / (n + 1.0)) * d2 * (n - k) / (k * (n - 1.0))
        dist[i] = math.sqrt(max(d2, 0.0))
        pval[i] = float(stats.f.sf(f_stat, k, n - k))
    level = alpha / n_used
    f_crit = float(stats.f.isf(level, k, n - k))
    out["threshold"] = math.sqrt(f_crit * k * (n - 1.0) / (n - k) * (n + 1.0) / n)
    out["outlier"] = np.where(np.isfinite(pval), pval < level, False)
    out["tested"] = True
    return out


# ============================================================================ reading the saved results
def collect_campaign(layout: dict[str, dict], results=()) -> Campaign:
    """The campaign table from the files each tyre's steps wrote.

    **Arguments:**

    - ``layout``: tyre → paths (``fitted``, ``posterior``, ``diagnosis``,
      ``targets``, ``records``), as :func:`ringfit.cli.batch.plan_campaign` makes.
    - ``results``: the :class:`ringfit.batch.TaskResult` of every step (named
      ``TYRE/STEP``); a file is read only if its step succeeded. Without
      results every existing file is read.
    """
    from ringfit.fit.posterior import load_posterior
    from ringfit.gap.diagnosis import read_diagnosis
    from ringfit.io.tyre import read_tyre
    from ringfit.params import RING_PARAMETERS

    by_name = {r.name: r for r in results}

    def usable(tyre: str, step: str, path) -> bool:
        r = by_name.get(f"{tyre}/{step}")
        return bool(path) and Path(path).exists() and (r is None if not by_name else r is not None and r.ok)

    rows, posts, failures = [], {}, []
    for tyre, paths in layout.items():
        row: dict = {"tyre": tyre, "status": "ok", "failed_step": "", "error": ""}
        for step in STEPS:
            r = by_name.get(f"{tyre}/{step}")
            if r is not None and not r.ok:
                failures.append((tyre, step, r.state, r.error))
                if not row["failed_step"]:
                    row.update(status="failed", failed_step=step, error=r.error)
        row["targets"] = (f"ssi:{Path(paths['records']).name}" if paths.get("records")
                          else Path(paths["targets"]).name)
        # a tyre with joint data is identified once (step "identify": its tyre file and posterior), others are fitted
        # to their free modes and sampled (steps "fit", "sample"); the diagnosis reads the same tyre file
        identified = bool(paths.get("identified"))
        if usable(tyre, "identify" if identified else "fit", paths.get("fitted")):
            row["_lsq"] = read_tyre(paths["fitted"]).ring_values
        if usable(tyre, "identify" if identified else "sample", paths.get("posterior")):
            post = load_posterior(paths["posterior"])
            posts[tyre] = post
            data = post.meta.get("data") or {}
            if "n" in data:
                row["modes"] = int(np.asarray(data["n"]).size)
            row["sampler_converged"] = bool(post.converged)
        if usable(tyre, "diagnose", paths.get("diagnosis")):
            v = read_diagnosis(paths["diagnosis"])["verdict"]
            row["verdict"] = "+".join(v.get("effects") or [v["effect"]])
            shrink = v.get("heldout_shrink_pct")
            row["heldout_shrink_pct"] = shrink if v["effect"] not in ("none", "unexplained") else None
        rows.append(row)

    # ring parameters (and any effect parameters); not the identification's per-run nuisances (gain_i, angle_offset_i)
    names = {n for p in posts.values() for n in p.names if not n.startswith(("gain_", "angle_offset_"))}
    parameters = [p for p in RING_PARAMETERS if p in names] + sorted(names - set(RING_PARAMETERS))
    N, k = len(rows), len(parameters)
    median, lo, hi = (np.full((N, k), np.nan) for _ in range(3))
    log_mean = np.full((N, k), np.nan)
    for i, row in enumerate(rows):
        post = posts.get(row["tyre"])
        lsq = row.pop("_lsq", {})
        summary = {s["name"]: s for s in post.summary_table()} if post is not None else {}
        if post is not None and set(parameters) <= set(post.names):
            draws = post.samples
            log_mean[i] = [np.log(draws[:, j]).mean() if np.all(draws[:, j] > 0) else draws[:, j].mean()
                           for j in (post.names.index(p) for p in parameters)]
        for j, p in enumerate(parameters):
            key = _toml_key(p)
            row[key] = lsq.get(p)
            s = summary.get(p)
            if s is not None:
                median[i, j], lo[i, j], hi[i, j] = s["median"], s["lo"], s["hi"]
            row[f"{key}_median"], row[f"{key}_lo"], row[f"{key}_hi"] = (
                (s["median"], s["lo"], s["hi"]) if s is not None else (None, None, None))
    distances = batch_distances(log_mean)
    for i, row in enumerate(rows):
        if np.isfinite(distances["distance"][i]):
            row["distance"] = float(distances["distance"][i])
            row["p_value"] = float(distances["p_value"][i])
            row["outlier"] = bool(distances["outlier"][i])
    return Campaign(rows, parameters, median, lo, hi, distances, failures)


# ============================================================================ CSV
def campaign_csv(campaign: Campaign) -> str:
    """The campaign table as CSV text (docs/formats.md §13)."""
    cols = campaign.columns
    return csv_text(cols, ([row.get(c) for c in cols] for row in campaign.rows))


def write_campaign_csv(campaign: Campaign, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write :func:`campaign_csv` atomically; refuses to overwrite unless ``overwrite``."""
    from ringfit.io.files import atomic_write_text, check_output_path

    path = check_output_path(path, overwrite=overwrite)
    return atomic_write_text(path, campaign_csv(campaign))


# ============================================================================ figures
def spread_figure(campaign: Campaign):
    """One panel per parameter: each tyre's posterior median and 95 % interval, the batch median and spread."""
    k, N = len(campaign.parameters), len(campaign.rows)
    fig, axes = new_figure(k, 1, figsize=(max(7.0, 1.6 + 0.22 * N), 1.9 * k + 0.8), sharex=True, squeeze=False)
    x = np.arange(N)
    flagged = np.asarray(campaign.distances["outlier"], bool)
    for j, p in enumerate(campaign.parameters):
        ax = axes[j, 0]
        med, lo, hi = campaign.median[:, j], campaign.lo[:, j], campaign.hi[:, j]
        ok = np.isfinite(med)
        if ok.any():
            centre = float(np.median(med[ok]))
            q = np.percentile(med[ok], [2.5, 97.5])
            ax.axhspan(q[0], q[1], color="#dde6f3", label="batch: 95 % of the medians")
            ax.axhline(centre, color="#4a6fa5", lw=1, label="batch median")
        for sel, colour, label in ((ok & ~flagged, "#1d2330", "tyre: median, 95 % interval"),
                                   (ok & flagged, "#c0392b", "flagged outlier")):
            if sel.any():
                ax.errorbar(x[sel], med[sel], yerr=[med[sel] - lo[sel], hi[sel] - med[sel]], fmt="o", ms=3.5,
                            color=colour, ecolor=colour, elinewidth=1, capsize=2, label=label)
        ax.set_yscale("log")
        ax.set_ylabel(LABELS.get(p, p))
        ax.grid(alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=7, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncols=4, frameon=False)
    fig.suptitle("Ring parameters across the batch (posterior medians with 95 % intervals)")
    axes[-1, 0].set_xticks(x, campaign.tyres, rotation=60 if N > 6 else 0, ha="right" if N > 6 else "center",
                           fontsize=7 if N > 12 else 9)
    axes[-1, 0].set_xlabel("tyre")
    fig.tight_layout()
    return fig


def distance_figure(campaign: Campaign):
    """Each tyre's Mahalanobis distance from the other tyres, with the flag threshold."""
    d = campaign.distances
    N = len(campaign.rows)
    fig, ax = new_figure(figsize=(max(7.0, 1.6 + 0.22 * N), 3.2))
    x = np.arange(N)
    dist = np.nan_to_num(np.asarray(d["distance"], float), nan=0.0)
    colours = np.where(np.asarray(d["outlier"], bool), "#c0392b", "#4a6fa5")
    ax.bar(x, dist, color=colours)
    ax.axhline(d["threshold"], color="#c0392b", ls="--", lw=1,
               label=f"flag threshold (p < {d['alpha']:g}/{d['n_used']})")
    ax.set_xticks(x, campaign.tyres, rotation=60 if N > 6 else 0, ha="right" if N > 6 else "center",
                  fontsize=7 if N > 12 else 9)
    ax.set_xlabel("tyre")
    ax.set_ylabel("Mahalanobis distance d [-]")
    ax.set_title("Distance of each tyre's posterior mean from the rest of the batch (log-parameters)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def verdict_figure(counts: dict[str, int]):
    """Bar chart of the diagnosis verdicts."""
    fig, ax = new_figure(figsize=(7.0, 0.5 + 0.35 * max(len(counts), 2)))
    labels = list(counts)[::-1]
    ax.barh(np.arange(len(labels)), [counts[v] for v in labels], color="#4a6fa5")
    ax.set_yticks(np.arange(len(labels)), labels)
    ax.set_xlabel("tyres [count]")
    ax.set_title("Gap diagnosis verdicts across the batch")
    fig.tight_layout()
    return fig


# ============================================================================ HTML
def build_campaign_report(campaign: Campaign, title: str = "ringfit campaign") -> str:
    """The self-contained HTML page of a campaign."""
    rows, d = campaign.rows, campaign.distances
    N = len(rows)
    complete = sum(r["status"] == "ok" for r in rows)
    sections = []
    over = (f"<p>{N} tyres; {complete} went through every step (targets → fit → posterior → diagnosis). "
            f"Every figure and number below is read from the saved result files (fitted tyre TOML, posterior "
            f"HDF5, diagnosis JSON); nothing is refitted.</p>")
    if campaign.failures:
        over += '<div class="flag">Steps that did not succeed:</div>' + table_html(
            ["tyre", "step", "state", "error"],
            [[esc(t), esc(s), esc(st), esc(e)] for t, s, st, e in campaign.failures], left_cols=4)
    else:
        over += '<div class="ok">Every step of every tyre succeeded.</div>'
    sections.append(("Summary", over))

    counts = campaign.verdict_counts()
    sections.append(("Verdicts", table_html(["verdict", "tyres"], [[esc(v), str(c)] for v, c in counts.items()])
                     + figure_html(verdict_figure(counts), "verdict counts")))

    if campaign.parameters and np.isfinite(campaign.median).any():
        sections.append(("Parameter spread", "<p>Posterior median and 95 % interval of each tyre; the band is "
                         "the central 95 % of the tyres' medians.</p>"
                         + figure_html(spread_figure(campaign), "parameter spread across the batch")))
    if d["tested"]:
        flagged = [campaign.tyres[i] for i in np.flatnonzero(d["outlier"])]
        text = (f"<p>Each tyre's posterior mean of the log-parameters ({', '.join(map(esc, campaign.parameters))}) "
                f"is compared with the other {d['n_used'] - 1} tyres: Mahalanobis distance d with their mean and "
                f"sample covariance. For one population (n/(n+1))·d² is Hotelling's T²(k, n−1) (n other tyres, "
                f"k = {d['k']} parameters); a tyre is flagged when p &lt; {d['alpha']:g}/{d['n_used']} "
                f"(Bonferroni: at most a {100 * d['alpha']:g} % chance of any flag in a batch without outliers), "
                f"i.e. d &gt; {d['threshold']:.2f}.</p>")
        text += (f'<div class="flag">Flagged: {esc(", ".join(flagged))}</div>' if flagged else
                 '<div class="ok">No tyre stands out from the batch.</div>')
        sections.append(("Outliers", text + figure_html(distance_figure(campaign), "distance from the batch")))
    else:
        sections.append(("Outliers", f"<p class='muted'>The outlier test needs at least k + 3 = "
                                     f"{d['k'] + 3} tyres with a posterior; this batch has {d['n_used']}.</p>"))

    header = ["tyre", "status", "targets"] + [LABELS.get(p, p) + " median (95 %)" for p in campaign.parameters]
    header += ["sampler", "verdict", "held-out shrink [%]", "distance"]
    body = []
    for i, r in enumerate(rows):
        cells = [esc(r["tyre"]), esc(r["status"] if r["status"] == "ok" else f"{r['failed_step']} failed"),
                 esc(r["targets"])]
        for j in range(len(campaign.parameters)):
            m = campaign.median[i, j]
            if np.isfinite(m):  # to the digits the interval warrants (ringfit/report/numbers.py)
                med, lo, hi = fmt_interval(m, campaign.lo[i, j], campaign.hi[i, j])
                cells.append(f"{med} ({lo} – {hi})")
            else:
                cells.append("—")
        conv = r.get("sampler_converged")
        cells.append("—" if conv is None else "converged" if conv else "<b>short chain</b>")
        cells.append(esc(r.get("verdict") or "—"))
        shrink = r.get("heldout_shrink_pct")
        cells.append(fmt(shrink, 3) if shrink is not None else "—")
        dist = r.get("distance")
        cells.append("—" if dist is None else (f"<b>{dist:.2f}</b>" if r.get("outlier") else f"{dist:.2f}"))
        body.append(cells)
    sections.append(("Campaign table", table_html(header, body, left_cols=3)
                     + "<p class='muted'>The same table with full precision: campaign.csv.</p>"))
    return html_document(title, sections, subtitle=f"{N} tyres of one batch: ring parameters, diagnosis, outliers")


def write_campaign_report(campaign: Campaign, path: str | os.PathLike, *, overwrite: bool = False,
                          title: str = "ringfit campaign") -> Path:
    """Write :func:`build_campaign_report` atomically; refuses to overwrite unless ``overwrite``."""
    from ringfit.io.files import atomic_write_text, check_output_path

    path = check_output_path(path, overwrite=overwrite)
    return atomic_write_text(path, build_campaign_report(campaign, title))
