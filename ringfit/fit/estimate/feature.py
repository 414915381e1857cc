"""The classic feature method (docs/physics.md §10): the two edge peaks of the band-limited radial
reading, their spacing → load through the model's load–spacing curve
(:class:`~ringfit.fit.estimate.curves.LoadCurves`). It starts the fit and is reported beside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ringfit.fit.estimate.harmonics import grid_signal

#: Points of the band-limited reading searched for the edge peaks (0.09° spacing).
PEAK_GRID = 4096
#: The edge peaks are searched within this angle [deg] of the dip.
PEAK_SEARCH_DEG = 60.0


def edge_peaks(amplitudes, k_min: int = 2) -> np.ndarray:
    """Edge peaks of radial readings given by their harmonic amplitudes ``(..., K)`` (k = k_min…).

    The patch is the deepest dip of the band-limited reading; the edge peaks are its
    maxima within :data:`PEAK_SEARCH_DEG` before and after the dip (refined by a parabola
    through the three highest points). **Returns:** ``(..., 4)``: leading, trailing [deg]
    (the reading's angle), their spacing and the dip's angle [deg]; NaN where no peak stands out.
    """
    x = grid_signal(amplitudes, k_min, PEAK_GRID)
    flat = x.reshape(-1, PEAK_GRID)
    out = np.array([_edge_peaks_one(row) for row in flat])
    return out.reshape(x.shape[:-1] + (4,))


def _edge_peaks_one(x: np.ndarray) -> tuple[float, float, float, float]:
    step = 360.0 / PEAK_GRID
    i_dip = int(np.argmin(x))
    reach = int(PEAK_SEARCH_DEG / step)
    idx = (i_dip + np.arange(-reach, reach + 1)) % PEAK_GRID
    seg = x[idx]
    centre = reach

    def peak(lo, hi):
        j = lo + int(np.argmax(seg[lo:hi]))
        if j in (lo, hi - 1):  # the maximum sits at the end of the search range: no peak
            return math.nan
        y0, y1, y2 = seg[j - 1], seg[j], seg[j + 1]
        den = y0 - 2 * y1 + y2
        frac = 0.5 * (y0 - y2) / den if den < 0 else 0.0
        return (j - centre + frac) * step

    lead, trail = peak(0, centre), peak(centre + 1, 2 * reach + 1)
    dip = -180.0 + i_dip * step
    return dip + lead, dip + trail, trail - lead, dip


@dataclass(frozen=True)
class FeatureEstimate:
    """The classic method: edge-peak angles [deg] of the radial reading, their spacing as a length
    along the outer radius [mm], and the load [N] whose model shows that spacing (NaN if outside)."""

    load_n: float
    leading_deg: float
    trailing_deg: float
    spacing_mm: float

    def to_record(self) -> dict:
        """The feature estimate as a JSON-ready dict (docs/formats.md §7)."""
        return {"load_n": _num(self.load_n), "peak_leading_deg": _num(self.leading_deg),
                "peak_trailing_deg": _num(self.trailing_deg), "peak_spacing_mm": _num(self.spacing_mm),
                "method": "edge peaks of the radial reading (harmonics 2…k_max) → load through the model's "
                          "load–spacing curve"}


def feature_estimate(amplitudes, curves, outer_radius: float) -> FeatureEstimate:
    """The classic feature method on measured radial amplitudes ``(K,)`` (k = 2…, band limited like ``curves``, a
    :class:`~ringfit.fit.estimate.curves.LoadCurves`, which imports this module for its own edge peaks)."""
    lead, trail, spacing, _ = edge_peaks(amplitudes, 2)
    load = float(curves.load_from_spacing(spacing)) if math.isfinite(spacing) else math.nan
    return FeatureEstimate(load, lead, trail, 1e3 * outer_radius * math.radians(spacing))


def _num(x):
    x = float(x)
    return x if math.isfinite(x) else None
