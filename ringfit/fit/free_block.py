"""The free-modes block: a free tyre's natural frequencies, their rows and their noise model, once for every fit
that reads a free table (docs/physics.md §11 "Noise per block").

``ringfit fit`` (:func:`ringfit.fit.least_squares.fit_natural_frequencies`), ``ringfit sample`` and ``ringfit
identify`` (:mod:`ringfit.fit.identify`, its free-modes block; its damping and loaded-mode blocks use the same
scale) read the same free table the same way, so the same table gives the same ring and the same interval:

- **rows**: :func:`frequency_data` — the table's structural rows with an assigned n, each with its starting σ:
  ``freq_std_hz`` where given, else :data:`DEFAULT_RELATIVE_STD` × f (or the caller's stated relative σ);
- **scale**: :func:`block_scale` — the block's σ scale from its weighted residual and the degrees of freedom the
  fit took from it, ``s² = χ² / (m − tr H_bb)`` with ``H`` the hat matrix (:func:`hat_diagonal`); a stated σ is
  only scaled up (s ≥ 1: a table that states too small a σ is widened, one that states too large a σ is kept);
  the fit is repeated with the rescaled rows until the scale settles (:data:`SCALE_PASSES`,
  :data:`SCALE_TOLERANCE`): a prior (``--prior physical``'s EI) makes the optimum depend on the scale;
- **intervals**: :func:`t_widening` — a scale estimated from ν residual degrees of freedom makes the parameters
  it pins follow Student's t_ν: the block's rows are widened by ``t_{ν,0.975}/z_{0.975}``; and by √κ, the
  block's model-discrepancy ratio (:func:`discrepancy_ratio` on :func:`frequency_folds`: held-out rows predicted
  worse than their noise allows) — in the covariance and in the sampled likelihood alike (``row_scale``,
  :func:`row_widening`, docs/physics.md §12.3).

:func:`fit_free_block` runs the whole model around any fit of the block (``ringfit fit``'s); ``ringfit identify``
composes the same functions over its blocks in its joint passes.

Example::

    data = frequency_data(table)                     # σ₀ per row, stated or not
    s, dof = block_scale(r, hat_diagonal(J)[:m], data.stated)
    widen = t_widening(dof)                          # 1 for a stated σ that holds
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from ringfit.errors import InputError
from ringfit.io.modes import ModeTable
from ringfit.units import Z95

#: σ_i / f_i where a mode table has no ``freq_std_hz``, as the *start* of the block's scale estimate (the scale is
#: then estimated from the residual). 1 % is the RMS relative difference between the source study's two
#: identifications of the same nine modes (Table 2: SSI vs FRF peak picking, 0.9 %), i.e. the spread that the
#: choice of identification method alone produces.
DEFAULT_RELATIVE_STD = 0.01
#: Passes of fit → block noise scales → refit (the scales settle in two or three).
SCALE_PASSES = 4
#: Stop re-weighting once every block scale changes by less than this fraction.
SCALE_TOLERANCE = 0.02
#: The smallest σ/f the scale estimate gives a row: no measured frequency is known better than 1 ppm, and a table
#: of exact model frequencies (residual ~1e-15) must not weight its rows by a σ the solver cannot resolve.
SIGMA_FLOOR_REL = 1e-6
#: Folds of a frequency block for its discrepancy ratio (rows dealt round-robin: each fold spans the harmonics n).
DISCREPANCY_FOLDS = 3
#: A fold direction whose leverage is above this is the fold's alone (held out, nothing predicts it): left out.
FOLD_LEVERAGE_MAX = 0.99
#: The noise models of a frequency fit: ``"estimated"`` (the block's scale from its residual, this module's),
#: ``"fixed"`` (the starting σ as it is: a known σ, e.g. the posterior's simulation-based calibration, or the
#: profile likelihood's refits at a fit's settled σ).
NoiseModel = Literal["estimated", "fixed"]
#: The names of :data:`NoiseModel`, as :func:`check_noise` validates them.
NOISE_MODELS: tuple[str, ...] = get_args(NoiseModel)


@dataclass(frozen=True)
class FrequencyData:
    """The rows of a mode table that take part in a fit.

    Arrays of shape ``(m,)``: ``n`` (float), ``freq_hz``, ``sigma_hz`` (the starting σ); ``rows`` are the indices
    into the table; ``sigma_source`` says where σ came from; ``stated``: every row's σ was stated (the table's
    ``freq_std_hz``, or the caller's relative σ) — the block's scale only widens it.
    """

    n: np.ndarray
    freq_hz: np.ndarray
    sigma_hz: np.ndarray
    rows: np.ndarray
    sigma_source: str
    stated: bool = False


def frequency_data(table: ModeTable, modes=None, default_relative_std: float | None = None) -> FrequencyData:
    """Select the rows of ``table`` a ring fit uses and give each its starting σ.

    **Arguments:**

    - ``modes``: ``None`` (every structural row with an assigned n), an
      iterable of n values to keep (e.g. ``range(1, 7)``), or a bool mask of
      shape ``(len(table),)``.
    - ``default_relative_std``: σ/f where ``freq_std_hz`` is empty, stated by the caller (e.g. ``ringfit fit
      --default-std``); ``None``: :data:`DEFAULT_RELATIVE_STD`, a start only (not stated).
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
    user = default_relative_std is not None
    rel = DEFAULT_RELATIVE_STD if default_relative_std is None else float(default_relative_std)
    std = table.freq_std_hz[rows]
    f = table.freq_hz[rows]
    have = np.isfinite(std) & (std > 0)
    sigma = np.where(have, std, rel * f)
    if have.all():
        source = "freq_std_hz"
    elif not have.any():
        source = f"{'stated' if user else 'default'} {rel:.1%} of frequency"
    else:
        source = f"freq_std_hz where given, else {'stated ' if user else ''}{rel:.1%} of frequency"
    return FrequencyData(table.n[rows].astype(np.float64), f, sigma, rows, source, stated=bool(have.all() or user))


def hat_diagonal(J: np.ndarray) -> np.ndarray:
    """Diagonal of the hat matrix ``J (JᵀJ)⁺ Jᵀ`` of a weighted problem's rows ``J`` ``(rows, k)`` (data and prior
    rows): the leverage of each row, whose sum over a block is the degrees of freedom the fit took from it."""
    U, s, _ = np.linalg.svd(np.asarray(J, dtype=np.float64), full_matrices=False)
    keep = s > 1e-12 * (s[0] if s.size else 1.0)
    return np.sum(U[:, keep] ** 2, axis=1)


def block_scale(residual, leverage, stated: bool, scaled: float = 1.0) -> tuple[float, float]:
    """The σ scale of one block and its residual degrees of freedom ``(s, ν)`` (docs/physics.md §11).

    ``residual`` ``(m,)``: the block's weighted rows ``(model − data)/σ`` at the optimum; ``leverage`` ``(m,)``: their
    hat-matrix diagonal (:func:`hat_diagonal` of the whole problem's Jacobian, prior rows included). ``s² = Σ r² /
    ν`` with ``ν = max(m − Σ h, 1)``: the factor to multiply the rows' present σ by. A ``stated`` σ is only scaled
    up: ``scaled`` is the factor its present σ already carries (the passes before), and the stated σ's total
    factor ``scaled · s`` stays ≥ 1; where the stated σ holds (total 1) no scale was estimated (ν = ∞, no
    widening)."""
    r = np.asarray(residual, dtype=np.float64)
    dof = max(r.size - float(np.sum(leverage)), 1.0)
    s = math.sqrt(float(r @ r) / dof)
    if stated and scaled * s <= 1.0:
        return 1.0 / scaled, math.inf
    return s, dof


def t_widening(dof: float) -> float:
    """``t_{ν, 0.975} / z_{0.975}``: how much wider a 95 % interval must be when the σ of its rows is estimated
    from ν residual degrees of freedom (1 for ν = ∞). A block whose scale came from a few rows (9 free modes
    less the ~4 parameters they pin leave ν ≈ 5: ×1.31) has its Fisher information divided by its square."""
    if not math.isfinite(dof):
        return 1.0
    from scipy.special import stdtrit

    return float(stdtrit(max(dof, 1.0), 0.975)) / Z95


def frequency_folds(idx) -> list[np.ndarray]:
    """The held-out groups of a frequency block's rows ``idx`` (indices into the residual vector): dealt round-robin
    into :data:`DISCREPANCY_FOLDS`, so each fold spans the harmonics n (docs/physics.md §11, model discrepancy)."""
    idx = np.asarray(idx)
    return [idx[j::DISCREPANCY_FOLDS] for j in range(min(DISCREPANCY_FOLDS, idx.size))]


def discrepancy_ratio(J: np.ndarray, r: np.ndarray, folds: list[np.ndarray]) -> float:
    """κ_b ≥ 1: how much more each held-out fold of a block would move the fit than its noise allows
    (docs/physics.md §11, *model discrepancy*).

    ``J``: the weighted Jacobian of the fit (data and prior rows), ``r``: its weighted residuals (unit variance
    where the noise model is right), ``folds``: the block's held-out groups (row indices). With H = J(JᵀJ)⁺Jᵀ,
    a fold F's rows predicted from the fit without them have the residual (I − H_FF)⁻¹ r_F (linearised), and its
    influence ``D_F = r_Fᵀ H_FF (I − H_FF)⁻¹ r_F`` has expectation tr H_FF under the noise model alone. A form
    error the parameters absorb differently in each fold raises it, however well the block's σ was fitted. Returns
    ``max(1, Σ_F D_F / Σ_F tr H_FF)`` (directions of leverage > :data:`FOLD_LEVERAGE_MAX` left out); the block's
    σ is multiplied by √κ_b in the covariance, i.e. a discrepancy variance (κ_b − 1)σ² added in quadrature.
    A fit without finite rows (not converged, said by its status) gets 1."""
    if not (np.all(np.isfinite(J)) and np.all(np.isfinite(r))):
        return 1.0
    U, s, Vt = np.linalg.svd(J, full_matrices=False)
    keep = s > 1e-12 * (s[0] if s.size else 1.0)
    L = Vt[keep].T / s[keep]  # (JᵀJ)⁺ = L Lᵀ
    D = T = 0.0
    for F in folds:
        if F.size == 0:
            continue
        u, sv, _ = np.linalg.svd(J[F] @ L, full_matrices=False)  # H_FF = u diag(sv²) uᵀ
        lam = sv**2
        ok = lam < FOLD_LEVERAGE_MAX
        c = u[:, ok].T @ r[F]
        D += float(np.sum(lam[ok] / (1.0 - lam[ok]) * c**2))
        T += float(np.sum(lam[ok]))
    return max(1.0, D / T) if T > 0 else 1.0


def check_noise(noise: str) -> NoiseModel:
    """``noise`` if it is one of :data:`NOISE_MODELS`, else an :class:`~ringfit.errors.InputError`."""
    if noise not in NOISE_MODELS:
        raise InputError(f"noise model {noise!r}: expected one of {', '.join(NOISE_MODELS)}")
    return noise


def noise_passes(fit_once, renoise) -> tuple:
    """The blocks' noise passes (docs/physics.md §11 *Noise per block*), the one loop of every block and of
    ``identify``: fit, re-estimate each block's noise from that fit, refit.

    ``fit_once()`` fits with the noise as it stands and returns its :class:`~ringfit.fit.result.FitResult`;
    ``renoise(fit)`` estimates each block's noise from ``fit``, sets it for the next fit and returns
    ``(change, holds)``: the largest relative change of a block's scale (0 for a block whose noise model has no
    single scale, the profiles'), and whether the noise held as it was (a stated σ the residual does not exceed:
    the refit would repeat the fit). The passes stop at the first settled fit (converged, or evaluated where
    nothing is free) whose noise held, or, after the first pass, whose scales moved by less than
    :data:`SCALE_TOLERANCE`; at most :data:`SCALE_PASSES` fits. The caller keeps what the last fit used.

    **Returns:** ``(fit, passes)``: the last fit and the fits made.
    """
    fit, passes = None, 0
    for passes in range(1, SCALE_PASSES + 1):
        fit = fit_once()
        change, holds = renoise(fit)
        settled = fit.converged or fit.status == "evaluated"
        if settled and (holds or (passes > 1 and change < SCALE_TOLERANCE)):
            break
    return fit, passes


def fit_free_block(fit_at, sigma0: np.ndarray, stated: bool, noise: NoiseModel = "estimated", scale0: float = 1.0,
                   freq_hz: np.ndarray | None = None):
    """A fit of one free-modes block with its noise model: refit with the rows' σ rescaled until the scale settles.

    ``fit_at(sigma (m,))`` fits (or evaluates) the problem with those σ and returns its
    :class:`~ringfit.fit.result.FitResult` (residual rows: the block's ``m`` rows, then the prior's; Jacobian
    likewise); ``sigma0`` ``(m,)`` the starting σ (:func:`frequency_data`); ``stated``: only scaled up;
    ``noise``: ``"estimated"`` (the scale, :func:`block_scale`, at most :data:`SCALE_PASSES` fits, until the
    scale changes by less than :data:`SCALE_TOLERANCE`; with ``freq_hz`` no row's σ below :data:`SIGMA_FLOOR_REL` × f)
    or ``"fixed"`` (σ₀ × ``scale0``, one fit, no widening).

    **Returns:** ``(fit, info)``: the last fit (its rows weighted by the σ it used) and ``info`` — ``scale`` (σ used
    / σ₀), ``dof`` (ν of the last fit's residual; ∞ for a stated σ that holds or a fixed one), ``t_widening``,
    ``discrepancy`` (κ ≥ 1 of :func:`discrepancy_ratio` on :func:`frequency_folds`; 1 for a fixed σ), ``passes``,
    ``noise``, ``sigma_hz`` (the σ used). The intervals' rows are widened by ``t_widening · √discrepancy``
    (:func:`row_widening`)."""
    check_noise(noise)
    sigma0 = np.asarray(sigma0, dtype=np.float64)
    m = sigma0.size
    scale = float(scale0)
    if noise == "fixed":
        fit = fit_at(sigma0 * scale)
        return fit, dict(scale=scale, dof=math.inf, t_widening=1.0, discrepancy=1.0, passes=1, noise=noise,
                         sigma_hz=sigma0 * scale)
    floor = 0.0 if freq_hz is None else SIGMA_FLOOR_REL * float(np.max(np.asarray(freq_hz) / sigma0))
    state = dict(scale=scale, used=scale, dof=math.inf)

    def fit_once():
        state["used"] = state["scale"]
        return fit_at(sigma0 * state["used"])

    def renoise(fit):
        r = np.asarray(fit.residuals, dtype=np.float64)[:m]
        s, state["dof"] = block_scale(r, hat_diagonal(fit.jacobian)[:m], stated, state["used"])
        state["scale"] = max(state["used"] * s, floor)
        return abs(s - 1.0), s == 1.0

    fit, passes = noise_passes(fit_once, renoise)
    scale, dof = state["used"], state["dof"]
    kappa = discrepancy_ratio(np.asarray(fit.jacobian), np.asarray(fit.residuals), frequency_folds(np.arange(m)))
    return fit, dict(scale=scale, dof=dof, t_widening=t_widening(dof), discrepancy=kappa, passes=passes, noise=noise,
                     sigma_hz=sigma0 * scale)


def row_widening(info: dict) -> float:
    """The factor on the block's σ in its intervals and its sampled likelihood: ``t_widening · √discrepancy`` (as
    identify's ``row_scale``, docs/physics.md §12.3)."""
    return float(info["t_widening"]) * math.sqrt(float(info["discrepancy"]))


def noise_summary(data: dict) -> str:
    """One line on the noise model a fit used, from its ``extra`` (or a posterior's ``meta["data"]``): where σ
    started, the scale estimated from the residual and its ν, and the intervals' widening (t and √κ)."""
    source = str(data.get("sigma_source", ""))
    scale = float(data.get("noise_scale", 1.0))
    dof = float(data.get("noise_dof", math.inf))
    t, kappa = float(data.get("t_widening", 1.0)), 1.0 + float(data.get("discrepancy", 0.0))
    if data.get("noise", "estimated") == "fixed":
        return f"{source}{f' × {scale:.3g}' if scale != 1.0 else ''} (taken as known)"
    held = "stated σ holds" if math.isinf(dof) else f"× {scale:.3g} estimated from the residual (ν = {dof:.1f})"
    return (f"{source}, {held}; intervals × {t * math.sqrt(kappa):.3g} (Student's t {t:.3g}, model discrepancy "
            f"√κ {math.sqrt(kappa):.3g})")


__all__ = ["noise_passes", "FrequencyData", "frequency_data", "hat_diagonal", "block_scale", "t_widening", "fit_free_block",
           "frequency_folds", "discrepancy_ratio", "row_widening", "noise_summary", "check_noise",
           "DEFAULT_RELATIVE_STD", "SIGMA_FLOOR_REL", "SCALE_PASSES", "SCALE_TOLERANCE", "Z95", "NOISE_MODELS",
           "NoiseModel", "DISCREPANCY_FOLDS", "FOLD_LEVERAGE_MAX"]
