"""The source study's own parameter procedure, for comparison with the fits.

As the thesis did it (seed §5, Table 9): for a given ρA, eq. 18 is linear in
(EI, k_w, k_v), so three measured modes — by default n = 1, 3, 7 — fix them
exactly; ρA is then stepped over a grid and the value that minimises the summed
absolute frequency error of the *other* modes is kept.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ringfit.errors import InputError
from ringfit.io.modes import ModeTable
from ringfit.params import RingParams, TyreGeometry
from ringfit.physics.natural import modal_stiffness_jit, natural_frequencies_jit


@dataclass
class SourceStudyFit:
    """Result of :func:`source_study_fit`.

    - ``ring``: the chosen parameters; ``rho_a_grid`` / ``summed_abs_error_hz``:
      the ρA sweep ``(g,)`` and its objective; ``solve_modes``: the three n used.
    - ``n``, ``freq_hz``, ``model_hz``: every structural mode with n, ``(m,)``.
    """

    ring: RingParams
    solve_modes: tuple[int, int, int]
    rho_a_grid: np.ndarray
    summed_abs_error_hz: np.ndarray
    n: np.ndarray
    freq_hz: np.ndarray
    model_hz: np.ndarray


def stiffness_from_three_modes(geometry: TyreGeometry, rho_a, n3, f3) -> np.ndarray:
    """Solve eq. 18 (docs/physics.md §2.1) for (EI, k_w, k_v) from three modes at given ρA.

    **Arguments:** ``rho_a`` — scalar or ``(g,)`` [kg/m]; ``n3``, ``f3`` — ``(3,)`` indices and Hz.
    **Returns:** ``(g, 3)`` array of (EI [N m²], k_w [N/m²], k_v [N/m²]).

    eq. 18 reads ``ρA(1+n²)ω² = EI/R⁴ n²(n²−1)² + P n²(n²−1) + k_w n² + k_v``;
    its right side is linear in (EI, k_w, k_v), so the system is obtained by
    evaluating :func:`modal_stiffness` at unit parameters.
    """
    n3 = np.asarray(n3, dtype=float)
    w2 = (2 * np.pi * np.asarray(f3, dtype=float)) ** 2
    unit = dict(rho_a=1.0, ei=0.0, kw=0.0, kv=0.0)
    zero = float(0.0)

    def col(**one):
        ring = RingParams(**{**unit, **one})
        geo0 = TyreGeometry(geometry.radius, geometry.width, zero)
        return np.asarray(modal_stiffness_jit(ring, geo0, n3))

    A = np.stack([col(ei=1.0), col(kw=1.0), col(kv=1.0)], axis=1)  # (3, 3)
    pressure_part = np.asarray(modal_stiffness_jit(RingParams(**unit), geometry, n3))  # P n²(n²−1)
    rho = np.atleast_1d(np.asarray(rho_a, dtype=float))
    rhs = rho[:, None] * (1 + n3**2) * w2 - pressure_part  # (g, 3)
    return np.linalg.solve(A, rhs.T).T


def source_study_fit(
    table: ModeTable,
    geometry: TyreGeometry,
    *,
    solve_modes=(1, 3, 7),
    rho_a_grid=None,
) -> SourceStudyFit:
    """The source study's procedure (see module doc).

    **Arguments:** ``solve_modes`` — the three n solved exactly; ``rho_a_grid`` —
    ρA values to step over [kg/m], default 0.5…6 in steps of 0.001.
    """
    mask = table.structural_with_n()
    n, f = table.n[mask].astype(float), table.freq_hz[mask]
    if len(set(solve_modes)) != 3:
        raise InputError(f"solve_modes must be three distinct n, got {solve_modes}")
    try:
        idx = [int(np.flatnonzero(n == k)[0]) for k in solve_modes]
    except IndexError:
        raise InputError(f"{table.source or 'mode table'}: needs structural modes n = {list(solve_modes)}") from None
    grid = np.arange(0.5, 6.0, 0.001) if rho_a_grid is None else np.asarray(rho_a_grid, dtype=float)
    stiff = stiffness_from_three_modes(geometry, grid, n[idx], f[idx])  # (g, 3)
    ok = np.all(stiff > 0, axis=1)
    if not ok.any():
        raise InputError("no ρA in the grid gives positive EI, k_w and k_v for the chosen modes")
    others = np.setdiff1d(np.arange(n.size), idx)
    rings = RingParams(rho_a=grid, ei=stiff[:, 0], kw=stiff[:, 1], kv=stiff[:, 2])
    model = np.asarray(natural_frequencies_jit(rings, geometry, n[:, None]))  # (m, g)
    err = np.abs(model[others] - f[others, None]).sum(axis=0)
    err = np.where(ok, err, np.inf)
    best = int(np.argmin(err))
    ring = RingParams(rho_a=float(grid[best]), ei=float(stiff[best, 0]), kw=float(stiff[best, 1]),
                      kv=float(stiff[best, 2]))
    return SourceStudyFit(ring, tuple(solve_modes), grid, err, n, f, model[:, best])
