"""Top level of the gap diagnosis: :func:`diagnose` a case folder, write the JSON of docs/formats.md §5.

Flow for each kind of data in the folder (mode tables, rolling profiles):
baseline fit → held-out baseline → where (:mod:`~ringfit.gap.localisation`)
→ is the held-out residual above the noise? (:func:`~ringfit.gap.verdict.residual_test`;
if not: verdict ``none``, candidates listed with their screen figures only,
no refits) → screen (:mod:`~ringfit.gap.screening`) → refit each candidate
that passes it and its held-out evidence (:mod:`~ringfit.gap.ranking`) →
acceptance, verdict and greedy chain (:mod:`~ringfit.gap.verdict`). Every
rule and threshold is written into the JSON under ``verdict.rule``.

A folder with both profiles and test mode tables is diagnosed per kind; the
top-level ``baseline``/``where``/``candidates`` are those of the part with
the larger standardised residual and every part is under ``parts``; the
verdict lists the effects accepted in any part, then ``unexplained`` if any
part left a structured residual.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.linalg

from ringfit.gap import effects as effect_library
from ringfit.gap.localisation import localise
from ringfit.gap.problem import GapProblem
from ringfit.fit.result import FitResult
from ringfit.gap.modal import OUTLIER_Z
from ringfit.gap.calibration import ALPHA, DRAWS, parametric_null, random_line_null, verdict_sentence
from ringfit.gap.ranking import (COMPUTED, JOIN, baseline_movement, chain_start, drift, effect_of, fit_chain,
                                 heldout, parts, prior_distance, reference_drift, rms, shrink, shrink_interval,
                                 theta_names)
from ringfit.gap.screening import SCREEN_MIN_SCORE, nonlinear_screen, objective, screen
from ringfit.gap.verdict import (P_NOISE, P_TRY_DAMPING, PREFER_COMPUTED_PTS, RULES, acceptance, null_decides,
                                 residual_test)
from ringfit.units import Z95


@dataclass
class PartResult:
    """Everything computed for one kind of data (kept for the report)."""

    problem: GapProblem
    baseline: FitResult
    reference: FitResult
    fits: dict = field(default_factory=dict)  # chain tuple -> FitResult (extra: pred, heldout_pred)
    summary: dict = field(default_factory=dict)  # the JSON of this part
    chain_fit: FitResult | None = None


@dataclass
class Diagnosis:
    """Result of :func:`diagnose`: ``content`` is the docs/formats.md §5 dict, ``parts`` the internals."""

    content: dict
    parts: list[PartResult]
    folder: Path | None = None

    @property
    def verdict(self) -> dict:
        return self.content["verdict"]

    def to_json(self) -> str:
        """The diagnosis as JSON text (what :meth:`write` saves, docs/formats.md §5)."""
        return json.dumps(self.content, indent=1, default=_json_default)

    def write(self, path: str | os.PathLike, *, overwrite: bool = False, inputs=()) -> Path:
        """Write the diagnosis JSON (atomically; refuses to overwrite unless ``overwrite``)."""
        from ringfit.io.files import atomic_write_text, check_output_path

        path = check_output_path(path, overwrite=overwrite, inputs=inputs)
        return atomic_write_text(path, self.to_json() + "\n")


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"cannot write {type(x).__name__} to JSON")


def _r(x, nd=4):
    x = float(x)
    return round(x, nd) if math.isfinite(x) else None


def read_diagnosis(path: str | os.PathLike) -> dict:
    """Load a ``*.diagnosis.json`` and check the docs/formats.md §5 keys; returns the dict."""
    from ringfit.errors import InputError

    try:
        d = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(f"not readable JSON ({exc})", source=path) from None
    for key in ("data", "baseline", "where", "candidates", "verdict"):
        if key not in d:
            raise InputError(f"missing key {key!r} (docs/formats.md §5)", source=path)
    if "effect" not in d["verdict"] or "effects" not in d["verdict"]:
        raise InputError("verdict needs 'effect' and 'effects' (docs/formats.md §5)", source=path)
    return d


# --------------------------------------------------------------------------- one part
def candidate_elements(problem: GapProblem) -> list[str]:
    """The candidates of a problem: each effect fitted, and also computed where its condition fixes it; where
    effects only act together on some rows (the rolling model's ``ground_contact`` and ``rotation`` on rolling
    tables, docs/physics.md §3.7) also their composite, computed and fitted, as one candidate."""
    out = []
    for e in problem.effects:
        if e.computable(problem.domain) and problem.domain in ("modes", "damping"):
            out.append(e.name + COMPUTED)
        out.append(e.name)
    if problem.domain == "modes" and getattr(problem.predictor, "joint", None) is not None:
        from ringfit.gap.rolling_rows import JOINT

        out += [JOIN.join(n + COMPUTED for n in JOINT), JOIN.join(JOINT)]
    return out


def computed_of(element: str) -> str:
    """The computed sibling of a fitted candidate (``"a+b"`` → ``"a@computed+b@computed"``)."""
    return JOIN.join(p.removesuffix(COMPUTED) + COMPUTED for p in parts(element))


def _variant(element: str) -> str:
    return "computed" if all(p.endswith(COMPUTED) for p in parts(element)) else "fitted"


def _candidate_entry(problem: GapProblem, element: str, fit: FitResult, current: FitResult, current_ho: np.ndarray,
                     reference: FitResult, scores: dict, on_top_of: tuple, group: str | None = None) -> dict:
    y = problem.y
    rb, rc = y - current.extra["pred"], y - fit.extra["pred"]
    hb, hc = y - current_ho, y - fit.extra["heldout_pred"]
    rms_c, hrms_c = rms(problem, rc), rms(problem, hc)
    lo, hi = shrink_interval(problem, hb, hc)
    m = problem.m
    dk = len(fit.names) - len(current.names)
    dchi2 = fit.chi2 - current.chi2
    params = {}
    names = theta_names(problem)
    partners: set = set()
    for piece in parts(element):
        name = effect_of(piece)
        sl = problem.slices()[name]
        effect = next(e for e in problem.effects if e.name == name)
        partners |= set(effect.baseline_partners)
        computed = piece.endswith(COMPUTED)
        cond_sd = problem.meta.condition_sd.get(name, {})
        for p, i in zip(problem.effect_params(effect), range(sl.start, sl.stop)):
            v = fit.theta[i]
            se = float(cond_sd.get(p.name, 0.0)) if computed else fit.stderr[names[i]]
            plo, phi = v - Z95 * se, v + Z95 * se
            key = p.name if len(parts(element)) == 1 else f"{name}.{p.name}"
            a, b = p.physical_range
            params[key] = {"value": _r(v, 6), "lo": _r(max(plo, p.lo), 6), "hi": _r(min(phi, p.hi), 6),
                           "null": p.null, "unit": p.unit, "excludes_null": bool(abs(v - p.null) > Z95 * se),
                           "physical_range": [a, b],
                           **({"implausible": True} if not computed and not (a - 1e-12 <= v <= b + 1e-12) else {}),
                           **({"fixed_by": "the measured condition"} if computed else {}),
                           **_physical(problem, name, p.name, v, se)}
    partners = tuple(sorted(partners))
    d = drift(problem, fit, reference)
    guarded = set(problem.meta.prior_guarded)
    d2, kp = prior_distance(problem, fit.theta, partners)
    d2_ref, _ = prior_distance(problem, reference.theta, partners)
    ref_drift = reference_drift(problem, fit, reference)
    entry = {
        "effect": effect_of(element),
        "element": element,
        "variant": _variant(element),
        **({"condition": problem.meta.conditions} if _variant(element) == "computed"
           and problem.meta.conditions else {}),
        "rms": _r(rms_c), "heldout_rms": _r(hrms_c),
        "shrink_pct": _r(shrink(problem, rb, rc), 2),
        "heldout_shrink_pct": _r(shrink(problem, hb, hc, heldout=True), 2),
        "heldout_shrink_interval_pct": [_r(lo, 2), _r(hi, 2)],
        **({"heldout_refits": fit.extra["heldout_refits"]} if "heldout_refits" in fit.extra else {}),
        **_group_shrink(problem, group, hb, hc),
        "rows": _deciding_rows(problem, group),
        "evidence": {"delta_bic": _r(dchi2 + dk * math.log(m), 2), "delta_chi2": _r(dchi2, 2),
                     "free_parameters_added": dk,
                     "screen_score": _r(scores.get(element, {}).get("score", math.nan), 3),
                     "alignment": _r(scores.get(element, {}).get("alignment", math.nan), 4),
                     **_screen_kind(scores.get(element, {}))},
        "params": params,
        "baseline_drift_sigma": {k: _r(v, 2) for k, v in d.items()},
        "baseline_drift_max_sigma": _r(max((abs(v) for v in d.values()), default=0.0), 2),
        "baseline_drift_relative": {k: _r(fit.theta[i] / reference.theta[i] - 1.0, 4)
                                    for i, k in enumerate(problem.base) if not problem.is_linear(i)},
        "baseline_drift_max_relative": _r(max((abs(fit.theta[i] / reference.theta[i] - 1.0)
                                               for i, k in enumerate(problem.base)
                                               if k.split(":")[0] not in partners
                                               and not problem.is_linear(i)
                                               and i not in guarded), default=0.0), 4),
        **({"reference_drift_sigma": _r(ref_drift, 3)} if ref_drift is not None else {}),
        **({"baseline_prior_distance": {"d2": _r(d2, 2), "d2_baseline_fit": _r(d2_ref, 2), "k": kp,
                                        "parameters": [problem.base[i] for i in sorted(guarded)
                                                       if problem.base[i] not in partners]}}
           if kp else {}),
        "on_top_of": [effect_of(c) for c in on_top_of],
        "screened_out": False,
    }
    ok, why = acceptance(entry)
    entry["accepted"] = ok
    if why:
        entry["rejected_because"] = why
    return entry


def _deciding_rows(problem: GapProblem, group) -> int:
    """Rows of the group that decided the structure test (all rows when there is one group)."""
    groups = np.asarray(problem.labels["group"])
    return int(np.sum(groups == group)) if group is not None and len(set(groups.tolist())) > 1 else problem.m


def _group_shrink(problem: GapProblem, group, hb: np.ndarray, hc: np.ndarray) -> dict:
    """Held-out shrink and its interval on the rows of ``group`` (the residual group that decided the
    structure test), ``{}`` when the problem has a single group."""
    groups = np.asarray(problem.labels["group"])
    if group is None or len(set(groups.tolist())) < 2:
        return {}
    sel = groups == group
    lo, hi = shrink_interval(problem, hb, hc, mask=sel)
    return {"group": str(group), "heldout_shrink_in_group_pct": _r(shrink(problem, hb, hc, sel, heldout=True), 2),
            "heldout_shrink_in_group_interval_pct": [_r(lo, 2), _r(hi, 2)]}


def _physical(problem: GapProblem, effect: str, param: str, value: float, se: float) -> dict:
    """An effect parameter in physical units per table (docs/formats.md §5 ``physical``): the contact patch's
    half-angle [deg] and length [mm] for ``ground_contact.patch_scale``, the wheel speed Ω [rad/s] the modes
    see for ``rotation.speed_gain``; ``{}`` for other parameters."""
    tables = problem.meta.table_names
    if not tables:
        return {}
    if (effect, param) == ("ground_contact", "patch_scale"):
        radius = problem.meta.outer_radius_m
        out = {}
        for t, (a, _) in zip(tables, problem.meta.patches):
            if a > 0:
                ang = value * a
                out[t] = {"half_angle_deg": _r(math.degrees(ang), 3), "half_angle_sd_deg": _r(math.degrees(se * a), 3),
                          "length_mm": _r(2000.0 * radius * math.sin(ang), 2)}
        return {"physical": out} if out else {}
    if (effect, param) == ("rotation", "speed_gain"):
        out = {t: {"omega_rad_s": _r(value * w, 4), "omega_sd_rad_s": _r(se * w, 4)}
               for t, w in zip(tables, problem.meta.spins) if w > 0}
        return {"physical": out} if out else {}
    return {}


def _screened_entry(problem, element, current, current_ho, scores, on_top_of, reason=None):
    y = problem.y
    r, h = rms(problem, y - current.extra["pred"]), rms(problem, y - current_ho)
    min_frac = float(problem.meta.screen_min_fraction)
    reason = reason or (f"screen score < {SCREEN_MIN_SCORE} or alignment^2 < {min_frac:g}: "
                        "the residual does not look like this effect")
    return {"effect": effect_of(element), "element": element, "variant": _variant(element), "rms": _r(r),
            "heldout_rms": _r(h),
            "shrink_pct": 0.0, "heldout_shrink_pct": 0.0, "heldout_shrink_interval_pct": [0.0, 0.0],
            "evidence": {"delta_bic": 0.0, "screen_score": _r(scores.get(element, {}).get("score", 0.0), 3),
                         "alignment": _r(scores.get(element, {}).get("alignment", 0.0), 4),
                         **_screen_kind(scores.get(element, {}))},
            "params": {}, "on_top_of": [effect_of(c) for c in on_top_of], "screened_out": True, "accepted": False,
            "rejected_because": [reason]}


def _movement_json(moved: dict) -> dict:
    """``baseline.drift`` of docs/formats.md §5 from :func:`ringfit.gap.ranking.baseline_movement`."""
    out = {"against": moved["against"], "max_abs_sigma": _r(moved["max_abs_sigma"], 2),
           "parameters": {k: {"reference": _r(v["reference"], 6), "value": _r(v["value"], 6),
                              "sigma": _r(v["sigma"], 2), "pct": _r(v["pct"], 1)}
                          for k, v in moved["parameters"].items()}}
    if "prior_distance" in moved:
        pd = moved["prior_distance"]
        out["prior_distance"] = {"d2": _r(pd["d2"], 2), "k": pd["k"], "limit": _r(pd["limit"], 2),
                                 "outside": pd["outside"]}
        out["sentence"] = _movement_sentence(moved)
    return out


def _movement_sentence(moved: dict) -> str:
    """One line on how far the baseline moved from its prior (the worst three parameters)."""
    pd = moved["prior_distance"]
    worst = sorted(moved["parameters"].items(), key=lambda kv: -abs(kv[1]["sigma"]))[:3]
    each = ", ".join(f"{k} {v['pct']:+.0f} % ({v['sigma']:+.1f} sigma)" for k, v in worst)
    if not pd["outside"]:
        return f"the baseline stayed inside its prior (D^2 {pd['d2']:.1f} <= {pd['limit']:.1f}; {each})"
    return (f"the baseline fit left its prior (D^2 {pd['d2']:.1f} > {pd['limit']:.1f}, the 99.9 % region; "
            f"{each}): it may be absorbing an unmodelled effect; where candidates are refitted, each is also "
            "refitted from the reference baseline (nonlinear screen)")


def _screen_kind(score: dict) -> dict:
    """``{"screen": "nonlinear", "linearised_screen_score": …}`` for a candidate screened by its refit from the
    reference baseline (the baseline had left its prior), ``{}`` for the linearised screen."""
    if score.get("screen") != "nonlinear":
        return {}
    lin = score.get("linearised", {})
    return {"screen": "nonlinear", "linearised_screen_score": _r(lin.get("score", math.nan), 3),
            "linearised_alignment": _r(lin.get("alignment", math.nan), 4)}


def _screened_out(problem: GapProblem, score: dict) -> bool:
    """The screen's verdict on one candidate (see :mod:`ringfit.gap.screening`)."""
    min_frac = float(problem.meta.screen_min_fraction)
    return score.get("score", 0.0) < SCREEN_MIN_SCORE or score.get("alignment", 0.0) ** 2 < min_frac


def _structure(problem: GapProblem, heldout_pred: np.ndarray) -> dict:
    """:func:`~ringfit.gap.verdict.residual_test` of the held-out residual (noise series from ``problem.meta``)."""
    return residual_test(problem.standardised(problem.y - heldout_pred, heldout=True), problem.labels["group"],
                         problem.labels.get("series"), problem.meta.series_dof,
                         p_try=P_TRY_DAMPING if problem.domain == "damping" else P_NOISE)


def _row_names(problem: GapProblem) -> list[str]:
    lab = problem.labels
    return list(lab.get("label", [])) if problem.domain != "profiles" else []


def _rows_table(problem: GapProblem, base_ho: np.ndarray, final_ho: np.ndarray) -> list[dict]:
    """Per row of a mode-table problem: measured, baseline and final held-out predictions, σ, z, outlier flag."""
    if problem.domain == "profiles":
        return []
    lab = problem.labels
    sigma = problem.sigma_heldout if problem.sigma_heldout is not None else problem.sigma
    zb = (problem.y - base_ho) / sigma
    zf = (problem.y - final_ho) / sigma
    matched = lab.get("matched", {})
    rolling = lab.get("rolling", {})  # rows of rolling tables: their branch of the rolling model (modal.py)
    out = []
    for i in range(problem.m):
        out.append({"row": lab["label"][i], "short": lab["short"][i], "measured": _r(problem.y[i], 5),
                    "baseline": _r(base_ho[i], 5), "with_effects": _r(final_ho[i], 5), "sigma": _r(sigma[i], 4),
                    "z_baseline": _r(zb[i], 2), "z_with_effects": _r(zf[i], 2),
                    "outlier": bool(abs(zf[i]) > OUTLIER_Z),
                    **({"model_mode": lab["model_mode"][i]} if "model_mode" in lab else {}),
                    **({"match": matched[lab["label"][i]]} if lab["label"][i] in matched else {}),
                    **({"rolling_match": rolling[lab["label"][i]]} if lab["label"][i] in rolling else {})})
    return out


def _prefer_computed(problem, part, chain, current, current_ho, elements, ss_b):
    """Replace fitted elements of the final chain by their computed variants where the held-out data cannot
    tell them apart (:data:`ringfit.gap.verdict.PREFER_COMPUTED_PTS`); all at once first, then one at a time.

    **Returns:** ``(chain, fit, held-out prediction, note or None)``.
    """
    effects = tuple(c for c in chain if c != "unexplained")
    singles = {p for el in elements for p in parts(el)}
    swappable = [i for i, c in enumerate(effects) if not c.endswith(COMPUTED) and c + COMPUTED in singles]
    if not swappable or ss_b <= 0:
        return chain, current, current_ho, None
    y = problem.y
    ss_cur = float(np.sum(problem.standardised(y - current_ho, heldout=True) ** 2))
    structured = _structure(problem, current_ho)["structured"]
    trials = [tuple(c + COMPUTED if i in swappable else c for i, c in enumerate(effects))]
    if len(swappable) > 1:
        trials += [tuple(c + COMPUTED if i == j else c for i, c in enumerate(effects)) for j in swappable]
    for alt in trials:
        fit = part.fits.get(alt)
        if fit is None:
            fit = fit_chain(problem, alt, start=chain_start(problem, alt, current.theta))
            heldout(problem, fit)
            part.fits[alt] = fit
        if not fit.converged:
            continue
        ho = fit.extra["heldout_pred"]
        ss_alt = float(np.sum(problem.standardised(y - ho, heldout=True) ** 2))
        lost = 100.0 * (ss_alt - ss_cur) / ss_b
        if lost <= PREFER_COMPUTED_PTS and (structured or not _structure(problem, ho)["structured"]):
            tail = ("unexplained",) if chain[-1:] == ("unexplained",) else ()
            swapped = [effect_of(c) for c, a in zip(effects, alt) if c != a]
            note = (f"{', '.join(swapped)}: the computed variant (no free parameter) replaces the fitted one; "
                    f"held-out shrink {100 * (1 - ss_alt / ss_b):.2f} % against {100 * (1 - ss_cur / ss_b):.2f} % "
                    f"(the rule allows {PREFER_COMPUTED_PTS:g} points)")
            return alt + tail, fit, ho, note
    return chain, current, current_ho, None


def _calibrate(problem, part, chain, current, remaining, entries, alpha, draws, round_no):
    """Test the round's accepted candidates against the nulls of :mod:`ringfit.gap.calibration` (in place: an
    entry gets ``p_value``, ``null`` and ``null_sentence``; one that does not beat them at ``alpha`` is no longer
    accepted). Every candidate of the round enters the null's selection, screened-out ones refitted for it."""
    t0, c0 = time.perf_counter(), time.process_time()
    elements = []
    for el in remaining:
        key = chain + parts(el)
        if key not in part.fits:
            fit = fit_chain(problem, key, start=chain_start(problem, parts(el), current.theta))
            if not fit.converged:
                continue
            part.fits[key] = fit
        elements.append(el)
    nulls = [parametric_null(problem, current, part.fits, chain, elements, draws, seed=round_no)]
    if problem.domain == "modes":
        rl = random_line_null(problem, part.fits, chain, elements, draws, seed=100 + round_no)
        if rl is not None:
            nulls.append(rl)
    # where the null decides instead of a bar, it must carry what the parametric draws idealise: for profiles the
    # rig's nuisances (gain drift over the session, angle jitter; the baseline and every refit fit them per run),
    # for mode tables the rows' own noise distribution (resampled residuals: heavy tails, a σ stated too small);
    # docs/physics.md §6.4: a third null
    rig = None
    if any(null_decides(c) for c in entries):
        rig = parametric_null(problem, current, part.fits, chain, elements, draws, seed=200 + round_no, nuisances=True)
    timing = {"wall_s": round(time.perf_counter() - t0, 3), "cpu_s": round(time.process_time() - c0, 3)}

    def name(n):
        return ("random_line" if n.kind.startswith("random-line") else
                ("parametric_rig_nuisances" if problem.domain == "profiles" else "parametric_resampled") if n is rig
                else "parametric")

    for c in entries:
        pending = null_decides(c)
        if not (c["accepted"] or pending) or c["element"] not in elements:
            continue
        el = c["element"]
        c["null_elapsed"] = timing
        mine = nulls + ([rig] if pending and rig is not None else [])
        # the binding null: the larger p; on a tie (both at their floor 1/(N+1)) the stricter one, whose
        # 95 % quantile is higher, so the sentence quotes the null that would have refused first
        worst = max(mine, key=lambda n: (n.p[el], n.summary(el)["q95_pct"]))
        c["p_value"] = round(worst.p[el], 5)
        c["null"] = {name(n): n.summary(el) for n in mine}
        c["null_sentence"] = verdict_sentence(c["effect"], worst, el, alpha)
        c["null_draws"] = {name(n): n.t_null.tolist() for n in mine}
        if not worst.p[el] < alpha:
            c["accepted"] = False
            c.setdefault("rejected_because", []).append(
                f"does not beat chance: p = {worst.p[el]:.3g} >= alpha {alpha:g} ({worst.kind.split(':')[0]} null)")
        elif pending:  # the calibrated null decides where only the heuristic bars of condition 1 refused
            c["accepted"] = True
            c["null_overruled"] = c.pop("rejected_because")
            c["null_sentence"] += (" — the null test decides instead of the fixed shrink bar or its bootstrap bound "
                                   "(verdict.null_decides)")


def _nearest(rounds, chain) -> dict:
    """An ``unexplained`` verdict's nearest candidate (docs/formats.md §5 ``verdict.nearest``): the refitted candidate
    of the last round with the largest held-out shrink, and why it was refused; ``{}`` otherwise."""
    if chain[-1:] != ("unexplained",) or not rounds:
        return {}
    tried = [c for c in rounds[-1] if not c.get("screened_out") and c.get("heldout_shrink_pct") is not None]
    if not tried:
        return {}
    c = max(tried, key=lambda c: c["heldout_shrink_pct"])
    return {"effect": c["effect"], "element": c["element"], "heldout_shrink_pct": c["heldout_shrink_pct"],
            "rejected_because": c.get("rejected_because", [])}


def _labels_evidence(problem, part, rounds, alpha, draws) -> dict:
    """``verdict.labels`` (docs/formats.md §5): per rolling table the labels the assignment kept and overrode, the
    label-permutation test of the first round's best refitted candidate
    (:func:`ringfit.gap.calibration.label_permutation_test`) and a sentence; ``{}`` without rolling tables.
    ``rests_on``: the clause an accepted verdict's sentence gets when its rows' labels were overridden."""
    counts = problem.meta.label_counts
    if problem.domain != "modes" or not counts:
        return {}
    labelled = sum(v["labelled"] for v in counts.values())
    over = sum(v["overridden"] for v in counts.values())
    out = {"tables": counts, "labelled": labelled, "kept": labelled - over, "overridden": over}
    if labelled and draws > 0:
        from ringfit.gap.calibration import label_permutation_test

        perm = label_permutation_test(problem, draws)
        if perm is not None:
            out["permutation"] = perm
    perm = out.get("permutation")
    said = f"the assignment kept {labelled - over} of {labelled} labels of the rolling tables and overrode {over}"
    if perm is not None:
        agree = perm["p_value"] < alpha
        said += (f"; label permutation: shuffled labels keep {perm['null_kept_median']:g} (median), these keep "
                 f"{perm['observed_kept']}: p = {perm['p_value']:.3g} over {perm['draws']} shuffles — "
                 + ("the labels carry information the model agrees with" if agree else
                    "inconclusive: the labels carry no information the model agrees with"))
    out["sentence"] = said
    if over:
        out["rests_on"] = (f"; it rests on rows whose labels the assignment overrode ({over} of {labelled} labels)"
                           + ("" if perm is None or perm["p_value"] < alpha else
                              ", and shuffled labels fit as well (the labels carry no information the model agrees "
                              "with)"))
    return out


def _computed_first(problem, part, chain, accepted, entries, alpha) -> str:
    """The element the round adds: the best accepted, except that a fitted variant gives way to its accepted
    computed sibling unless its likelihood-ratio test against it beats alpha (the entry says so)."""
    from scipy.special import chdtrc  # χ² upper tail (scipy.stats costs ~0.5 s to import)

    best = accepted[0]
    el = best["element"]
    if best["variant"] != "fitted":
        return el
    sib = computed_of(el)
    sib_entry = next((c for c in entries if c.get("element") == sib), None)
    f_fit, f_sib = part.fits.get(chain + parts(el)), part.fits.get(chain + parts(sib))
    if sib_entry is None or f_fit is None or f_sib is None:
        return el
    k = max(len(f_fit.names) - len(f_sib.names), 1)
    dchi2 = max(float(f_sib.extra.get("chi2_raw", f_sib.chi2)) - float(f_fit.extra.get("chi2_raw", f_fit.chi2)), 0.0)
    p = float(chdtrc(k, dchi2))
    best["computed_vs_fitted"] = {"delta_chi2": _r(dchi2, 3), "free_parameters": k, "p_value": _r(p, 5),
                                  "fitted_kept": bool(p < alpha or not sib_entry["accepted"])}
    if p < alpha or not sib_entry["accepted"]:
        return el
    return sib


def diagnose_problem(problem: GapProblem, progress: bool = True, alpha: float = ALPHA,
                     null_draws: int = DRAWS) -> PartResult:
    """Run baseline, where, screen, candidates, their nulls and the greedy chain on one problem.

    ``alpha``: an accepted candidate must beat the null of its round at this level
    (:mod:`ringfit.gap.calibration`; ``null_draws`` draws per null; 0 turns the nulls off).
    """
    t0 = time.perf_counter()
    base = fit_chain(problem, ())
    extrapolates = problem.domain in ("modes", "damping")
    base_ho = heldout(problem, base, variance=extrapolates)
    if extrapolates:  # one σ for every held-out statistic: noise and the baseline's held-out prediction variance
        problem.sigma_heldout = np.sqrt(problem.sigma**2 + base.extra["heldout_var"])
    ref_mask = problem.meta.reference_mask
    reference = fit_chain(problem, (), train=ref_mask) if ref_mask is not None and not np.all(ref_mask) else base
    part = PartResult(problem, base, reference)
    part.fits[()] = base
    test = _structure(problem, base_ho)
    elements = candidate_elements(problem)
    scores = screen(problem, base, elements=elements)
    moved = baseline_movement(problem, base, reference)
    rescued = {}
    if moved is not None and moved.get("prior_distance", {}).get("outside"):
        import warnings

        warnings.warn(f"{problem.domain}: {_movement_sentence(moved)}", stacklevel=2)
        if test["excess"]:  # (below it no candidate is refitted: the screen's figures are all there is)
            # the baseline left its prior: it may have absorbed the effect, so the linearised screen at it is not
            # trusted — every candidate is also refitted from the reference baseline (screening.nonlinear_screen)
            for element, nl in nonlinear_screen(problem, base, elements).items():
                rescued[element] = nl.pop("fit")
                if nl["score"] > scores.get(element, {}).get("score", 0.0):
                    scores[element] = {**nl, "linearised": scores.get(element, {})}
    y = problem.y
    noise_rms = float(np.sqrt(np.mean((problem.sigma * problem.scale) ** 2)))
    hrms_b = rms(problem, y - base_ho)
    ss_b = float(np.sum(problem.standardised(y - base_ho, heldout=True) ** 2))
    loc = localise(problem, y - base.extra["pred"])

    bar = _progress(problem, progress, len(elements))
    current, current_ho, chain, rounds = base, base_ho, (), []
    remaining = list(elements)
    cur = test
    rescreen = float(problem.meta.screen_min_fraction) > 0
    while True:
        entries = []
        round_scores = scores if not chain else (screen(problem, current, elements=remaining) if rescreen else {})
        for element in remaining:
            if bar is not None:
                bar.set_description(f"{problem.domain}: {'+'.join(chain + (element,))}")
            if not test["excess"]:  # nothing to explain: the screen's figures are all there is to report
                entries.append(_screened_entry(problem, element, current, current_ho, round_scores, chain,
                                               "not refitted: the baseline residual is at the noise level"))
            elif (not chain or rescreen) and _screened_out(problem, round_scores.get(element, {})):
                entries.append(_screened_entry(problem, element, current, current_ho, round_scores, chain))
            else:
                start = chain_start(problem, parts(element), current.theta)
                fit = fit_chain(problem, chain + parts(element), start=start)
                if not chain and element in rescued:  # the better refit: from the moved or the reference baseline
                    alt = rescued[element]
                    if alt.converged and (not fit.converged or objective(problem, alt) < objective(problem, fit)):
                        fit = alt
                heldout(problem, fit)
                part.fits[chain + parts(element)] = fit
                entries.append(_candidate_entry(problem, element, fit, current, current_ho, reference, round_scores,
                                                chain, cur["group"]))
            if bar is not None:
                bar.update(1)
        entries.sort(key=lambda c: (-(c["heldout_shrink_pct"] if c["heldout_shrink_pct"] is not None else -1e9),
                                    c.get("variant") != "computed"))
        rounds.append(entries)
        if not cur["excess"]:
            break
        if any(c["accepted"] or null_decides(c) for c in entries) and null_draws > 0:
            if bar is not None:  # the longest step of a diagnosis: say so while it runs
                bar.set_description(f"{problem.domain}: round {len(rounds)}: {null_draws} null draws")
            _calibrate(problem, part, chain, current, remaining, entries, alpha, null_draws, len(rounds))
        accepted = [c for c in entries if c["accepted"]]
        if not accepted:
            # `none` only when the residual is noise: a residual that fails the noise test with nothing to explain
            # it is `unexplained` (once an effect was found, the structured level decides whether a gap remains)
            if cur["structured"] or (not chain and cur["material"]):
                chain = chain + ("unexplained",)
            break
        best = _computed_first(problem, part, chain, accepted, entries, alpha)
        chain = chain + parts(best)
        current = part.fits[chain]
        current_ho = current.extra["heldout_pred"]
        taken = set(effect_of(best).split(JOIN))
        remaining = [e for e in remaining if not taken & set(effect_of(e).split(JOIN))]
        cur = _structure(problem, current_ho)
        if not remaining or not cur["excess"]:
            if cur["structured"]:
                chain = chain + ("unexplained",)
            break
    if bar is not None:
        bar.close()
    chain, current, current_ho, simplified = _prefer_computed(problem, part, chain, current, current_ho, elements,
                                                              ss_b)
    if simplified:
        cur = _structure(problem, current_ho)
    part.chain_fit = current
    effects_list = [effect_of(c) for c in chain] or ["none"]
    labels = _labels_evidence(problem, part, rounds, alpha, null_draws)
    calibrated = [{"effect": c["effect"], "variant": c["variant"], "p_value": c["p_value"],
                   "sentence": c.get("null_sentence", "") + (labels.get("rests_on", "") if labels else "")}
                  for r in rounds for c in r if c.get("accepted") and "p_value" in c]
    ss_f = float(np.sum(problem.standardised(y - current_ho, heldout=True) ** 2))
    names = _row_names(problem)
    zb, zf = problem.standardised(y - base_ho, heldout=True), problem.standardised(y - current_ho, heldout=True)
    raw = (y - current_ho) / (problem.sigma_heldout if problem.sigma_heldout is not None else problem.sigma)
    explains = [names[i] for i in range(len(names)) if abs(zb[i]) > 2 and abs(zf[i]) <= 2]
    leaves = [names[i] for i in range(len(names)) if abs(zf[i]) > 2]
    outliers = [names[i] for i in range(len(names)) if abs(raw[i]) > OUTLIER_Z]
    nearest = _nearest(rounds, chain)
    verdict = {"effect": effects_list[0], "effects": effects_list,
               **({"nearest": nearest} if nearest else {}),
               "variants": [_variant(c) for c in chain if c != "unexplained"],
               **({"simplified": simplified} if simplified else {}),
               "alpha": alpha, "null_draws": int(null_draws), "calibration": calibrated,
               **({"labels": {k: v for k, v in labels.items() if k != "rests_on"}} if labels else {}),
               "heldout_shrink_pct": _r(100.0 * (1.0 - ss_f / ss_b), 2) if effects_list[0] not in
               ("none", "unexplained") and ss_b > 0 else 0.0,
               **({"explains": explains, "leaves": leaves, "outliers": outliers} if names else {}),
               "rule": {**RULES, "screen": (
                   f"a candidate is refitted only if its linearised score (chi2 it would remove) >= {SCREEN_MIN_SCORE}"
                   f" and alignment^2 >= {float(problem.meta.screen_min_fraction):g} of the residual"),
                   "shrink": ("100 (1 - SS_after/SS_before) over held-out rows, SS = sum of psi(residual/sigma)^2, "
                              "each residual weighted by its own noise sigma; psi = Huber on robust rows"),
                   "noise": problem.noise_method, "heldout": problem.fold_kind,
                   "calibration": (f"an accepted candidate must beat the null of its round at alpha = {alpha:g}: "
                                   f"p = (1 + #null >= observed)/(N + 1) over {null_draws} draws of the selection "
                                   "statistic (the best candidate's held-out shrink, linearised refits) under the "
                                   "parametric null and, for rows matched by frequency, the random-line null "
                                   "(docs/formats.md §5); a fitted variant replaces its computed sibling only when "
                                   f"its likelihood-ratio test beats it at alpha")}}
    part.summary = {
        "data": problem.data_files,
        "family": {"modes": "frequency", "damping": "damping", "profiles": "profile"}[problem.domain],
        "baseline": {"model": problem.baseline_model, "rms": _r(rms(problem, y - base.extra["pred"])),
                     "unit": problem.unit, "heldout_rms": _r(hrms_b), "noise_rms": _r(noise_rms),
                     **({"heldout_refits": base.extra["heldout_refits"]} if "heldout_refits" in base.extra else {}),
                     "ideal_shrink_pct": _r(100.0 * (1.0 - problem.m / ss_b), 2) if ss_b > problem.m else 0.0,
                     "reduced_chi2": _r(test["reduced_chi2"], 3), "noise_p_value": test["p"],
                     "noise_dof": _r(test["dof"], 1), "worst_group": test["group"],
                     "excess": test["excess"], "structured": test["structured"],
                     "reduced_chi2_in_sample": _r(float(np.mean(problem.standardised(y - base.extra["pred"]) ** 2)), 3),
                     "remaining_reduced_chi2": _r(cur["reduced_chi2"], 3), "remaining_structured": cur["structured"],
                     "noise_method": problem.noise_method, "heldout_method": problem.fold_kind,
                     "parameters": {k: _r(v, 6) for k, v in zip(problem.base, base.theta)},
                     **({"drift": _movement_json(moved)} if moved is not None else {}),
                     **({"reference_fit": problem.meta.reference_fit} if problem.meta.reference_fit is not None else {}),
                     **({"conditions": problem.meta.conditions} if problem.meta.conditions else {}),
                     **({"rolling_structure": problem.meta.rolling_structure}
                        if problem.meta.rolling_structure is not None else {}),
                     **({"sources": problem.meta.sources} if problem.meta.sources is not None else {})},
        "where": loc["where"],
        "where_detail": {k: v for k, v in loc.items() if k != "where"},
        "candidates": rounds[0],
        "chain": [{"added": effect_of(c), "variant": _variant(c), "candidates": r}
                  for c, r in zip(chain[:len(rounds) - 1], rounds[1:])],
        "not_applicable": problem.not_applicable,
        "verdict": verdict,
        **({"rows": _rows_table(problem, base_ho, current_ho)} if names else {}),
        "elapsed_s": round(time.perf_counter() - t0, 2),
    }
    return part


def _progress(problem, progress, total):
    if not progress:
        return None
    from tqdm.auto import tqdm

    return tqdm(total=total, file=sys.stderr, leave=False, unit="candidate")


# --------------------------------------------------------------------------- folder
def build_problems(case, effects, noise=None, baseline: bool = False) -> list[GapProblem]:
    """The problems of a case: mode-table frequencies and damping (:mod:`ringfit.gap.modal`) and profiles (if any).

    ``baseline``: ``case.tyre``'s ring is the baseline as it is (``diagnose --tyre``), not refitted to free.modes.csv.
    """
    from ringfit.gap.modal import build_modal_problems

    problems = build_modal_problems([case.free, *case.tables], case.tyre, effects, noise=noise, baseline=baseline)
    if case.profiles:
        from ringfit.gap.profile import build_profile_problem

        ring, sources, prior = _ring_from_free(problems, case.tyre)
        problems.append(build_profile_problem(case, ring, effects, noise=noise, sources=sources, ring_prior=prior))
    return problems


def _ring_from_free(modal_problems: list[GapProblem], tyre):
    """The ring for the profile baseline and its uncertainty, from the fits to ``free.modes.csv``.

    ρA, EI, k_w, k_v come from ``ringfit fit``'s fit (the frequency problem's reference
    fit), ζ from the free table's damping level when it has damping (else ``tyre.toml``),
    the k_trd start from ``tyre.toml``. The prior of the profile refit is the fit's Laplace
    posterior of log EI, log k_w, log k_v (σ inflated by √(χ²/dof) when > 1) and, for ζ,
    the damping level's standard error. Eq. 18 pins the stiffnesses only relative to the
    pressure term P(n²−1), which dominates for n ≥ 3, so EI is known to ~10–30 % from a free
    table while the profiles' bending-length features determine it far better.

    **Returns:** ``(ring, sources, prior)``; ``prior = {"names": (…), "cov": (k, k)}``.
    """
    from ringfit.gap.profile import RING_BASE, RING_PRIOR_SD_FALLBACK

    freq = modal_problems[0]
    fit = freq.meta.reference_result
    fitted = {k: float(fit.values[k]) for k in freq.base}
    sources = {k: "ringfit fit of free.modes.csv (eq. 18, physical EI prior)" for k in fitted}
    damping = next((p for p in modal_problems[1:] if p.domain == "damping" and 0 in p.meta.tables), None)
    names = [n for n in RING_BASE if n in fit.names]
    infl = max(1.0, fit.chi2 / max(fit.dof, 1))
    idx = [fit.names.index(n) for n in names]
    blocks = [fit.covariance_log[np.ix_(idx, idx)] * infl]
    if damping is not None:
        level = float(damping.base_values[0])
        sel = damping.labels["table"] == 0
        sd = float(np.median(damping.sigma[sel])) / math.sqrt(max(int(sel.sum()), 1))
        fitted["damping_ratio"] = level
        sources["damping_ratio"] = "median damping of free.modes.csv"
        names.append("damping_ratio")
        blocks.append(np.array([[sd**2]]))
    else:
        sources["damping_ratio"] = "tyre.toml [ring]" if "damping_ratio" in tyre.ring_values else "Table 9 default"
    sources["k_tread"] = ("tyre.toml [ring]" if "k_tread" in tyre.ring_values else "Table 9 default") + \
        " (start of the fit)"
    cov = scipy.linalg.block_diag(*blocks)
    if not np.all(np.isfinite(cov)) or np.any(np.diag(cov) <= 0):
        cov = np.eye(cov.shape[0]) * RING_PRIOR_SD_FALLBACK**2
    return tyre.ring.replace(**fitted), sources, {"names": tuple(names), "cov": cov}


def resolve_effects(effects=None):
    """Effect objects from names (``None`` = every registered effect)."""
    if effects is None:
        return tuple(effect_library.get(n) for n in effect_library.available())
    if isinstance(effects, str):
        effects = [e.strip() for e in effects.split(",") if e.strip()]
    return tuple(e if isinstance(e, effect_library.Effect) else effect_library.get(e) for e in effects)


def diagnose(folder, effects=None, progress: bool = True, noise: dict | None = None, alpha: float = ALPHA,
             null_draws: int = DRAWS, tyre=None) -> Diagnosis:
    """Diagnose the sim-to-real gap of a case folder (docs/formats.md §6) against the baselines of docs/physics.md §6.

    **Arguments:**

    - ``folder``: the case folder (or a :class:`~ringfit.gap.case.Case`).
    - ``effects``: candidate names (list or comma-separated string); ``None`` = all registered.
    - ``progress``: show a tqdm bar on stderr while candidates are fitted.
    - ``noise``: optional user noise levels, ``{"freq_hz": σ, "damping": σ, "profile_ms2": σ}``;
      default: estimated from the data (see :mod:`ringfit.gap.modal`, :mod:`ringfit.gap.profile`).
    - ``alpha``: significance level every accepted effect must beat its null at
      (:mod:`ringfit.gap.calibration`); ``null_draws``: draws per null (0: no null, not recommended).
    - ``tyre``: an identified or fitted :class:`~ringfit.io.tyre.Tyre` whose ring (and ``[ring.covariance]``)
      is the baseline as it is — one ring per tyre; default: the ring fitted to ``free.modes.csv``.

    **Returns:** :class:`Diagnosis` (``.content`` is the docs/formats.md §5 dict, ``.write(path)``).
    """
    from ringfit.gap.case import Case, read_case

    case = folder if isinstance(folder, Case) else read_case(folder)
    if tyre is not None:  # the given ring on the case's own geometry
        from ringfit.io.tyre import Tyre

        case.tyre = Tyre(case.tyre.geometry, dict(tyre.ring_values), dict(case.tyre.extra), tyre.source,
                         tyre.covariance)
    chosen = resolve_effects(effects)
    t0 = time.perf_counter()
    # one BLAS thread: every solve here is small (eigen-solves of ≤ 100 × 100, least squares of ≤ a few
    # thousand rows × ≤ 12 columns), where threaded BLAS only synchronises (50× slower on a busy machine)
    from ringfit._threads import small_matrix_threads

    parts_ = []
    with small_matrix_threads():
        problems = build_problems(case, chosen, noise, baseline=tyre is not None)
        for prob in problems:
            # the mode-table parts are only a test when the folder holds test tables or nothing else
            if prob.domain in ("modes", "damping") and case.profiles and not case.tables:
                continue
            parts_.append(diagnose_problem(prob, progress, alpha, null_draws))
    content = _combine(parts_)
    content["data"] = case.data_files
    if tyre is not None:
        content["baseline_tyre"] = str(tyre.source)
    content["elapsed_s"] = round(time.perf_counter() - t0, 2)
    return Diagnosis(content, parts_, getattr(case, "folder", None))


def _combine(parts: list[PartResult]) -> dict:
    """One docs/formats.md §5 dict from the parts: the structural parts (frequencies, profiles) decide the verdict;
    the damping part adds only the damping effects it accepts — its own unexplained residual is reported
    under ``verdict.damping``, never as a structural ``unexplained``."""
    structural = [p for p in parts if p.problem.domain != "damping"] or parts
    damping = [p for p in parts if p.problem.domain == "damping"]
    primary = max(structural, key=lambda p: p.summary["baseline"]["reduced_chi2"] or 0.0)
    if all(p.summary["verdict"]["effects"] == ["none"] for p in structural) and damping and \
            damping[0].summary["verdict"]["effects"][0] not in ("none", "unexplained"):
        primary = damping[0]  # the only finding is a damping effect: its figures lead
    out = dict(primary.summary)
    effects, unexplained = [], False
    for p in structural:
        for e in p.summary["verdict"]["effects"]:
            if e == "unexplained":
                unexplained = True
            elif e != "none" and e not in effects:
                effects.append(e)
    for p in damping:
        for e in p.summary["verdict"]["effects"]:
            if e not in ("none", "unexplained") and e not in effects:
                effects.append(e)
    if unexplained:
        effects.append("unexplained")
    effects = effects or ["none"]
    v = dict(primary.summary["verdict"])
    v.update(effect=effects[0], effects=effects)
    if damping:
        dv = damping[0].summary["verdict"]
        v["damping"] = {"effects": dv["effects"], "structured": damping[0].summary["baseline"]["structured"],
                        "note": ("damping residuals are judged on their own scale (ln of the damping ratio) and "
                                 "decide no structural verdict; only damping effects are tried on them"),
                        **{k: dv[k] for k in ("explains", "leaves", "outliers") if k in dv}}
    out["verdict"] = v
    if len(parts) > 1:
        out["parts"] = [p.summary for p in parts]
    return out
