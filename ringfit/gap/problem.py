"""The common shape of a gap-diagnosis problem, whatever the data (mode tables or rolling profiles).

A :class:`GapProblem` holds the observations ``y`` (one row each), their
noise level ``sigma``, the held-out folds, labels for localisation, the
baseline parameters with their reference values (the baseline fit), and a
predictor of **every** applicable effect at once:
``predictor(theta, data) -> (m,)`` with ``theta = [baseline params, effect 1
params, effect 2 params, …]`` in natural units. A candidate chain frees the
baseline and the chain's parameters and keeps every other effect at its null
(where each effect gives back the baseline exactly), so one compiled refit of
the engine serves every candidate, chain and prediction (:mod:`ringfit.gap.ranking`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ringfit.gap.effects.base import Effect, Parameter
from ringfit.fit.engine import LINEAR, LOG, Coordinate

#: :attr:`ProblemMeta.line_problem` before :func:`ringfit.gap.modal_lines.line_problem` has looked (``None`` = looked, none).
UNSET = object()


@dataclass
class ProblemMeta:
    """What a :class:`GapProblem`'s builder knows beyond the rows, for the diagnosis, its nulls and its report.

    Every field is optional (``None`` = the builder did not set it); the defaults are what a reader assumes.

    *Statistics*
    - ``block``: rows per block of the held-out shrink's block bootstrap (``ranking.shrink_interval``);
      ``tangents``: the linearised screen's tangent budget (``None`` = the problem's θ size);
      ``screen_min_fraction``: the rescreen's alignment² threshold (0 = off).
    - ``reference_mask``: bool ``(m,)`` the rows the baseline is fitted to (free-table rows); the others are
      its predictions (test rows). ``sigma_matched``: σ of the rows before any widening (the random-line null).
    - ``series_dof``: ``{series: effective dof}`` of a profile's noise; ``noise_slope``: its fitted power law.
    - ``prior_guarded``: baseline indices whose prior the candidate refits may not move far.
    - ``fold_nuisances``: ``{fold: baseline indices}`` — nuisances that act on that fold's rows alone (a profile's
      own gain and angle offset under leave-one-speed-out): a held-out prediction of the fold fits them to the
      fold's own rows (:func:`ringfit.gap.ranking.fold_nuisance_step`), since the other runs do not determine a
      run's calibration.
    - ``noise_rule``: optional ``(rows (B, m), center (m,)) -> σ (B, m)``, the rule that estimated ``sigma`` from
      the data (the damping problem's from the rows alone; the profiles' from the far side of each run's residual
      about ``center``, the model the draw was made from): the parametric null applies it to every draw (the noise
      estimate is a data-dependent choice the null repeats).
    - ``condition_sd``: stated-condition uncertainty per effect parameter (loaded tables' patches).

    *Modal problems*
    - ``padded_rows``: the predictor's padded row count; ``files``: data file names; ``tables``: the damping
      problem's table indices; ``table_names``, ``patches``, ``spins``, ``outer_radius_m``: per table its label,
      (patch half-angle, …), spin [rad/s], and the tyre's outer radius (localisation).
    - ``reference_fit`` (record) and ``reference_result`` (:class:`~ringfit.fit.result.FitResult`): the free-table
      fit; ``conditions``: the tables' stated conditions.
    - ``lines``: the rows' candidate model lines (``modal.LineSets``); ``line_problem``: their cached line
      problem (:data:`UNSET` until built); ``rolling_structure``, ``label_counts``: the rolling rows'
      assignment record and label counts (docs/formats.md §5).

    *Profile problems*
    - ``k_max``: top harmonic per profile; ``omega``, ``omega_source``: Ω per profile and where it came from;
      ``sources``: where each baseline value came from.
    """

    block: int = 1
    tangents: int | None = None
    screen_min_fraction: float = 0.0
    reference_mask: np.ndarray | None = None
    sigma_matched: np.ndarray | None = None
    series_dof: dict | None = None
    noise_slope: Any = None
    prior_guarded: tuple = ()
    fold_nuisances: dict = field(default_factory=dict)
    noise_rule: Any = None
    condition_sd: dict = field(default_factory=dict)
    padded_rows: int | None = None
    files: list | None = None
    tables: list | None = None
    table_names: list | None = None
    patches: list = field(default_factory=list)
    spins: list = field(default_factory=list)
    outer_radius_m: float = float("nan")
    reference_fit: dict | None = None
    reference_result: Any = None
    conditions: dict = field(default_factory=dict)
    lines: Any = None
    line_problem: Any = UNSET
    rolling_structure: dict | None = None
    label_counts: dict | None = None
    k_max: Any = None
    omega: Any = None
    omega_source: list | None = None
    sources: dict | None = None


@dataclass
class GapProblem:
    """Observations, noise, folds and the model of one diagnosis.

    - ``domain``: ``"modes"`` or ``"profiles"``.
    - ``data_files``: file names the data came from (JSON ``data``).
    - ``y``, ``sigma``: ``(m,)`` observations and one-σ noise, data units.
    - ``unit``: unit of the RMS figures (``Hz``-equivalent for modes, m/s² for profiles).
    - ``scale``: ``(m,)`` factor turning a residual into the unit of the RMS figures.
    - ``folds``: ``(m,)`` int, held-out group of each row (speed / mode fold); ``fold_kind`` names it.
    - ``labels``: per-row information used by :mod:`ringfit.gap.localisation`.
    - ``base``: baseline parameters (log-fitted, positive), ``base_values`` their reference
      values (baseline fit, the starting point of refits), ``base_prior_sd`` the σ of a
      log-normal prior used in refits (``inf`` = none), centred on ``base_prior_mean``
      (natural units; ``None`` = ``base_values``). ``base_prior_cov`` (optional, ``(nb, nb)``
      in log units, ``inf`` on the diagonal = no prior) replaces ``diag(base_prior_sd²)`` when a
      prior is correlated — e.g. the ring stiffnesses of the profile baseline, whose prior is
      the free-table fit's Laplace posterior.
    - ``effects``: the applicable effects, in the order of ``theta`` after the baseline.
    - ``data``: the predictor's pytree argument.
    - ``noise_method``: how ``sigma`` was obtained (one line, goes into the JSON).
    - ``not_applicable``: effect name -> reason, for effects left out.
    - ``base_linear``: per baseline parameter, ``True`` for a nuisance fitted linearly
      (e.g. the profiles' angle offset [rad], which may be negative) instead of as a log;
      ``base_linear_scale`` its typical size and ``base_linear_bound`` its hard bound ±.
      ``None`` = every baseline parameter positive and log-fitted.
    - ``sigma_heldout``: optional ``(m,)`` σ of a held-out residual: √(σ² + the variance of the
      baseline's held-out prediction at that row); set by the diagnosis where a held-out refit
      extrapolates (mode tables), used by every held-out statistic (``None`` = ``sigma``).
    - ``robust``: optional bool ``(m,)``: rows whose standardised residual enters refits and
      statistics through the Huber function with threshold ``huber`` (heavy-tailed data).
    - ``predictor``: the un-jitted prediction ``predictor(theta, data) -> (m_padded,)`` (an
      ``eqx.Module`` with static configuration; rows past ``m`` are padding) — what every refit
      differentiates inside the engine's one compiled solve.
    """

    domain: str
    data_files: list[str]
    y: np.ndarray
    sigma: np.ndarray
    unit: str
    scale: np.ndarray
    folds: np.ndarray
    fold_kind: str
    labels: dict
    base: tuple[str, ...]
    base_values: np.ndarray
    base_prior_sd: np.ndarray
    effects: tuple[Effect, ...]
    data: Any
    noise_method: str
    baseline_model: str
    not_applicable: dict = field(default_factory=dict)
    meta: ProblemMeta = field(default_factory=ProblemMeta)
    base_linear: tuple | None = None
    base_linear_scale: tuple | None = None
    base_linear_bound: tuple | None = None
    base_prior_mean: np.ndarray | None = None
    base_prior_cov: np.ndarray | None = None
    predictor: Any = None
    robust: np.ndarray | None = None
    huber: float | None = None
    sigma_heldout: np.ndarray | None = None
    #: optional solver coordinate of a baseline parameter by name (e.g. the profile block's nuisances:
    #: a gain bounded to its range), in place of the default (log within e^±3 of its value, or linear)
    base_coords: dict | None = None

    def prior_rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The baseline prior as whitened residual rows: ``(index, mean_u, W)`` with rows ``W (u[index] − mean_u)``.

        ``u`` is the solver coordinate of each baseline parameter (:meth:`base_coordinate`: log, or
        (value − center)/scale for a linear nuisance, whose prior covariance is in natural units); ``index`` the
        baseline parameters with a prior; ``W`` the inverse Cholesky factor of their prior covariance.
        """
        nb = len(self.base)
        mean = np.asarray(self.base_values if self.base_prior_mean is None else self.base_prior_mean, dtype=np.float64)
        cov = (np.diag(np.asarray(self.base_prior_sd, dtype=np.float64) ** 2) if self.base_prior_cov is None
               else np.asarray(self.base_prior_cov, dtype=np.float64))
        idx = np.array([i for i in range(nb) if np.isfinite(cov[i, i])], dtype=int)
        if idx.size == 0:
            return idx, np.zeros(0), np.zeros((0, 0))
        coords = [self.base_coordinate(i) for i in idx]
        # a linear nuisance's prior is given in natural units: its solver coordinate is (θ − center)/scale
        d = np.array([1.0 if c.kind == LOG else c.scale for c in coords])
        L = np.linalg.cholesky(cov[np.ix_(idx, idx)] / np.outer(d, d))
        return idx, np.array([c.to_u(mean[i]) for c, i in zip(coords, idx)]), np.linalg.inv(L)

    def base_coordinate(self, i: int) -> Coordinate:
        """The solver coordinate of baseline parameter ``i`` (its :attr:`base_coords` entry, else linear with
        :attr:`base_linear_scale` or log) — bounds aside, which the refits set (:func:`ringfit.gap.ranking.coordinates`)."""
        name = self.base[i]
        if self.base_coords and name in self.base_coords:
            return self.base_coords[name]
        if self.is_linear(i):
            return Coordinate(name, LINEAR, scale=float(self.base_linear_scale[i]))
        return Coordinate(name, LOG)

    def is_linear(self, i: int) -> bool:
        """Whether baseline parameter ``i`` is fitted linearly (a nuisance) rather than as a log."""
        return bool(self.base_linear is not None and self.base_linear[i])

    def standardised(self, resid: np.ndarray, mask=None, heldout: bool = False) -> np.ndarray:
        """``resid/σ`` with the Huber function applied to the robust rows (what refits and tests see);
        ``heldout``: σ of a held-out residual (:attr:`sigma_heldout` where set)."""
        sigma = self.sigma_heldout if heldout and self.sigma_heldout is not None else self.sigma
        z = self.psi(np.asarray(resid, dtype=np.float64) / sigma)
        return z if mask is None else z[mask]

    def psi(self, z):
        """Huber's ψ on the robust rows (``sign(z)·√(2c|z| − c²)`` beyond c = :attr:`huber`), identity elsewhere;
        ``z`` ``(..., m)`` standardised residuals (any leading batch axes)."""
        if self.robust is None or self.huber is None:
            return z
        c = float(self.huber)
        a = np.abs(z)
        return np.where(np.asarray(self.robust, dtype=bool) & (a > c),
                        np.sign(z) * np.sqrt(np.maximum(2 * c * a - c * c, 0.0)), z)

    @property
    def m(self) -> int:
        return int(self.y.shape[0])

    def effect_params(self, effect: Effect) -> tuple[Parameter, ...]:
        """The parameters ``effect`` adds in this problem's domain (modal or profile)."""
        return effect.params_for(self.domain)

    def slices(self) -> dict[str, slice]:
        """Where each effect's parameters sit in ``theta``."""
        out, i = {}, len(self.base)
        for e in self.effects:
            k = len(self.effect_params(e))
            out[e.name] = slice(i, i + k)
            i += k
        return out

    @property
    def n_theta(self) -> int:
        return len(self.base) + sum(len(self.effect_params(e)) for e in self.effects)

    def null_theta(self, base_values=None) -> np.ndarray:
        """theta with the baseline at ``base_values`` (default: reference) and every effect at its null."""
        parts = [np.asarray(self.base_values if base_values is None else base_values, dtype=np.float64)]
        parts += [np.array([p.null for p in self.effect_params(e)], dtype=np.float64) for e in self.effects]
        return np.concatenate(parts)
