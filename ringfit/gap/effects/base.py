"""What an effect of the gap diagnosis is: named, bounded parameters with a null value, and model hooks.

An effect is one small module under ``ringfit/gap/effects/`` (or anywhere,
see ``docs/adding-an-effect.md``) that defines a subclass of :class:`Effect`
and registers one instance with :func:`ringfit.gap.effects.register`. It
extends the baseline by composition — a change of the predicted modal
frequencies/damping (:meth:`Effect.modal`), a term added to the rolling
ring's per-harmonic operator, a load, or a sensor layer
(:meth:`Effect.profile_model`) — never by copying a model.

Contract, tested for every registered effect: with all parameters at their
``null`` values the prediction equals the baseline's exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Parameter:
    """One parameter of an effect, in natural (SI) units.

    - ``name``: key used in the diagnosis JSON (``candidates[].params``).
    - ``unit``: unit string.
    - ``null``: the value at which the effect vanishes (baseline exactly).
    - ``lo``, ``hi``: hard bounds of the refit (``lo ≤ null ≤ hi``).
    - ``start``: interior starting value of the refit (never the null: some
      effects switch off exactly at the null and have no slope there).
    - ``prior``: optional Gaussian ``(mean, sd)`` entering the refit as an
      extra residual row; ``None`` = flat within the bounds.
    - ``description``: one line for reports.
    - ``condition``: the value the measured condition fixes (e.g. 1 for a patch scale
      when the contact patch is computed from the table's load); an effect whose every
      parameter has one is also tried as a *computed* candidate — a prediction with no
      free parameter. ``None`` = the parameter can only be fitted.
    - ``plausible``: the parameter's physical range ``(low, high)`` (docs/physics.md §6.4, *implausible
      parameters*): a fitted value outside it is not a finding (the candidate is refused, the case is
      ``unexplained`` with the candidate named nearest). ``None`` = the refit's bounds ``(lo, hi)``.
    """

    name: str
    unit: str
    null: float
    lo: float
    hi: float
    start: float
    prior: tuple[float, float] | None = None
    description: str = ""
    condition: float | None = None
    plausible: tuple[float, float] | None = None

    @property
    def physical_range(self) -> tuple[float, float]:
        """``plausible`` or the refit's bounds."""
        return self.plausible if self.plausible is not None else (self.lo, self.hi)

    def __post_init__(self):
        if not (self.lo <= self.null <= self.hi and self.lo <= self.start <= self.hi and self.lo < self.hi):
            raise ValueError(f"parameter {self.name}: need lo <= null, start <= hi (got {self})")

    @property
    def span(self) -> float:
        return self.hi - self.lo


class Effect:
    """Base class of a candidate unmodelled effect (docs/physics.md §6).

    Subclasses set ``name``, ``summary``, ``parameters`` and implement the
    hooks for the kinds of data they speak to:

    - modal data (mode tables): :meth:`modal_mask` and :meth:`modal`;
    - rolling profiles: :meth:`profile_model`.

    A hook that is not implemented means "this effect does not change this
    kind of data"; the diagnosis then lists the effect as not applicable.
    """

    name: str = ""
    summary: str = ""
    #: parameters for every kind of data ...
    parameters: tuple[Parameter, ...] = ()
    #: ... unless the effect needs different ones for rolling profiles (``None`` = ``parameters``)
    profile_parameters: tuple[Parameter, ...] | None = None
    #: baseline parameters the effect legitimately re-balances (e.g. the intercept ζ0 of a
    #: damping slope); they are left out of the drift guard of :mod:`ringfit.gap.verdict`
    baseline_partners: tuple[str, ...] = ()
    #: what in the data makes the effect act on mode-table rows (the ``not_applicable`` note of a diagnosis whose
    #: tables give it no row, docs/formats.md §5); "" = the generic note
    applies_when: str = ""

    # ---------------------------------------------------------------- helpers
    def params_for(self, domain: str) -> tuple[Parameter, ...]:
        """The parameters used on ``domain`` (``"modes"`` or ``"profiles"``)."""
        if domain == "profiles" and self.profile_parameters is not None:
            return self.profile_parameters
        return self.parameters

    def __repr__(self) -> str:
        names = ", ".join(p.name for p in self.parameters) or "no parameters"
        return f"<effect {self.name}: {names}>"

    # ---------------------------------------------------------------- modal data
    def modal_mask(self, rows) -> np.ndarray | None:
        """Bool ``(m,)``: which rows of a :class:`ringfit.gap.modal_rows.ModalRows` the effect can change; ``None`` = not a modal effect."""
        return None

    def modal(self, values, omega, zeta, rows, ring, geometry):
        """Modify the predicted angular frequencies ω [rad/s] and damping ratios ζ [-] of every row.

        **Arguments:** ``values`` — this effect's parameters, JAX ``(k,)`` in
        the order of ``parameters``; ``omega``, ``zeta`` — ``(m,)`` the
        prediction so far (baseline, possibly modified by earlier effects);
        ``rows`` — :class:`ringfit.gap.modal_rows.ModalRows`; ``ring``,
        ``geometry`` — the current ring parameters.

        **Returns:** ``(omega, zeta)`` of the same shapes. At the null values
        it must return its inputs unchanged.
        """
        return omega, zeta

    # ---------------------------------------------------------------- rolling profiles
    def profile_model(self, values, model):
        """Return the rolling-profile model with this effect added (see :mod:`ringfit.gap.profile`).

        ``model`` is a :class:`ringfit.gap.profile.ProfileModel` (the
        baseline's composition: operator terms, extra loads, sensor layers);
        ``values`` JAX ``(k,)``. ``None`` (default) = not a profile effect.
        """
        return None

    def computable(self, domain: str) -> bool:
        """Whether the measured condition fixes every parameter on ``domain`` (a *computed* candidate exists)."""
        params = self.params_for(domain)
        return bool(params) and all(p.condition is not None for p in params)

    @property
    def speaks_to_profiles(self) -> bool:
        return type(self).profile_model is not Effect.profile_model
