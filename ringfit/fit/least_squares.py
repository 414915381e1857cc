"""Weighted least-squares fit of ring parameters to measured natural frequencies.

Model: static inextensible ring, eq. 18 (docs/physics.md §2.1), via
:func:`ringfit.physics.natural.natural_frequencies`. Residual of mode i:
``(f_model(n_i) − f_i) / σ_i`` with σ_i from ``freq_std_hz`` or, where that is
empty, :data:`DEFAULT_RELATIVE_STD` × f_i. Optional log-normal priors enter as
extra residual rows ``(log θ − μ)/σ_ln``. The solver (optimistix
Levenberg–Marquardt with an SVD linear solve, :mod:`ringfit.fit.engine`) works on
``log θ`` of the free parameters; all other ring parameters stay fixed at the
initial values.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ringfit.errors import InputError
from ringfit.fit.engine import (LINEAR, LOG, AbstractResiduals, Coordinate, GaussianPrior, Problem, evaluate,
                                least_squares)
from ringfit.fit.priors import BOUNDS, LogNormalPrior, resolve_priors
from ringfit.fit.result import FitResult
from ringfit.io.modes import ModeTable
from ringfit.params import RING_PARAMETERS, RingParams, TyreGeometry
from ringfit.physics.natural import natural_frequencies

#: σ_i / f_i used where a mode table has no ``freq_std_hz``. 1 % is the RMS
#: relative difference between the source study's two identifications of the
#: same nine modes (Table 2: SSI vs FRF peak picking, 0.9 %), i.e. the spread
#: that the choice of identification method alone produces.
DEFAULT_RELATIVE_STD = 0.01
#: The parameters of eq. 18 that a free-tyre fit frees by default.
DEFAULT_FREE = ("rho_a", "ei", "kw", "kv")
RING_FIELDS = tuple(f.name for f in fields(RingParams))


@dataclass(frozen=True)
class FrequencyData:
    """The rows of a mode table that take part in a fit.

    Arrays of shape ``(m,)``: ``n`` (float), ``freq_hz``, ``sigma_hz``; ``rows``
    are the indices into the table; ``sigma_source`` says where σ came from.
    """

    n: np.ndarray
    freq_hz: np.ndarray
    sigma_hz: np.ndarray
    rows: np.ndarray
    sigma_source: str


def frequency_data(table: ModeTable, modes=None, default_relative_std: float = DEFAULT_RELATIVE_STD) -> FrequencyData:
    """Select the rows of ``table`` a ring fit uses and give each its σ.

    **Arguments:**

    - ``modes``: ``None`` (every structural row with an assigned n), an
      iterable of n values to keep (e.g. ``range(1, 7)``), or a bool mask of
      shape ``(len(table),)``.
    - ``default_relative_std``: σ/f where ``freq_std_hz`` is empty.
    """
    base = table.structural_with_n()
    if modes is None:
        mask = base
    else:
        modes = np.asarray(list(modes) if not isinstance(modes, np.ndarray) else modes)
        if modes.dtype == bool:
            if modes.shape != base.shape:
                raise InputError(f"mode mask has {modes.size} entries, table has {base.size} rows")
            mask = base & modes
        else:
            wanted = {int(x) for x in modes}
            missing = wanted - set(table.n[base].tolist())
            if missing:
                raise InputError(f"{table.source or 'mode table'}: no structural mode with n in {sorted(missing)}")
            mask = base & np.isin(table.n, list(wanted))
    rows = np.flatnonzero(mask)
    if rows.size == 0:
        raise InputError(f"{table.source or 'mode table'}: no structural modes with an assigned n to fit")
    std = table.freq_std_hz[rows]
    f = table.freq_hz[rows]
    have = np.isfinite(std) & (std > 0)
    sigma = np.where(have, std, default_relative_std * f)
    if have.all():
        source = "freq_std_hz"
    elif not have.any():
        source = f"default {default_relative_std:.1%} of frequency"
    else:
        source = f"freq_std_hz where given, else {default_relative_std:.1%} of frequency"
    return FrequencyData(table.n[rows].astype(np.float64), f, sigma, rows, source)


def ring_vector(ring: RingParams) -> np.ndarray:
    """All ring parameters as a float64 vector in :data:`RING_FIELDS` order."""
    return np.array([float(getattr(ring, k)) for k in RING_FIELDS])


def ring_from_vector(theta) -> RingParams:
    """A :class:`RingParams` from a vector in :data:`RING_FIELDS` order (JAX or NumPy)."""
    return RingParams(*[theta[i] for i in range(len(RING_FIELDS))])


#: Solver coordinates of the ring parameters: logarithms (χ, a share, linear).
RING_COORDS = tuple(Coordinate(k, LINEAR) if k == "chi" else Coordinate(k, LOG) for k in RING_FIELDS)


#: Rows of a frequency fit are padded to a multiple of this (zero-weight rows): one compilation per bucket.
ROW_BUCKET = 16


class FrequencyArrays(eqx.Module):
    """What the eq. 18 residuals need besides θ: geometry and the rows ``(m,)`` n, f [Hz], σ [Hz]."""

    geometry: TyreGeometry
    n: jax.Array
    freq: jax.Array
    sigma: jax.Array


class NaturalFrequencyResiduals(AbstractResiduals):
    """Rows ``(f_model(n_i) − f_i)/σ_i`` of eq. 18 (docs/physics.md §2.1); aux: the model frequencies [Hz].

    Its solve compiles quickly (the engine's ``compile_quick``): a cold ``ringfit fit`` compiles it in ~0.35 s
    instead of ~0.9 s; a fit then takes ~0.33 ms instead of ~0.29 ms.
    """

    compile_quick: ClassVar[bool] = True

    def __call__(self, theta, data: FrequencyArrays):
        model = natural_frequencies(ring_from_vector(theta), data.geometry, data.n)
        return (model - data.freq) / data.sigma, model


def log_normal_prior(priors: dict) -> GaussianPrior | None:
    """The engine's prior from ``name -> LogNormalPrior`` (a normal prior on log θ)."""
    if not priors:
        return None
    return GaussianPrior.independent({k: (p.mu, p.sigma_ln) for k, p in priors.items()})


def check_free(free) -> tuple[str, ...]:
    """Validate parameter names; returns them as a tuple."""
    free = tuple(free)
    for k in free:
        if k not in RING_PARAMETERS or k == "chi":
            raise InputError(f"unknown or non-positive parameter {k!r} to fit; choose from "
                             f"{', '.join(k for k in RING_PARAMETERS if k != 'chi')}")
    if len(set(free)) != len(free):
        raise InputError(f"parameter listed twice in {list(free)}")
    if not free:
        raise InputError("no free parameter to fit")
    return free


def fit_natural_frequencies(
    table: ModeTable,
    geometry: TyreGeometry,
    initial: RingParams,
    *,
    free=DEFAULT_FREE,
    prior="none",
    modes=None,
    default_relative_std: float = DEFAULT_RELATIVE_STD,
    max_steps: int = 256,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    at_initial: bool = False,
) -> FitResult:
    """Fit ring parameters to measured natural frequencies (eq. 18, docs/physics.md §2.1).

    **Arguments:**

    - ``table``: measured modes (:class:`~ringfit.io.modes.ModeTable`).
    - ``geometry``: radius, width and pressure (known, not fitted).
    - ``initial``: starting values; parameters not in ``free`` stay at these values.
    - ``free``: names of the parameters to fit (any subset of
      ``rho_a, ei, kw, kv, damping_ratio, k_tread, ea``; only the first four enter eq. 18).
    - ``prior``: ``"none"``, ``"physical"`` (the belt-plate prior on EI, see
      :mod:`ringfit.fit.priors`) or a dict name -> ``LogNormalPrior``/(median, σ_ln).
    - ``modes``: which rows take part (see :func:`frequency_data`).
    - ``default_relative_std``: σ/f where the table gives no ``freq_std_hz``.
    - ``at_initial``: no fit: residuals, Jacobian and covariance at ``initial`` (status ``"evaluated"``;
      a ring identified elsewhere, e.g. by ``ringfit identify``, used as it is).

    **Returns:** :class:`~ringfit.fit.result.FitResult`; ``extra`` holds
    ``n``, ``freq_hz``, ``model_hz``, ``sigma_hz`` (shape ``(m,)``),
    ``sigma_source``, ``priors`` and the data-only Fisher information.
    Never raises on non-convergence: check ``result.converged``.

    Examples
    --------
    >>> from ringfit.data import path
    >>> from ringfit.fit.least_squares import fit_natural_frequencies
    >>> from ringfit.io.modes import read_mode_table
    >>> from ringfit.io.tyre import read_tyre
    >>> tyre = read_tyre(path("table9.tyre.toml"))
    >>> table = read_mode_table(path("free-ssi.modes.csv"))
    >>> fit = fit_natural_frequencies(table, tyre.geometry, tyre.ring, prior="physical")
    >>> fit.converged, fit.names
    (True, ('rho_a', 'ei', 'kw', 'kv'))
    >>> round(fit.values["rho_a"], 2), round(fit.values["kw"] / 1e6, 2)  # kg/m, MN/m²
    (2.54, 1.11)
    """
    free = check_free(free)
    if geometry.pressure <= 0 or geometry.radius <= 0 or geometry.width <= 0:
        raise InputError("tyre geometry needs positive radius, width and pressure")
    data = frequency_data(table, modes, default_relative_std)
    priors = resolve_priors(prior, free)
    base = ring_vector(initial)
    start = np.array([base[RING_FIELDS.index(k)] for k in free])
    if not np.all(np.isfinite(start) & (start > 0)):
        raise InputError(f"initial values of {list(free)} must be positive and finite, got {start}")
    # rows padded to a multiple of ROW_BUCKET with rows of infinite σ (residual and Jacobian exactly 0):
    # tables of 8, 9 … 16 modes share one compiled fit (and one compiled posterior)
    m = data.n.size
    pad = (-m) % ROW_BUCKET
    arrays = FrequencyArrays(geometry, np.concatenate([data.n, np.ones(pad)]),
                             np.concatenate([data.freq_hz, np.full(pad, 100.0)]),
                             np.concatenate([data.sigma_hz, np.full(pad, np.inf)]))
    problem = Problem(NaturalFrequencyResiduals(), arrays, RING_COORDS, prior=log_normal_prior(priors),
                      plausible=BOUNDS, data_label="these modes")
    # free sets of up to the four eq. 18 parameters padded to four: the profile likelihood's refits (three
    # free) share the four-parameter fit's compiled solve
    pad_to = max(len(free), len(DEFAULT_FREE))
    if at_initial:
        result = evaluate(problem, base, free, n_data=m, pad_to=pad_to)
    else:
        result = least_squares(problem, base, free, max_steps=max_steps, rtol=rtol, atol=atol, n_data=m,
                               pad_to=pad_to)
    model = np.asarray(result.extra.pop("aux"))[:m]
    result.residuals = result.residuals[:m]
    result.jacobian = np.concatenate([result.jacobian[:m], result.jacobian[m + pad:]])
    if table.state != "free" or float(table.condition.get("speed_kmh", 0) or 0) > 0:
        result.flags.append(f"table state is {table.state!r} (speed {table.condition.get('speed_kmh', 0)} km/h); "
                            "the eq. 18 model assumes a static, free tyre")
    J = result.jacobian[:m]
    result.extra.update(
        n=data.n, freq_hz=data.freq_hz, model_hz=model, sigma_hz=data.sigma_hz, rows=data.rows,
        sigma_source=data.sigma_source, priors=priors, ring=fitted_ring(result), geometry=geometry,
        fisher_data=J.T @ J,
    )
    return result


def fitted_ring(result: FitResult) -> RingParams:
    """The :class:`RingParams` of a ring fit (free parameters at their optimum, the rest as given)."""
    return RingParams(**{k: result.values[k] for k in RING_FIELDS})


__all__ = ["fit_natural_frequencies", "frequency_data", "FrequencyData", "DEFAULT_RELATIVE_STD",
           "DEFAULT_FREE", "fitted_ring", "LogNormalPrior"]

