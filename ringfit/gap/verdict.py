"""The verdict: the best effect, ``none`` or ``unexplained`` — stated rules and thresholds (docs/physics.md §6.3).

Whether there is a gap is read from the current model's *held-out* residual, per group of rows (reduced χ² and
its p with coloured noise's effective degrees of freedom: :func:`residual_test`); a candidate is accepted when its
held-out shrink, ΔBIC, effect interval, baseline drift and plausibility pass (:func:`acceptance`, §6.3 conditions
1–5) and it beats its round's null (§6.4, :mod:`ringfit.gap.calibration`); the best accepted one joins a greedy
chain. The thresholds are this module's constants, each with its reason beside it.

Example (the verdict of a diagnosed case folder, docs/formats.md §5)::

    from ringfit.gap import diagnose
    d = diagnose("case/", null_draws=200)
    print(d.verdict["effects"])  # e.g. ["rotation"], ["none"], ["ground_contact", "unexplained"]
"""

from __future__ import annotations

import math

from scipy.special import chdtrc, chdtri  # χ² upper tail and its inverse (scipy.stats costs ~0.5 s to import)

#: Reduced χ² (held-out) above which a residual is called structured (``unexplained`` if nothing removes it).
CHI2_RED_STRUCTURED = 3.0
P_NOISE = 1e-3
#: Held-out shrink of the weighted sum of squares (docs/formats.md §5): 19 % of the SS is 10 % of the RMS.
#: A heuristic bar: below it (down to the floor) the calibrated null decides (:func:`null_decides`).
MIN_HELDOUT_SHRINK_PCT = 19.0
#: The smallest held-out shrink the null may accept: 5 % of the SS (2.5 % of the RMS), a shrink worth reporting.
MIN_HELDOUT_SHRINK_FLOOR_PCT = 5.0
#: A held-out residual carries a *material* gap when, beyond noise, it holds at least the share of its SS that an
#: accepted effect must remove (:data:`MIN_HELDOUT_SHRINK_PCT`): reduced χ² ≥ 1/(1 − 0.19) ≈ 1.235 (the ideal
#: shrink 1 − 1/χ²_red reaching the bar). Below it a residual that fails the noise test (the noise level is
#: estimated, so its χ² p-value is optimistic on long series) is no gap any candidate could be accepted for:
#: ``none``. A pure-noise profile case of an independent simulator read χ²_red 1.106 at p = 5e-4.
CHI2_RED_MATERIAL = 1.0 / (1.0 - MIN_HELDOUT_SHRINK_PCT / 100.0)
#: Lower end of its 95 % bootstrap interval: 9.75 % of the SS is 5 % of the RMS.
MIN_HELDOUT_SHRINK_LO_PCT = 9.75
MAX_DELTA_BIC = -10.0
#: How :func:`acceptance` names a refusal for the bootstrap interval's lower bound (a heuristic: the diagnosis
#: lets the calibrated null decide such a candidate, :func:`null_decides`).
LOWER_BOUND_REASON = "heldout shrink lower bound"
#: Below this many rows (in the deciding group) a bootstrap interval of a sum-of-squares ratio is not
#: informative: it is reported, and acceptance rests on the shrink itself, ΔBIC and the null exclusion.
MIN_INTERVAL_ROWS = 20
MAX_DRIFT_RELATIVE = 0.25
#: Mode tables: a refit may move the reference-state (free-table) predictions by at most this RMS, in σ.
MAX_REFERENCE_DRIFT_SIGMA = 1.0
#: The damping family (a handful of rows, a noise level known to ±50 %) tries its candidates from this p
#: (χ² above its median under noise): refits of a few rows cost ~0.1 s, and whether one is accepted is
#: decided by its held-out evidence and its null. At 0.05 a real damping slope whose residual had p = 0.15
#: (8 rows, σ overestimated) was never refitted.
P_TRY_DAMPING = 0.5
#: Probability content of the prior ellipsoid the guarded baseline parameters must stay in.
PRIOR_REGION = 0.999

#: At the end of the greedy chain a fitted element is replaced by its computed variant (its parameter
#: fixed by the measured condition: no free parameter) when that loses at most this many points of
#: held-out shrink and leaves the residual no more structured (Occam: the data cannot tell them apart).
PREFER_COMPUTED_PTS = 2.0

RULES = {
    "structured": (f"held-out residual / noise: in some row group reduced chi2 >= {CHI2_RED_STRUCTURED} and chi2 "
                   f"test p < {P_NOISE}/groups (effective dof of coloured noise), the group's largest row left out "
                   f"(one row cannot decide); candidates refitted from chi2 test p < {P_NOISE}/groups alone (no bar on the "
                   f"reduced chi2)"),
    "accept": (f"heldout shrink of the weighted sum of squares (1 - SS_after/SS_before) >= "
               f"{MIN_HELDOUT_SHRINK_PCT}% with bootstrap lower bound >= {MIN_HELDOUT_SHRINK_LO_PCT}% (all rows, "
               f"or the rows of the group that decided the structure test; the bound is not used below "
               f"{MIN_INTERVAL_ROWS} rows), delta BIC <= {MAX_DELTA_BIC}, a "
               f"parameter interval excluding its null (a computed effect: its condition value; a composite: in "
               f"every part), baseline drift: "
               f"mode tables - reference-state predictions move <= {MAX_REFERENCE_DRIFT_SIGMA:g} sigma RMS; "
               f"profiles - <= {100 * MAX_DRIFT_RELATIVE:.0f}% relative (parameters with an independent prior: "
               f"Mahalanobis D^2 <= chi2_k({PRIOR_REGION}) or <= that of the baseline fit); the shrink bar and its "
               f"bootstrap bound are heuristics: a candidate failing only them, with heldout shrink >= "
               f"{MIN_HELDOUT_SHRINK_FLOOR_PCT}%, is decided by its calibrated null (accepted when p < alpha); "
               "every fitted effect parameter inside its physical range (an implausible value is not a finding)"),
    "none": ("'none' only when the held-out residual is noise; a residual that fails the noise test with a "
             f"material excess (reduced chi2 without its largest row >= {CHI2_RED_MATERIAL:.3f}, the share an "
             "accepted effect must remove) and no candidate accepted (screened out, refused or implausible) is "
             "'unexplained', verdict.nearest naming the candidate that came closest"),
    "best": ("largest heldout shrink among accepted (a computed variant first on a tie); greedy chain while the "
             f"residual stays structured; then each fitted element of the chain is replaced by its computed variant "
             f"when the chain's held-out shrink drops by <= {PREFER_COMPUTED_PTS:g} points (all at once first)"),
    "damping": (f"damping rows (ln of the damping ratio) form their own problem: candidates are refitted from "
                f"chi2 test p < {P_TRY_DAMPING} (few rows), only damping effects are tried, and an unexplained damping "
                "residual is reported under verdict.damping, never as a structural 'unexplained'"),
}


def residual_test(z, groups, series=None, series_dof=None, p_try: float = P_NOISE) -> dict:
    """χ² test of standardised residuals ``z`` (m,) against pure noise, per group; the most significant group.

    ``groups`` (m,) labels; ``series`` (m,) labels of noise series (default: each row its own)
    with ``series_dof`` {label: effective dof ν} (default: rows). **Returns** ``{"reduced_chi2",
    "p", "group", "dof", "excess", "material", "structured"}`` (see the module docstring).
    """
    import numpy as np

    z = np.asarray(z, dtype=np.float64)
    groups = np.asarray(groups)
    names = list(dict.fromkeys(groups.tolist()))
    best = None
    for g in names:
        sel = groups == g
        rows = int(sel.sum())
        if series is None:
            dof = float(rows)
        else:
            ser = np.asarray(series)[sel]
            labs, counts = np.unique(ser, return_counts=True)
            nu = np.array([float((series_dof or {}).get(lab, c)) for lab, c in zip(labs.tolist(), counts)])
            nu = np.clip(nu, 1.0, counts)
            dof = float(counts.sum() ** 2 / np.sum(counts.astype(float) ** 2 / nu))
        zz = z[sel] ** 2
        red = float(np.sum(zz)) / max(rows, 1)
        p = float(chdtrc(dof, red * dof))
        # one row cannot decide the verdict: the structured level leaves the group's largest row out
        # (it is a named outlier at most); whether candidates are tried uses every row
        rows_t = max(rows - 1, 1)
        dof_t = dof * rows_t / rows if rows > 1 else dof
        red_t = float(np.sum(zz) - np.max(zz)) / rows_t if rows > 1 else red
        p_t = float(chdtrc(dof_t, red_t * dof_t))
        out = {"reduced_chi2": red, "p": p, "group": str(g), "dof": dof,
               "reduced_chi2_without_largest_row": red_t,
               "excess": bool(p < p_try / len(names)),
               "material": bool(red_t >= CHI2_RED_MATERIAL and p_t < P_NOISE / len(names)),
               "structured": bool(red_t >= CHI2_RED_STRUCTURED and p_t < P_NOISE / len(names))}
        if best is None or (out["structured"], out["excess"], red) > (best["structured"], best["excess"],
                                                                      best["reduced_chi2"]):
            best = out
    return best


def acceptance(candidate: dict, bars: bool = True) -> tuple[bool, list[str]]:
    """Apply the acceptance rule to one candidate dict (diagnosis JSON form); returns (accepted, reasons it failed).

    ``bars=False``: condition 1 is the floor :data:`MIN_HELDOUT_SHRINK_FLOOR_PCT` alone (over all rows or the
    deciding group), without the shrink bar and its bootstrap bound — what :func:`null_decides` asks."""
    why = []
    hs = candidate.get("heldout_shrink_pct", -math.inf)
    lo = candidate.get("heldout_shrink_interval_pct", [-math.inf, math.inf])[0]
    hg = candidate.get("heldout_shrink_in_group_pct", -math.inf)
    lg = candidate.get("heldout_shrink_in_group_interval_pct", [-math.inf, math.inf])[0]

    small = candidate.get("rows", MIN_INTERVAL_ROWS) < MIN_INTERVAL_ROWS

    def ok(h, low):
        return h is not None and low is not None and h >= MIN_HELDOUT_SHRINK_PCT and (
            small or low >= MIN_HELDOUT_SHRINK_LO_PCT)

    if not bars:
        if not (_ge(hs, MIN_HELDOUT_SHRINK_FLOOR_PCT) or _ge(hg, MIN_HELDOUT_SHRINK_FLOOR_PCT)):
            where = f" (in {candidate['group']}: {hg:.1f}%)" if "group" in candidate else ""
            why.append(f"heldout shrink {hs:.1f}% < the floor {MIN_HELDOUT_SHRINK_FLOOR_PCT}%{where}")
    elif not (ok(hs, lo) or ok(hg, lg)):
        where = f" (in {candidate['group']}: {hg:.1f}%, lower bound {lg:.1f}%)" if "group" in candidate else ""
        if not hs >= MIN_HELDOUT_SHRINK_PCT:
            why.append(f"heldout shrink {hs:.1f}% < {MIN_HELDOUT_SHRINK_PCT}%{where}")
        else:
            why.append(f"{LOWER_BOUND_REASON} {lo:.1f}% < {MIN_HELDOUT_SHRINK_LO_PCT}%{where}")
    dbic = candidate.get("evidence", {}).get("delta_bic", math.inf)
    if not dbic <= MAX_DELTA_BIC:
        why.append(f"delta BIC {dbic:.1f} > {MAX_DELTA_BIC}")
    params = candidate.get("params", {})
    for k, p in params.items():  # implausible parameters are not findings (docs/physics.md §6.4)
        if p.get("implausible"):
            a, b = p.get("physical_range", (math.nan, math.nan))
            why.append(f"{k} = {p['value']:.4g} {p.get('unit', '')} lies outside its physical range "
                       f"[{a:g}, {b:g}]: not a finding")
    if not any(p.get("excludes_null") for p in params.values()):
        why.append("no parameter interval excludes its null value")
    elif "+" in candidate.get("effect", ""):  # a composite stands only if every part does
        for part in candidate["effect"].split("+"):
            mine = [p for k, p in params.items() if k.startswith(part + ".")]
            if mine and not any(p.get("excludes_null") for p in mine):
                why.append(f"the {part} part: no parameter interval excludes its null value")
    rd = candidate.get("reference_drift_sigma")
    if rd is not None:
        if not rd <= MAX_REFERENCE_DRIFT_SIGMA:
            why.append(f"the reference-state predictions moved {rd:.2f} sigma RMS > {MAX_REFERENCE_DRIFT_SIGMA:g}")
    else:
        d = candidate.get("baseline_drift_max_relative", 0.0)
        if not d <= MAX_DRIFT_RELATIVE:
            why.append(f"baseline parameters drifted {100 * d:.0f}% > {100 * MAX_DRIFT_RELATIVE:.0f}%")
    pd = candidate.get("baseline_prior_distance")
    if pd and pd.get("k"):
        limit = float(chdtri(pd["k"], 1.0 - PRIOR_REGION))
        if not (pd["d2"] <= limit or pd["d2"] <= pd["d2_baseline_fit"]):
            why.append(f"baseline ring parameters left their free-table prior (D^2 {pd['d2']:.1f} > {limit:.1f})")
    return (not why), why


def _ge(x, bar: float) -> bool:
    return x is not None and x >= bar


def null_decides(candidate: dict) -> bool:
    """Whether the calibrated null decides a candidate the rule refused: it failed only the heuristic bars of
    condition 1 (the shrink bar, the bootstrap bound) and its held-out shrink reaches the floor
    :data:`MIN_HELDOUT_SHRINK_FLOOR_PCT`; every other condition (ΔBIC, a parameter interval excluding its null,
    the baseline drift) holds. Screened-out candidates were not refitted: never."""
    if candidate.get("accepted") or candidate.get("screened_out") or not candidate.get("rejected_because"):
        return False
    return acceptance(candidate, bars=False)[0]
