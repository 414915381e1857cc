"""Which parameters do the data determine? Fisher information and profile likelihood.

For weighted least squares the Fisher information of the log-parameters is
``F = JᵀJ`` (J: Jacobian of the weighted data residuals). Its eigenvalues say
how strongly each parameter *combination* is pinned: a standard deviation of
``1/√λ`` in log units along eigenvector ``v``. A tiny eigenvalue whose
eigenvector loads on one parameter means that parameter is not identifiable
from these data. The profile likelihood confirms it without linearisation:
``χ²_min(θ_k)`` minimised over the other parameters, for θ_k on a grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ringfit.fit.priors import PriorSpec
from ringfit.fit.result import MAX_RELATIVE_STDERR, FitResult

#: An eigen-direction whose log-standard deviation 1/√λ exceeds this (a factor
#: e^0.5 ≈ 1.65 at one σ) is called poorly determined.
MAX_LOG_STD = 0.5


@dataclass
class Identifiability:
    """Findings about a fit.

    - ``names``: free parameters ``(k,)``.
    - ``eigenvalues``: ``(k,)`` eigenvalues of the data-only Fisher information
      of log-parameters, ascending; ``eigenvectors``: ``(k, k)`` columns.
    - ``log_std``: ``(k,)`` 1/√λ per eigen-direction.
    - ``condition_number``: λ_max/λ_min.
    - ``flags``: one sentence per finding (parameters at bounds, relative
      standard error > 50 %, weak eigen-directions).
    - ``profiles``: name -> (grid ``(g,)`` SI, χ²_min ``(g,)``) when computed.
    """

    names: tuple[str, ...]
    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    log_std: np.ndarray
    condition_number: float
    flags: list[str] = field(default_factory=list)
    profiles: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)

    @property
    def well_posed(self) -> bool:
        return not self.flags

    def to_record(self) -> dict:
        """A JSON-serialisable dict (saved with a posterior, so a report can redraw it)."""
        return dict(names=list(self.names), eigenvalues=self.eigenvalues.tolist(),
                    eigenvectors=self.eigenvectors.tolist(), log_std=np.where(np.isfinite(self.log_std), self.log_std,
                                                                               1e300).tolist(),
                    condition_number=self.condition_number if math.isfinite(self.condition_number) else 1e300,
                    flags=list(self.flags),
                    profiles={k: [g.tolist(), c.tolist()] for k, (g, c) in self.profiles.items()})

    @classmethod
    def from_record(cls, record: dict) -> "Identifiability":
        """The inverse of :meth:`to_record`."""
        return cls(tuple(record["names"]), np.asarray(record["eigenvalues"]), np.asarray(record["eigenvectors"]),
                   np.asarray(record["log_std"]), float(record["condition_number"]), list(record["flags"]),
                   {k: (np.asarray(g), np.asarray(c)) for k, (g, c) in record.get("profiles", {}).items()})

    def summary(self, known=()) -> str:
        """Plain text: the Fisher spectrum and the findings (``known``: findings already printed, left out)."""
        lines = ["Fisher information of log-parameters (data only):",
                 f"{'λ':>11} {'σ(log)':>8}  dominant loadings"]
        for lam, s, v in zip(self.eigenvalues, self.log_std, self.eigenvectors.T):
            order = np.argsort(-np.abs(v))
            load = ", ".join(f"{v[i]:+.2f} {self.names[i]}" for i in order if abs(v[i]) > 0.2)
            lines.append(f"{lam:11.3g} {s:8.3g}  {load}")
        lines.append(f"condition number {self.condition_number:.3g}")
        lines += [f"FLAG: {f}" for f in self.flags if f not in known] or (
            [] if self.flags else ["all parameters determined by the data"])
        return "\n".join(lines)


def identifiability(result: FitResult, *, profile: tuple[str, ...] = (), fit_again=None,
                    grid_points: int = 25) -> Identifiability:
    """Analyse a :class:`FitResult` from a least-squares fit.

    **Arguments:**

    - ``result``: a fit whose ``jacobian`` rows start with the data rows.
    - ``profile``: parameter names whose profile likelihood to compute.
    - ``fit_again``: ``callable(name, value) -> FitResult`` that refits with
      ``name`` fixed at ``value`` (needed for ``profile``; see
      :func:`profile_natural_frequencies`).
    - ``grid_points``: profile grid size; the grid spans the parameter's
      plausible range (:data:`ringfit.fit.priors.BOUNDS`).

    Examples
    --------
    Without a prior, the free tyre's modes leave EI almost undetermined, and the
    analysis says so:

    >>> from ringfit.data import path
    >>> from ringfit.fit.identifiability import identifiability
    >>> from ringfit.fit.least_squares import fit_natural_frequencies
    >>> from ringfit.io.modes import read_mode_table
    >>> from ringfit.io.tyre import read_tyre
    >>> tyre = read_tyre(path("table9.tyre.toml"))
    >>> table = read_mode_table(path("free-ssi.modes.csv"))
    >>> fit = fit_natural_frequencies(table, tyre.geometry, tyre.ring, prior="physical")
    >>> ident = identifiability(fit)
    >>> ident.well_posed
    False
    >>> any("ei" in flag for flag in ident.flags)
    True
    """
    from ringfit.fit.priors import BOUNDS

    J = np.asarray(result.jacobian)[: result.n_data]
    F = J.T @ J
    lam, vec = np.linalg.eigh(F)
    lam = np.clip(lam, 0.0, None)
    with np.errstate(divide="ignore"):
        log_std = 1.0 / np.sqrt(lam)
    cond = float(lam[-1] / lam[0]) if lam[0] > 0 else math.inf
    flags = [f for f in result.flags if "ran to the edge" in f or "relative standard error" in f]
    for lam_i, s, v in zip(lam, log_std, vec.T):
        if s > MAX_LOG_STD:
            main = int(np.argmax(np.abs(v)))
            flags.append(
                f"weak direction: the data fix {'/'.join(n for n, x in zip(result.names, v) if abs(x) > 0.3)} "
                f"(mostly {result.names[main]}) only to "
                + (f"a factor {math.exp(s):.3g}" if s < math.log(100) else "worse than a factor 100")
                + " at one σ "
                f"(Fisher eigenvalue {lam_i:.3g})"
            )
    for k in result.names:
        rel = result.relative_stderr[k]
        if not rel <= MAX_RELATIVE_STDERR and not any(k in f and "relative" in f for f in flags):
            flags.append(f"{k} has relative standard error {rel:.0%} > {MAX_RELATIVE_STDERR:.0%}"
                         if rel < 10 else f"{k} has relative standard error over 1000 %")
    out = Identifiability(tuple(result.names), lam, vec, log_std, cond, flags)
    for name in profile:
        if fit_again is None:
            raise ValueError("profile likelihood needs fit_again")
        lo, hi = BOUNDS[name]
        grid = np.geomspace(lo, hi, grid_points)
        chi2 = np.array([fit_again(name, x).chi2 for x in grid])
        out.profiles[name] = (grid, chi2)
    return out


def profile_natural_frequencies(table, geometry, initial, free, prior: PriorSpec = "none", noise_scale=None,
                                **kwargs):
    """A ``fit_again`` callable for :func:`identifiability` on eq. 18 fits.

    The refits hold the σ of the rows where the fit with every parameter free settled it (``noise="fixed"`` at
    its ``extra["noise_scale"]``, docs/physics.md §11 "Noise per block"), so their χ² compare on one scale:
    ``noise_scale`` — that scale (default: that fit, made once on the first call)."""
    from ringfit.fit.least_squares import fit_natural_frequencies

    scale = [noise_scale]

    def fit_again(name, value):
        if scale[0] is None:
            full = fit_natural_frequencies(table, geometry, initial, free=free, prior=prior, **kwargs)
            scale[0] = float(full.extra["noise_scale"])
        others = tuple(k for k in free if k != name)
        return fit_natural_frequencies(table, geometry, initial.replace(**{name: value}), free=others,
                                       prior=prior, noise="fixed", noise_scale=scale[0], **kwargs)

    return fit_again
