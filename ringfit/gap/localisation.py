"""Where the baseline residual lies: by mode and family (mode tables), by angle region, channel and speed (profiles).

Shares are of the noise-standardised residual energy Σ(r/σ)², so a region's
share says how much of the *evidence* against the baseline it holds; they
sum to ≤ 1 (only the leading regions are listed).

Profiles: per channel, the standardised energy is pooled over speeds on
1° bins; contiguous runs of bins whose energy exceeds the channel's mean
bin energy (merged across gaps < 3°) are the regions, ranked by energy,
listed until 90 % of the total is covered (at most 8).
"""

from __future__ import annotations

import numpy as np

from ringfit.gap.problem import GapProblem

MAX_REGIONS = 8
COVER = 0.9


def _top(items: list[tuple[str, float]], total: float, max_items=MAX_REGIONS, cover=COVER) -> list[dict]:
    items = sorted(items, key=lambda t: -t[1])
    out, acc = [], 0.0
    for name, e in items[:max_items]:
        share = e / total if total > 0 else 0.0
        out.append({"region": name, "share": round(float(share), 4)})
        acc += share
        if acc >= cover:
            break
    return out


def localise(problem: GapProblem, resid: np.ndarray) -> dict:
    """``{"where": [...], "by_family": [...], "by_speed": [...]}`` for residual ``resid`` = y − pred, shape ``(m,)``."""
    e = (resid / problem.sigma) ** 2
    total = float(e.sum())
    lab = problem.labels
    if problem.domain in ("modes", "damping"):
        where = _top(list(zip(lab["label"], e)), total)
        fams = {}
        for f, v in zip(lab["family"], e):
            fams[f] = fams.get(f, 0.0) + float(v)
        by_family = [{"family": k, "share": round(v / total, 4) if total > 0 else 0.0}
                     for k, v in sorted(fams.items(), key=lambda t: -t[1])]
        return {"where": where, "by_family": by_family}
    # profiles
    angle, channel, speed = lab["angle_deg"], lab["channel"], lab["speed_kmh"]
    regions = []
    for ch in dict.fromkeys(channel):
        m = channel == ch
        bins = np.floor(angle[m] + 180.0).astype(int) % 360
        energy = np.bincount(bins, weights=e[m], minlength=360)
        hot = energy > energy.mean()
        # runs on the circle, merging gaps shorter than 3 bins
        idx = np.flatnonzero(hot)
        if idx.size == 0:
            continue
        runs, startb, prev = [], idx[0], idx[0]
        for b in idx[1:]:
            if b - prev > 3:
                runs.append((startb, prev))
                startb = b
            prev = b
        runs.append((startb, prev))
        if len(runs) > 1 and runs[0][0] == 0 and runs[-1][1] == 359:
            runs[0] = (runs[-1][0] - 360, runs[0][1])
            runs.pop()
        for a, b in runs:
            sel = np.arange(a, b + 1) % 360
            regions.append((f"{ch} angle {a - 180}..{b + 1 - 180} deg", float(energy[sel].sum())))
    where = _top(regions, total)
    by_speed = []
    for s in dict.fromkeys(speed.tolist()):
        by_speed.append({"speed_kmh": float(s), "share": round(float(e[speed == s].sum() / total), 4)})
    by_channel = [{"channel": str(c), "share": round(float(e[channel == c].sum() / total), 4)}
                  for c in dict.fromkeys(channel.tolist())]
    return {"where": where, "by_speed": by_speed, "by_channel": by_channel}
