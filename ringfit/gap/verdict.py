"""The verdict: the best effect, ``none`` or ``unexplained`` — stated rules and thresholds.

**Is there a gap?** The residual of the current model (baseline, then the
accepted chain) is *structured* when both

- in at least one group of rows (mode tables: frequency rows, damping rows;
  profiles: each channel) the reduced χ² (noise-standardised, in-sample) is
  at least :data:`CHI2_RED_STRUCTURED` (the RMS is ≥ 1.73× the noise level:
  below that the best possible shrink is < 42 %, and a noise level estimated
  from the data — coloured noise included — is not trusted to better than that), and
- the χ² test of that group rejects pure noise at p < :data:`P_NOISE` / groups.

Otherwise the verdict is ``none`` (or the chain stops).

**Is an effect accepted?** All of:

1. held-out shrink ≥ :data:`MIN_HELDOUT_SHRINK_PCT` and the lower end of its
   95 % bootstrap interval ≥ :data:`MIN_HELDOUT_SHRINK_LO_PCT`
   (it removes residual on data that took no part in fitting it);
2. ΔBIC ≤ :data:`MAX_DELTA_BIC` (strong evidence in-sample, with the
   parameter-count penalty);
3. at least one effect parameter's 95 % interval excludes its null value;
4. no baseline parameter moved by more than :data:`MAX_DRIFT_RELATIVE` (relative)
   from the reference baseline fit (the effect does not win by letting the
   baseline drift to implausible values). The drift in standard errors is
   reported too, but not used: when the baseline fit absorbed part of a
   real effect, adding the right effect moves it back by many (small)
   standard errors.

Among accepted candidates the best is the largest held-out shrink.
**Greedy chain**: the best is added, the rest are refitted on top of it, and
so on while the residual stays structured. If a structured residual remains
and nothing is accepted, ``unexplained`` closes the chain.
"""

from __future__ import annotations

import math

from scipy.stats import chi2 as chi2_dist

CHI2_RED_STRUCTURED = 3.0
P_NOISE = 1e-3
MIN_HELDOUT_SHRINK_PCT = 10.0
MIN_HELDOUT_SHRINK_LO_PCT = 5.0
MAX_DELTA_BIC = -10.0
MAX_DRIFT_RELATIVE = 0.25

RULES = {
    "structured": f"in some row group reduced chi2 >= {CHI2_RED_STRUCTURED} and chi2 test p < {P_NOISE}/groups",
    "accept": (f"heldout shrink >= {MIN_HELDOUT_SHRINK_PCT}% with bootstrap lower bound >= "
               f"{MIN_HELDOUT_SHRINK_LO_PCT}%, delta BIC <= {MAX_DELTA_BIC}, a parameter interval excluding its "
               f"null, baseline drift <= {100 * MAX_DRIFT_RELATIVE:.0f}% relative"),
    "best": "largest heldout shrink among accepted; greedy chain while the residual stays structured",
}


def is_structured(z, groups, k: int) -> tuple[bool, float, float]:
    """``(structured, reduced χ², p-value)`` of standardised residuals ``z`` (m,) with k fitted parameters.

    Tested per group (``groups`` (m,) labels); the returned χ² figures are of the
    most significant group. The k parameters are shared out over groups by size.
    """
    import numpy as np

    z = np.asarray(z)
    groups = np.asarray(groups)
    names = list(dict.fromkeys(groups.tolist()))
    best = (False, 0.0, 1.0)
    for g in names:
        sel = groups == g
        mg = int(sel.sum())
        dof = max(mg - k * mg / z.size, 1.0)
        c2 = float(np.sum(z[sel] ** 2))
        red, p = c2 / dof, float(chi2_dist.sf(c2, dof))
        hit = red >= CHI2_RED_STRUCTURED and p < P_NOISE / len(names)
        if (hit, -p) > (best[0], -best[2]):
            best = (hit, red, p)
    return best


def acceptance(candidate: dict) -> tuple[bool, list[str]]:
    """Apply the acceptance rule to one candidate dict (diagnosis JSON form); returns (accepted, reasons it failed)."""
    why = []
    hs = candidate.get("heldout_shrink_pct", -math.inf)
    lo = candidate.get("heldout_shrink_interval_pct", [-math.inf, math.inf])[0]
    if not hs >= MIN_HELDOUT_SHRINK_PCT:
        why.append(f"heldout shrink {hs:.1f}% < {MIN_HELDOUT_SHRINK_PCT}%")
    elif not lo >= MIN_HELDOUT_SHRINK_LO_PCT:
        why.append(f"heldout shrink lower bound {lo:.1f}% < {MIN_HELDOUT_SHRINK_LO_PCT}%")
    dbic = candidate.get("evidence", {}).get("delta_bic", math.inf)
    if not dbic <= MAX_DELTA_BIC:
        why.append(f"delta BIC {dbic:.1f} > {MAX_DELTA_BIC}")
    if not any(p.get("excludes_null") for p in candidate.get("params", {}).values()):
        why.append("no parameter interval excludes its null value")
    d = candidate.get("baseline_drift_max_relative", 0.0)
    if not d <= MAX_DRIFT_RELATIVE:
        why.append(f"baseline parameters drifted {100 * d:.0f}% > {100 * MAX_DRIFT_RELATIVE:.0f}%")
    return (not why), why
