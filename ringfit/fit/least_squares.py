"""Weighted least-squares fit of ring parameters to measured natural frequencies.

Model: static inextensible ring, eq. 18 (PHYSICS.md §2.1), via
:func:`ringfit.physics.natural.natural_frequencies`. Residual of mode i:
``(f_model(n_i) − f_i) / σ_i`` with σ_i from ``freq_std_hz`` or, where that is
empty, :data:`DEFAULT_RELATIVE_STD` × f_i. Optional log-normal priors enter as
extra residual rows ``(log θ − μ)/σ_ln``. The solver (optimistix
Levenberg–Marquardt with an SVD linear solve) works on ``log θ`` of the free
parameters; all other ring parameters stay fixed at the initial values.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, fields

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from ringfit.errors import InputError
from ringfit.fit.priors import LogNormalPrior, prior_arrays, resolve_priors
from ringfit.fit.result import FitResult, covariance_from_jacobian, parameter_flags, solver_flags, solver_status
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


def ring_from_log(log_free, free_index: tuple[int, ...], base):
    """A :class:`RingParams` whose free entries are ``exp(log_free)`` and the rest ``base``.

    **Arguments:** ``log_free`` — ``(k,)``; ``free_index`` — static positions in
    :data:`RING_FIELDS`; ``base`` — ``(8,)`` vector of all parameters.
    """
    vec = jnp.asarray(base).at[jnp.array(free_index)].set(jnp.exp(log_free))
    return RingParams(*[vec[i] for i in range(len(RING_FIELDS))])


def weighted_residuals(log_free, free_index, base, geometry, n, freq, sigma):
    """Data rows ``(f_model − f)/σ``, shape ``(m,)`` (eq. 18, PHYSICS.md §2.1)."""
    ring = ring_from_log(log_free, free_index, base)
    return (natural_frequencies(ring, geometry, n) - freq) / sigma


def _all_residuals(log_free, args, free_index):
    base, geometry, n, freq, sigma, mu, sd, mask = args
    data = weighted_residuals(log_free, free_index, base, geometry, n, freq, sigma)
    prior = mask * (log_free - mu) / sd
    return jnp.concatenate([data, prior])


@functools.partial(jax.jit, static_argnames=("free_index", "max_steps", "rtol", "atol"))
def _solve(y0, args, *, free_index, max_steps, rtol, atol):
    fn = functools.partial(_residual_for_optx, free_index=free_index)
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.SVD())
    sol = optx.least_squares(fn, solver, y0, args=args, max_steps=max_steps, throw=False)
    jac = jax.jacfwd(_all_residuals)(sol.value, args, free_index)
    res = _all_residuals(sol.value, args, free_index)
    return sol.value, sol.result, sol.stats["num_steps"], jac, res


def _residual_for_optx(y, args, *, free_index):
    return _all_residuals(y, args, free_index)


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
) -> FitResult:
    """Fit ring parameters to measured natural frequencies (eq. 18, PHYSICS.md §2.1).

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

    **Returns:** :class:`~ringfit.fit.result.FitResult`; ``extra`` holds
    ``n``, ``freq_hz``, ``model_hz``, ``sigma_hz`` (shape ``(m,)``),
    ``sigma_source``, ``priors`` and the data-only Fisher information.
    Never raises on non-convergence: check ``result.converged``.
    """
    free = check_free(free)
    if geometry.pressure <= 0 or geometry.radius <= 0 or geometry.width <= 0:
        raise InputError("tyre geometry needs positive radius, width and pressure")
    data = frequency_data(table, modes, default_relative_std)
    priors = resolve_priors(prior, free)
    mu, sd, mask = prior_arrays(priors, free)
    base = ring_vector(initial)
    free_index = tuple(RING_FIELDS.index(k) for k in free)
    start = base[list(free_index)]
    if not np.all(np.isfinite(start) & (start > 0)):
        raise InputError(f"initial values of {list(free)} must be positive and finite, got {start}")
    y0 = np.log(start)
    args = (jnp.asarray(base), geometry, jnp.asarray(data.n), jnp.asarray(data.freq_hz),
            jnp.asarray(data.sigma_hz), jnp.asarray(mu), jnp.asarray(sd), jnp.asarray(mask))
    y, result, steps, jac, res = _solve(jnp.asarray(y0), args, free_index=free_index,
                                       max_steps=max_steps, rtol=rtol, atol=atol)
    return _result(free, free_index, base, geometry, data, priors, np.asarray(y), result,
                   int(steps), np.asarray(jac), np.asarray(res), table)


def _result(free, free_index, base, geometry, data, priors, y, result, steps, jac, res, table) -> FitResult:
    status, message = solver_status(result)
    m = data.n.size
    values = dict(zip(RING_FIELDS, base.tolist()))
    values.update({k: float(np.exp(v)) for k, v in zip(free, y)})
    cov = covariance_from_jacobian(jac)
    stderr = {k: float(values[k] * math.sqrt(cov[i, i])) if np.isfinite(cov[i, i]) else math.inf
              for i, k in enumerate(free)}
    ring = RingParams(**values)
    model = np.asarray(natural_frequencies(ring, geometry, data.n))
    flags = solver_flags(status, message) + parameter_flags(free, values, stderr, data="these modes", priors=priors)
    if table.state != "free" or float(table.condition.get("speed_kmh", 0) or 0) > 0:
        flags.append(f"table state is {table.state!r} (speed {table.condition.get('speed_kmh', 0)} km/h); "
                     "the eq. 18 model assumes a static, free tyre")
    return FitResult(
        status=status,
        message=message or "converged",
        names=tuple(free),
        values=values,
        stderr=stderr,
        covariance_log=cov,
        residuals=res[:m],
        jacobian=jac,
        n_data=m,
        iterations=steps,
        flags=flags,
        extra=dict(
            n=data.n, freq_hz=data.freq_hz, model_hz=model, sigma_hz=data.sigma_hz, rows=data.rows,
            sigma_source=data.sigma_source, priors=priors, ring=ring, geometry=geometry,
            fisher_data=jac[:m].T @ jac[:m],
        ),
    )


def fitted_ring(result: FitResult) -> RingParams:
    """The :class:`RingParams` of a fit (free parameters at their optimum)."""
    return RingParams(**{k: result.values[k] for k in RING_FIELDS})


__all__ = ["fit_natural_frequencies", "frequency_data", "FrequencyData", "DEFAULT_RELATIVE_STD",
           "DEFAULT_FREE", "fitted_ring", "LogNormalPrior"]

