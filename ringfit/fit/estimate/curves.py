"""Load curves: the model at a grid of loads — patch and edge-peak feature against load (docs/physics.md §10).

One vmapped contact solve at log-spaced loads over :data:`~ringfit.fit.estimate.problem.LOAD_RANGE`
gives the patch (interpolated at the fitted load for the report), the edge-peak spacing (the feature
method's load–spacing curve) and the model readings (starting gain, sign check).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import equinox as eqx
import jax
import numpy as np

from ringfit.fit.estimate.feature import edge_peaks
from ringfit.fit.estimate.harmonics import harmonic_amplitudes
from ringfit.fit.estimate.problem import LOAD_RANGE, EstimateSettings
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.contact import ContactSolver, as_traced, contact_length, patch_edges
from ringfit.physics.profile import ProfileModel, flat_or_drum, rolling_state

@dataclass(frozen=True)
class LoadCurves:
    """The model at a grid of loads (same tyre, road, Ω): patch and edge-peak feature vs load.

    ``load_n`` ``(G,)``; ``length_mm``, ``leading_deg``, ``trailing_deg`` ``(G,)`` the contact patch
    (docs/physics.md §4.4); ``peak_spacing_deg`` ``(G,)`` the angle between the radial reading's two
    edge peaks (band-limited to k ≤ ``k_max``); ``ok`` ``(G,)`` contact solved inside its window.
    """

    load_n: np.ndarray
    length_mm: np.ndarray
    leading_deg: np.ndarray
    trailing_deg: np.ndarray
    peak_spacing_deg: np.ndarray
    peak_mid_deg: np.ndarray
    amplitudes: np.ndarray
    ok: np.ndarray
    k_max: int

    def _interp(self, y, load):
        good = self.ok
        return np.interp(np.log(np.asarray(load, dtype=np.float64)), np.log(self.load_n[good]), y[good])

    def patch_at(self, load) -> dict:
        """Patch length [mm], leading and trailing edge [deg] at ``load`` [N] (scalar or array)."""
        return {"length_mm": self._interp(self.length_mm, load), "leading_deg": self._interp(self.leading_deg, load),
                "trailing_deg": self._interp(self.trailing_deg, load)}

    def gain_at(self, load: float, amplitudes) -> float:
        """Least-squares gain of measured amplitudes ``(K,)`` on the curve's model at the nearest load (0.6–1.6)."""
        model = self.amplitudes[int(np.argmin(np.abs(np.log(self.load_n / load))))]
        g = np.sum(np.abs(np.asarray(amplitudes) * model)) / max(float(np.sum(np.abs(model) ** 2)), 1e-300)
        return float(np.clip(g, 0.6, 1.6))

    def load_from_spacing(self, spacing_deg) -> np.ndarray:
        """Load [N] whose model edge-peak spacing is ``spacing_deg`` (NaN outside the curve)."""
        good = self.ok & np.isfinite(self.peak_spacing_deg)
        s, L = self.peak_spacing_deg[good], np.log(self.load_n[good])
        order = np.argsort(s)
        s, L = s[order], L[order]
        x = np.asarray(spacing_deg, dtype=np.float64)
        out = np.exp(np.interp(x, s, L))
        return np.where((x >= s[0]) & (x <= s[-1]), out, np.nan)


@eqx.filter_jit
def _curve_states(model, ring, geometry, omega, loads, roads, solver):
    def one(load, road):
        from ringfit.physics.operating import OperatingPoint

        sol, ch = rolling_state(model, ring, geometry, OperatingPoint(omega, load, road), solver)
        lead, trail = patch_edges(sol)
        return ch[0], lead, trail, contact_length(sol), sol.ok

    return jax.vmap(one)(loads, roads)


def load_curves(geometry: TyreGeometry, ring: RingParams, omega: float, drum_diameter_m=None, *,
                settings: EstimateSettings = EstimateSettings(), k_max: int | None = None) -> LoadCurves:
    """The model's patch and edge-peak spacing at ``settings.curve_points`` loads log-spaced over
    :data:`LOAD_RANGE` (one vmapped solve on ``settings.curve_grid`` points; baseline sensor).

    **Arguments:** the tyre, Ω [rad/s] (the shape does not depend on it for χ = 1), the drum
    diameter [m] or None (flat road), the settings; ``k_max``: band limit of the peak feature.
    """
    k_max = settings.k_max if k_max is None else int(k_max)
    G = settings.curve_points
    loads = np.exp(np.linspace(math.log(LOAD_RANGE[0]), math.log(LOAD_RANGE[1]), G))
    solver = ContactSolver(n_grid=settings.curve_grid, window_deg=settings.window_deg)
    roads = flat_or_drum(drum_diameter_m, G)
    rad, lead, trail, length, ok = _curve_states(*as_traced((ProfileModel(), ring, geometry)), np.float64(omega),
                                                  loads, roads, solver)
    amp = harmonic_amplitudes(np.asarray(rad), 2, k_max)
    peaks = edge_peaks(amp, 2)[:, :2]
    return LoadCurves(load_n=loads, length_mm=1e3 * np.asarray(length), leading_deg=np.degrees(np.asarray(lead)),
                      trailing_deg=np.degrees(np.asarray(trail)), peak_spacing_deg=peaks[:, 1] - peaks[:, 0],
                      peak_mid_deg=peaks.mean(axis=1), amplitudes=amp, ok=np.asarray(ok), k_max=k_max)
