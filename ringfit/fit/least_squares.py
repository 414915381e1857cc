"""Weighted least-squares fit of ring parameters to measured natural frequencies.

Model: static inextensible ring, eq. 18 (docs/physics.md §2.1), via
:func:`ringfit.physics.natural.natural_frequencies`. Residual of mode i:
``(f_model(n_i) − f_i) / σ_i``. σ is the free-modes block's noise model
(:mod:`ringfit.fit.free_block`, docs/physics.md §11 "Noise per block"), the same ``ringfit identify`` uses:
``freq_std_hz`` (or a stated relative σ) only scaled up, else :data:`DEFAULT_RELATIVE_STD` × f_i
as a start, scaled by the residual's hat-matrix estimate until it settles, the intervals
widened by Student's t and the model-discrepancy ratio. Optional log-normal priors enter as extra residual rows
``(log θ − μ)/σ_ln``. The solver (optimistix Levenberg–Marquardt with an SVD linear solve,
:mod:`ringfit.fit.engine`) works on ``log θ`` of the free parameters; all other ring parameters
stay fixed at the initial values.
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import ClassVar

import equinox as eqx
import jax
import numpy as np

from ringfit.errors import InputError
from ringfit.fit.engine import (LINEAR, LOG, AbstractResiduals, Coordinate, GaussianPrior, Problem, evaluate,
                                least_squares)
from ringfit.fit.free_block import (DEFAULT_RELATIVE_STD, NOISE_MODELS, FrequencyData, NoiseModel, check_noise,
                                    fit_free_block, frequency_data, row_widening)
from ringfit.fit.priors import BOUNDS, LogNormalPrior, PriorSpec, resolve_priors
from ringfit.fit.result import FitResult, covariance_from_jacobian
from ringfit.io.modes import ModeTable
from ringfit.params import RING_PARAMETERS, RingParams, TyreGeometry
from ringfit.physics.natural import natural_frequencies

#: The parameters of eq. 18 that a free-tyre fit frees by default.
DEFAULT_FREE = ("rho_a", "ei", "kw", "kv")
RING_FIELDS = tuple(f.name for f in fields(RingParams))


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
    prior: PriorSpec = "none",
    modes=None,
    default_relative_std: float | None = None,
    noise: NoiseModel = "estimated",
    noise_scale: float = 1.0,
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
    - ``default_relative_std``: a stated σ/f where the table gives no ``freq_std_hz`` (only scaled up, as a
      stated ``freq_std_hz``); ``None`` (default): :data:`DEFAULT_RELATIVE_STD` as the start of the estimate.
    - ``noise``: ``"estimated"`` (default) — the free-modes block's noise model (:mod:`ringfit.fit.free_block`,
      docs/physics.md §11 "Noise per block", the one ``ringfit identify`` uses): the σ scale from the residual and
      the hat matrix, refitted until it settles, the covariance Student-t widened and by the model-discrepancy
      ratio κ; ``"fixed"`` — the starting σ ×
      ``noise_scale`` as a known σ (simulation-based calibration at a known σ; a profile likelihood's refits at a
      fit's settled σ, ``extra["noise_scale"]``).
    - ``at_initial``: no fit: residuals, Jacobian and covariance at ``initial`` (status ``"evaluated"``;
      a ring identified elsewhere, e.g. by ``ringfit identify``, used as it is).

    **Returns:** :class:`~ringfit.fit.result.FitResult` (residuals and Jacobian weighted by the σ used; its
    covariance with the t-widening); ``extra`` holds ``n``, ``freq_hz``, ``model_hz``, ``sigma_hz`` (the σ
    used, shape ``(m,)``), ``sigma_source`` (where the starting σ came from), ``noise_scale`` (σ used / starting
    σ), ``noise_dof`` (ν, ∞ where no scale was estimated), ``t_widening``, ``discrepancy`` (κ − 1),
    ``row_scale`` (t_widening · √κ per row of the problem, padding included: what
    :func:`ringfit.fit.posterior.sample` samples), ``noise``, ``priors``
    and the data-only Fisher information (widened, as the covariance). Never raises on non-convergence: check
    ``result.converged``.

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
    check_noise(noise)
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
    prior_rows = log_normal_prior(priors)
    # free sets of up to the four eq. 18 parameters padded to four: the profile likelihood's refits (three
    # free) share the four-parameter fit's compiled solve
    pad_to = max(len(free), len(DEFAULT_FREE))

    def fit_at(sigma):
        arrays = FrequencyArrays(geometry, np.concatenate([data.n, np.ones(pad)]),
                                 np.concatenate([data.freq_hz, np.full(pad, 100.0)]),
                                 np.concatenate([sigma, np.full(pad, np.inf)]))
        problem = Problem(NaturalFrequencyResiduals(), arrays, RING_COORDS, prior=prior_rows,
                          plausible=BOUNDS, data_label="these modes")
        if at_initial:
            return evaluate(problem, base, free, n_data=m, pad_to=pad_to)
        # every pass starts from ``initial``: the solver started at the last pass's optimum takes no step it can
        # call converged (its first steps are all rejected)
        return least_squares(problem, base, free, max_steps=max_steps, rtol=rtol, atol=atol, n_data=m,
                             pad_to=pad_to)

    # the free-modes block's noise model (docs/physics.md §11): σ scaled from the residual until it settles
    result, noise_info = fit_free_block(fit_at, data.sigma_hz, data.stated, noise, noise_scale,
                                           freq_hz=data.freq_hz)
    model = np.asarray(result.extra.pop("aux"))[:m]
    result.residuals = result.residuals[:m]
    result.jacobian = np.concatenate([result.jacobian[:m], result.jacobian[m + pad:]])
    widen = row_widening(noise_info)  # Student's t_ν of a scale from ν degrees of freedom, × √κ (discrepancy)
    J = result.jacobian[:m] / widen
    if widen > 1.0:
        cov = covariance_from_jacobian(np.concatenate([J, result.jacobian[m:]]))
        result.covariance_log = cov
        for j, name in enumerate(result.names):
            sd = math.sqrt(cov[j, j]) if np.isfinite(cov[j, j]) and cov[j, j] >= 0 else math.inf
            result.stderr[name] = result.values[name] * sd
    if table.state != "free" or float(table.condition.get("speed_kmh", 0) or 0) > 0:
        result.flags.append(f"table state is {table.state!r} (speed {table.condition.get('speed_kmh', 0)} km/h); "
                            "the eq. 18 model assumes a static, free tyre")
    row_scale = np.concatenate([np.full(m, widen), np.ones(pad)])
    # a scale estimated from ν residual degrees of freedom: the posterior integrates it out (1/s prior; a stated σ
    # only scaled up, s ≥ the stated σ), which gives the t shape at every level (docs/physics.md §12.3)
    marginal = None
    if math.isfinite(noise_info["dof"]):
        kappa = math.sqrt(max(float(noise_info["discrepancy"]), 1.0))
        marginal = dict(rows=m, s_min=1.0 / float(noise_info["scale"]) if data.stated else 0.0,
                        row_scale=np.concatenate([np.full(m, kappa), np.ones(pad)]))
    result.extra.update(scale_marginal=marginal,

        n=data.n, freq_hz=data.freq_hz, model_hz=model, sigma_hz=noise_info["sigma_hz"], rows=data.rows,
        sigma_source=data.sigma_source, noise=noise_info["noise"], noise_scale=noise_info["scale"],
        noise_dof=noise_info["dof"], t_widening=noise_info["t_widening"],
        discrepancy=noise_info["discrepancy"] - 1.0, scale_passes=noise_info["passes"], row_scale=row_scale,
        priors=priors, ring=fitted_ring(result), geometry=geometry, fisher_data=J.T @ J,
    )
    return result


def fitted_ring(result: FitResult) -> RingParams:
    """The :class:`RingParams` of a ring fit (free parameters at their optimum, the rest as given)."""
    return RingParams(**{k: result.values[k] for k in RING_FIELDS})


__all__ = ["fit_natural_frequencies", "frequency_data", "FrequencyData", "DEFAULT_RELATIVE_STD",
           "DEFAULT_FREE", "fitted_ring", "LogNormalPrior", "NOISE_MODELS", "NoiseModel", "PriorSpec"]

