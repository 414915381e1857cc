"""The result of a least-squares fit: status, values, uncertainties, residuals.

optimistix returns the optimum and a status but no covariance; every ringfit
fitter fills a :class:`FitResult` with the covariance computed from the
Jacobian of the weighted residuals at the optimum (Gauss–Newton / Laplace
approximation, in the log-parameter space the solver works in).
"""

from __future__ import annotations

import functools

import math
from dataclasses import dataclass, field

import numpy as np

#: A relative standard error above this flags a parameter as poorly determined.
MAX_RELATIVE_STDERR = 0.5


@dataclass
class FitResult:
    """What a fit returns.

    - ``status``: ``"converged"``, ``"max_steps_reached"``, ``"nonfinite"`` or
      another optimistix result name; ``converged`` is ``status == "converged"``.
    - ``message``: one line saying what happened and, if it failed, what to try.
    - ``names``: the free parameters, in solver order (``k`` of them).
    - ``values``: every model parameter after the fit (free and fixed), SI.
    - ``stderr``: one standard error per free parameter (delta method from the
      log-space covariance), SI; ``inf`` where the information is singular.
    - ``covariance_log``: ``(k, k)`` covariance of the log-parameters.
    - ``correlation``: ``(k, k)`` correlation matrix of the free parameters.
    - ``residuals``: ``(m,)`` weighted data residuals (model − data)/σ at the optimum.
    - ``jacobian``: ``(m_total, k)`` Jacobian of all residual rows (data, then
      prior rows) with respect to the log-parameters.
    - ``n_data``: number of data rows m (the first rows of ``jacobian``).
    - ``iterations``: solver steps taken.
    - ``chi2``: sum of squared weighted data residuals; ``dof`` = m − k.
    - ``flags``: human-readable warnings (bound hit, large relative error, ...).
    - ``extra``: fitter-specific arrays (model and measured values, σ, n, ...).
    - ``theta``: ``(p,)`` every parameter of the problem at the optimum, natural units,
      in the order of ``coords`` (the :class:`ringfit.fit.engine.Coordinate` s).
    - ``problem``: the :class:`ringfit.fit.engine.Problem` that was solved (not saved to files;
      :func:`ringfit.fit.posterior.sample` samples it).
    """

    status: str
    message: str
    names: tuple[str, ...]
    values: dict[str, float]
    stderr: dict[str, float]
    covariance_log: np.ndarray
    residuals: np.ndarray
    jacobian: np.ndarray
    n_data: int
    iterations: int
    flags: list[str] = field(default_factory=list)
    extra: dict = field(default_factory=dict)
    theta: np.ndarray | None = None
    coords: tuple = ()
    problem: object = field(default=None, repr=False)

    @property
    def converged(self) -> bool:
        return self.status == "converged"

    @property
    def chi2(self) -> float:
        return float(np.sum(self.residuals**2))

    @property
    def dof(self) -> int:
        return int(self.n_data - len(self.names))

    @property
    def correlation(self) -> np.ndarray:
        c = self.covariance_log
        d = np.sqrt(np.abs(np.diag(c)))
        with np.errstate(invalid="ignore", divide="ignore"):
            return c / np.outer(d, d)

    @property
    def relative_stderr(self) -> dict[str, float]:
        return {k: self.stderr[k] / abs(self.values[k]) if self.values[k] else math.inf for k in self.names}

    @property
    def free_index(self) -> np.ndarray:
        """Positions of the free parameters in ``theta``."""
        order = [c.name for c in self.coords]
        return np.array([order.index(k) for k in self.names], dtype=int)

    def interval(self, name: str, level: float = 0.95) -> tuple[float, float]:
        """Approximate interval from the Laplace approximation in the solver coordinate
        (log-normal for a log parameter, normal for a linear one)."""
        from scipy.special import ndtri  # the normal quantile (scipy.stats is slow to import)

        i = self.names.index(name)
        s = math.sqrt(max(self.covariance_log[i, i], 0.0))
        z = ndtri(0.5 + level / 2)
        v = self.values[name]
        coord = next((c for c in self.coords if c.name == name), None)
        if coord is not None and coord.kind == "linear":
            return v - z * s * coord.scale, v + z * s * coord.scale
        return v * math.exp(-z * s), v * math.exp(z * s)

    def to_record(self, **extra) -> dict:
        """The fit's figures as a JSON-serialisable dict (saved with a posterior; ``extra`` added)."""
        return dict(status=self.status, message=self.message, names=list(self.names),
                    values={k: self.values[k] for k in self.names}, stderr=dict(self.stderr),
                    flags=list(self.flags), chi2=self.chi2, dof=self.dof, n_data=self.n_data,
                    iterations=self.iterations, **extra)

    def summary(self, flags: bool = True, status: bool = True) -> str:
        """A plain-text table of the fit (``flags``: with its warnings; ``status``: with the solver's line)."""
        lines = [f"status: {self.status} after {self.iterations} iterations — {self.message}"] if status else []
        if self.dof > 0:
            lines.append(f"chi2 = {self.chi2:.3g} for {self.n_data} data, {len(self.names)} free (dof {self.dof}; "
                         f"chi2/dof = {self.chi2 / self.dof:.3g})")
        lines.append(f"{'parameter':<14}{'value':>14}{'std err':>12}{'rel.':>9}")
        for k in self.names:
            rel = self.relative_stderr[k]
            rel_s = f"{rel:.1%}" if rel < 10 else ">1000%"
            lines.append(f"{k:<14}{self.values[k]:>14.6g}{self.stderr[k]:>12.3g}{rel_s:>9}")
        if flags:
            lines += [f"WARNING: {flag}" for flag in self.flags]
        return "\n".join(lines)


@dataclass
class BatchFitResult:
    """What :func:`ringfit.fit.engine.least_squares_batch` returns: B fits of one problem structure.

    - ``names``: the free parameters (``k``); ``coords``: every parameter's coordinate.
    - ``theta``: ``(B, p)`` every parameter at each optimum, natural units.
    - ``status``: ``(B,)`` solver status strings (as :attr:`FitResult.status`); ``converged`` ``(B,)`` bool.
    - ``iterations``: ``(B,)`` solver steps.
    - ``stderr``: ``(B, k)`` standard errors, natural units; ``covariance_log``: ``(B, k, k)`` in the
      solver coordinates (as :attr:`FitResult.covariance_log`).
    - ``residuals``: ``(B, m)`` weighted data residuals (scaled by ``sigma_scale`` for ``sigma="estimate"``);
      ``chi2_raw``: ``(B,)`` Σ r² before that scaling; ``sigma_scale``: ``(B,)``.
    - ``at_bound``: ``(B, k)`` bool, a free parameter within 1e-6 of a bound of its coordinate.
    - ``aux``: the model's aux at each optimum (leading axis B); ``n_data``: data rows per fit.
    """

    names: tuple[str, ...]
    coords: tuple
    theta: np.ndarray
    status: np.ndarray
    iterations: np.ndarray
    stderr: np.ndarray
    covariance_log: np.ndarray
    residuals: np.ndarray
    chi2_raw: np.ndarray
    sigma_scale: np.ndarray
    at_bound: np.ndarray
    aux: object
    n_data: int

    @property
    def converged(self) -> np.ndarray:
        return self.status == "converged"

    def __len__(self) -> int:
        return self.theta.shape[0]

    def values(self, name: str) -> np.ndarray:
        """``(B,)`` values of one parameter, natural units."""
        return self.theta[:, [c.name for c in self.coords].index(name)]

    def interval(self, name: str, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """``(lo, hi)`` ``(B,)`` Laplace intervals, as :meth:`FitResult.interval`."""
        from scipy.special import ndtri  # the normal quantile (scipy.stats is slow to import)

        i = self.names.index(name)
        s = np.sqrt(np.clip(self.covariance_log[:, i, i], 0.0, None))
        z = ndtri(0.5 + level / 2)
        v = self.values(name)
        coord = next(c for c in self.coords if c.name == name)
        if coord.kind == "linear":
            return v - z * s * coord.scale, v + z * s * coord.scale
        return v * np.exp(-z * s), v * np.exp(z * s)


def covariance_batch(jacobian: np.ndarray, rcond: float = 1e-12) -> np.ndarray:
    """:func:`covariance_from_jacobian` of a stack of Jacobians ``(B, m, k)`` → ``(B, k, k)`` (one batched SVD)."""
    J = np.asarray(jacobian, dtype=np.float64)
    _, s, vt = np.linalg.svd(J, full_matrices=False)
    keep = s > rcond * s[:, :1]
    inv = np.where(keep, 1.0 / np.where(keep, s, 1.0) ** 2, 0.0)
    cov = np.einsum("bji,bj,bjl->bil", vt, inv, vt)
    for b in np.flatnonzero(~keep.all(axis=1)):
        cov[b] = covariance_from_jacobian(J[b], rcond)
    return cov


def covariance_from_jacobian(jacobian: np.ndarray, rcond: float = 1e-12) -> np.ndarray:
    """``(JᵀJ)⁻¹`` via the SVD of J; directions with no information get ``inf`` variance.

    **Arguments:** ``jacobian`` — ``(m, k)`` Jacobian of weighted residuals.
    **Returns:** ``(k, k)`` covariance.
    """
    J = np.asarray(jacobian, dtype=np.float64)
    _, s, vt = np.linalg.svd(J, full_matrices=False)
    k = J.shape[1]
    if s.size == 0:
        return np.full((k, k), np.inf)
    keep = s > rcond * s[0]
    inv = np.where(keep, 1.0 / np.where(keep, s, 1.0) ** 2, np.inf)
    with np.errstate(invalid="ignore"):
        cov = (vt.T * inv) @ vt
    if not keep.all():
        # an unidentifiable direction: mark every parameter that loads on it
        null = np.abs(vt[~keep]).max(axis=0) > 1e-8
        cov[np.ix_(null, null)] = np.inf
    return cov


def gauss_newton_step(fit: FitResult, delta: np.ndarray) -> np.ndarray:
    """The Gauss–Newton step ``δu = −J⁺ Δr`` of the fit's free solver coordinates for a change ``delta`` ``(m,)``
    of its data rows (as ``fit.residuals``, σ scale as fitted; the prior's rows unchanged): how far the optimum
    moves when the rows change by ``delta`` at the fit (docs/physics.md §10 *the model's grid*)."""
    full = np.zeros(fit.jacobian.shape[0])
    full[:fit.residuals.size] = delta
    return -np.linalg.lstsq(fit.jacobian, full, rcond=None)[0]


#: The range of Richardson's ratio ρ = |δu_a|/|δu_b| of two successive grid halvings' moves (:func:`richardson_tail`):
#: 2 is a first-order error (the tail as large as the last move), 16 a fourth-order one.
RICHARDSON_RHO = (2.0, 16.0)


def richardson_tail(step_a: np.ndarray, step_b: np.ndarray, covariance: np.ndarray) -> np.ndarray:
    """The move still to come beyond the finest of three grids (M, 2M, 4M), by Richardson's rule on the fit's own
    moves ``step_a`` (M → 2M) and ``step_b`` (2M → 4M): ρ = |δu_a|/|δu_b| in the metric of ``covariance`` (the
    fit's, solver coordinates), clipped to :data:`RICHARDSON_RHO` (at worst a first-order error, the tail as large
    as the last move); the tail is δu_b/(ρ − 1) (docs/physics.md §13.4 *the model's grid*)."""
    prec = np.linalg.pinv(np.asarray(covariance, dtype=np.float64))
    size = lambda d: math.sqrt(max(float(d @ prec @ d), 0.0))  # noqa: E731
    rho = float(np.clip(size(step_a) / max(size(step_b), 1e-300), *RICHARDSON_RHO))
    return np.asarray(step_b, dtype=np.float64) / (rho - 1.0)


def grid_moves(fit: FitResult, rows) -> tuple[list, np.ndarray]:
    """The fit's moves under a model refined M → 2M → 4M … (docs/physics.md §11, §13.4 *the model's grid*): ``rows``
    the fit's weighted data rows ``(m,)`` at each grid, coarsest first (as ``fit.residuals``, σ scale as fitted);
    each halving's move is one Gauss–Newton step of the rows' change (:func:`gauss_newton_step`), and the move still
    to come beyond the finest grid Richardson's on the last two (:func:`richardson_tail`; with one halving, as large
    as it). **Returns** ``(steps, tail)`` in the fit's free solver coordinates."""
    rows = [np.asarray(r, dtype=np.float64).ravel() for r in rows]
    steps = [gauss_newton_step(fit, b - a) for a, b in zip(rows[:-1], rows[1:])]
    tail = richardson_tail(steps[-2], steps[-1], fit.covariance_log) if len(steps) > 1 else steps[-1]
    return steps, tail


def solver_status(result) -> tuple[str, str]:
    """``(status, message)`` from an ``optimistix.RESULTS`` item or its integer code (outside jit).

    status is ``"converged"``, ``"max_steps_reached"``, ``"divergence"``,
    ``"nonfinite"`` or ``"failed"``; message is optimistix's explanation.
    """
    successful, named, messages = _status_codes()
    code = int(getattr(result, "_value", result))
    if code == successful:
        return "converged", "the solver met its tolerances"
    return named.get(code, "failed"), messages[code]


@functools.cache
def _status_codes() -> tuple[int, dict[int, str], dict]:
    """optimistix's code of success, the codes of the named failures, and every code's message (read once)."""
    import optimistix as optx

    named = {int(getattr(optx.RESULTS, name)._value): name.removeprefix("nonlinear_")
             for name in ("nonlinear_max_steps_reached", "nonlinear_divergence", "nonfinite")}
    return int(optx.RESULTS.successful._value), named, optx.RESULTS._index_to_message


def solver_flags(status: str, message: str) -> list[str]:
    """The report line for a solver that did not converge (none when it did)."""
    return [] if status == "converged" else [f"solver did not converge ({status}): {message}"]


def parameter_flags(names, values: dict, stderr: dict, *, data: str = "these data", priors=(),
                    plausible: dict | None = None) -> list[str]:
    """Warnings for fitted positive parameters: at the edge of the plausible range, or poorly determined.

    A parameter is at the edge when its logarithm lies within 1 % of the log-span
    of its plausible range (``plausible``: name -> (lo, hi); names not in it are not
    checked) from either bound (or beyond); poorly determined when its relative
    standard error exceeds :data:`MAX_RELATIVE_STDERR`. ``data`` names what was
    fitted (for the message); ``priors`` the parameters that carried an informative prior.
    """
    flags = []
    for k in names:
        if plausible and k in plausible:
            lo, hi = plausible[k]
            span = math.log(hi / lo)
            y = math.log(values[k]) if values[k] > 0 else -math.inf
            if y <= math.log(lo) + 0.01 * span or y >= math.log(hi) - 0.01 * span:
                flags.append(f"{k} = {values[k]:.4g} ran to the edge of its plausible range [{lo:.3g}, {hi:.3g}]: "
                             "the data do not bound it")
        rel = stderr[k] / abs(values[k]) if values[k] else math.inf
        if not rel <= MAX_RELATIVE_STDERR:
            pct = f"{rel:.0%}" if rel < 10 else "over 1000 %"
            hint = " even with its prior" if k in priors else " (consider an informative prior)"
            flags.append(f"{k} has relative standard error {pct} > {MAX_RELATIVE_STDERR:.0%}: "
                         f"poorly determined by {data}" + hint)
    return flags
