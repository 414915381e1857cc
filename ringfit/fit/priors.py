"""Priors and plausibility bounds for ring parameters.

Every positive parameter is handled as its natural logarithm inside solvers
and samplers. A :class:`LogNormalPrior` on a parameter θ is a normal prior on
``log θ``; parameters without an informative prior get a uniform prior on
``log θ`` within :data:`BOUNDS` (scale-free, weakly informative).

The physically based prior on the bending stiffness (:data:`PHYSICAL_PRIORS`)
is what makes the free-tyre fit well posed: on a free tyre's n = 1…9 modes the
bending term ``EI/R⁴·n²(n²−1)²`` is at most ~10 % of the pressure term, so the
frequencies hardly constrain EI (see ``ringfit.fit.identifiability``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, get_args

from ringfit.errors import InputError


@dataclass(frozen=True)
class LogNormalPrior:
    """Normal prior on ``log θ``: median ``median`` (SI), log-standard deviation ``sigma_ln``."""

    median: float
    sigma_ln: float
    source: str = ""

    @property
    def mu(self) -> float:
        return math.log(self.median)

    def interval(self, level: float = 0.95) -> tuple[float, float]:
        """Central ``level`` interval ``(lo, hi)`` of the log-normal, natural units."""
        from scipy.special import ndtri  # the normal quantile (scipy.stats is slow to import)

        z = ndtri(0.5 + level / 2)
        return self.median * math.exp(-z * self.sigma_ln), self.median * math.exp(z * self.sigma_ln)


#: Plausibility bounds (SI) for a passenger-car tyre; a fit that ends outside or
#: within 1 % (in log) of a bound is flagged, and the posterior's flat log-prior is
#: truncated here.
BOUNDS: dict[str, tuple[float, float]] = {
    "rho_a": (0.3, 30.0),
    "ei": (1.0e-3, 1.0e3),
    "kw": (1.0e4, 1.0e8),
    "kv": (1.0e4, 1.0e8),
    "damping_ratio": (1.0e-4, 0.5),
    "k_tread": (1.0e5, 1.0e9),
    "ea": (1.0e3, 1.0e10),
}

#: The bending-stiffness prior offered to make the free-tyre fit well posed.
#: The steel-belt package of a passenger-car tyre treated as a plate,
#: ``EI = E_eff·b·h³/12``, with effective circumferential modulus
#: E_eff = 0.5–5 GPa (steel-cord plies at ±20–25° in rubber, shear-lag reduced)
#: and package thickness h = 2–4 mm, spans EI ≈ 0.05–4 N m² for b = 0.152 m; the
#: prior puts that span at ±2σ: median √(0.05·4) ≈ 0.45 N m², σ_ln = ln(80)/4 ≈ 1.1.
#: The source study's Table 9 value (0.94 N m², solved from three modes) lies
#: inside one σ; the prior is independent of the free-tyre frequencies.
EI_BELT_PLATE_PRIOR = LogNormalPrior(
    median=math.sqrt(0.05 * 4.0),
    sigma_ln=math.log(4.0 / 0.05) / 4.0,
    source="steel-belt plate estimate EI = E_eff b h^3/12, E_eff 0.5-5 GPa, h 2-4 mm, b = 0.152 m (0.05-4 N m^2 at +-2 sigma)",
)

PHYSICAL_PRIORS: dict[str, LogNormalPrior] = {"ei": EI_BELT_PLATE_PRIOR}

#: A named prior of :func:`resolve_priors`: ``"none"`` (no informative prior) or ``"physical"``
#: (:data:`PHYSICAL_PRIORS`).
PriorName = Literal["none", "physical"]
#: A fit's ``prior`` argument: a :data:`PriorName`, a dict name -> :class:`LogNormalPrior` or (median, σ_ln), or
#: ``None`` (as ``"none"``).
PriorSpec = PriorName | dict[str, LogNormalPrior | tuple[float, float]] | None


def resolve_priors(prior: PriorSpec, free: tuple[str, ...]) -> dict[str, LogNormalPrior]:
    """Turn the user's ``prior`` argument into {name: LogNormalPrior} for free parameters.

    ``prior`` may be ``None``/``"none"`` (no informative prior), ``"physical"``
    (:data:`PHYSICAL_PRIORS`), or a dict name -> LogNormalPrior or (median, sigma_ln).
    Priors on fixed parameters are ignored.
    """
    if prior is None or prior == "none":
        return {}
    if prior == "physical":
        chosen = dict(PHYSICAL_PRIORS)
    elif isinstance(prior, dict):
        chosen = {}
        for k, v in prior.items():
            if k not in BOUNDS:
                raise InputError(f"prior on unknown parameter {k!r}; known: {sorted(BOUNDS)}")
            chosen[k] = v if isinstance(v, LogNormalPrior) else LogNormalPrior(float(v[0]), float(v[1]))
    else:
        raise InputError(f"prior = {prior!r}; expected {', '.join(map(repr, get_args(PriorName)))} or a dict")
    return {k: v for k, v in chosen.items() if k in free}

