"""The verdict rule of the gap diagnosis, one acceptance condition at a time, and the residual test's two levels.

Each test starts from a candidate that passes every condition and breaks exactly one: the rule must
reject it for that reason and no other (docs/formats.md §5, ringfit/gap/verdict.py).
"""

import math

import numpy as np
import pytest
from scipy.stats import chi2 as chi2_dist

from ringfit.gap import verdict as V


def good(**changes) -> dict:
    """A candidate (diagnosis JSON form) that meets every condition with a margin."""
    c = {
        "effect": "sensor_tilt",
        "heldout_shrink_pct": V.MIN_HELDOUT_SHRINK_PCT + 20.0,
        "heldout_shrink_interval_pct": [V.MIN_HELDOUT_SHRINK_LO_PCT + 10.0, 90.0],
        "evidence": {"delta_bic": V.MAX_DELTA_BIC - 50.0},
        "params": {"tilt_gain": {"value": 0.9, "excludes_null": True}},
        "baseline_drift_max_relative": 0.5 * V.MAX_DRIFT_RELATIVE,
    }
    c.update(changes)
    return c


def test_a_good_candidate_is_accepted():
    ok, why = V.acceptance(good())
    assert ok and why == []


def test_condition_1_heldout_shrink():
    ok, why = V.acceptance(good(heldout_shrink_pct=V.MIN_HELDOUT_SHRINK_PCT - 0.1))
    assert not ok and len(why) == 1 and "heldout shrink" in why[0] and "lower bound" not in why[0]


def test_condition_1_shrink_lower_bound():
    ok, why = V.acceptance(good(heldout_shrink_interval_pct=[V.MIN_HELDOUT_SHRINK_LO_PCT - 0.1, 80.0]))
    assert not ok and len(why) == 1 and "lower bound" in why[0]
    # few rows: the bootstrap interval of a ratio is reported, not used
    few = good(heldout_shrink_interval_pct=[-50.0, 80.0], rows=V.MIN_INTERVAL_ROWS - 1)
    assert V.acceptance(few) == (True, [])
    assert not V.acceptance(dict(few, rows=V.MIN_INTERVAL_ROWS))[0]


def test_condition_1_group_shrink_rescues_a_diluted_effect():
    """An effect that acts on one group only (e.g. the damping rows) passes on that group's shrink."""
    diluted = good(heldout_shrink_pct=5.0, heldout_shrink_interval_pct=[1.0, 9.0], group="damping",
                   heldout_shrink_in_group_pct=V.MIN_HELDOUT_SHRINK_PCT + 5.0,
                   heldout_shrink_in_group_interval_pct=[V.MIN_HELDOUT_SHRINK_LO_PCT + 1.0, 60.0])
    assert V.acceptance(diluted) == (True, [])
    weak = dict(diluted, heldout_shrink_in_group_pct=V.MIN_HELDOUT_SHRINK_PCT - 1.0)
    ok, why = V.acceptance(weak)
    assert not ok and "in damping" in why[0]


def test_condition_2_delta_bic():
    ok, why = V.acceptance(good(evidence={"delta_bic": V.MAX_DELTA_BIC + 0.1}))
    assert not ok and len(why) == 1 and "delta BIC" in why[0]


def test_condition_3_an_interval_must_exclude_the_null():
    ok, why = V.acceptance(good(params={"tilt_gain": {"value": 0.1, "excludes_null": False}}))
    assert not ok and len(why) == 1 and "null" in why[0]
    two = {"a": {"excludes_null": False}, "b": {"excludes_null": True}}
    assert V.acceptance(good(params=two))[0]  # one of several suffices


def test_condition_4_relative_drift_of_the_baseline():
    ok, why = V.acceptance(good(baseline_drift_max_relative=V.MAX_DRIFT_RELATIVE + 0.01))
    assert not ok and len(why) == 1 and "drifted" in why[0]


def test_condition_4_reference_state_drift_replaces_the_relative_one():
    """Mode tables judge drift by what it does to the free-table predictions, in σ, not by percentages."""
    big_relative = good(baseline_drift_max_relative=10.0, reference_drift_sigma=0.5 * V.MAX_REFERENCE_DRIFT_SIGMA)
    assert V.acceptance(big_relative) == (True, [])
    ok, why = V.acceptance(good(reference_drift_sigma=V.MAX_REFERENCE_DRIFT_SIGMA + 0.01))
    assert not ok and len(why) == 1 and "reference-state" in why[0]


def test_condition_4_independent_prior_region():
    k = 3
    limit = float(chi2_dist.ppf(V.PRIOR_REGION, k))
    inside = good(baseline_prior_distance={"d2": limit - 0.1, "d2_baseline_fit": 0.0, "k": k})
    assert V.acceptance(inside) == (True, [])
    outside = good(baseline_prior_distance={"d2": limit + 0.1, "d2_baseline_fit": 0.0, "k": k})
    ok, why = V.acceptance(outside)
    assert not ok and len(why) == 1 and "prior" in why[0]
    # no further out than the baseline-only fit: allowed
    assert V.acceptance(good(baseline_prior_distance={"d2": limit + 5, "d2_baseline_fit": limit + 6, "k": k}))[0]


def test_every_failure_is_reported_together():
    bad = good(heldout_shrink_pct=0.0, evidence={"delta_bic": 3.0}, params={"x": {"excludes_null": False}},
               baseline_drift_max_relative=1.0)
    ok, why = V.acceptance(bad)
    assert not ok and len(why) == 4


def test_residual_test_levels_on_white_noise_and_structure():
    rng = np.random.default_rng(0)
    groups = np.array(["a"] * 200 + ["b"] * 200)
    noise = V.residual_test(rng.standard_normal(400), groups)
    assert not noise["excess"] and not noise["structured"]
    z = rng.standard_normal(400)
    z[200:] *= math.sqrt(2.0)  # reduced chi2 ≈ 2 in group b: an excess, not yet structured
    excess = V.residual_test(z, groups)
    assert excess["group"] == "b" and excess["excess"] and not excess["structured"]
    z[200:] *= math.sqrt(2.5)  # ≈ 5: structured
    structured = V.residual_test(z, groups)
    assert structured["group"] == "b" and structured["structured"]


def test_one_row_cannot_make_a_residual_structured():
    z = np.zeros(9) + 0.5
    z[0] = 30.0  # one wild row (an n = 1 damping outlier, say)
    out = V.residual_test(z, np.zeros(9))
    assert out["excess"] and not out["structured"]
    z[1] = -30.0  # two rows: structure
    assert V.residual_test(z, np.zeros(9))["structured"]


def test_residual_test_effective_dof_of_coloured_noise():
    """A few effective degrees of freedom (red noise) make the same χ² far less significant."""
    z = np.full(100, math.sqrt(2.0))
    white = V.residual_test(z, np.zeros(100), series=np.zeros(100), series_dof={0: 100.0})
    red = V.residual_test(z, np.zeros(100), series=np.zeros(100), series_dof={0: 4.0})
    assert red["p"] > 100 * white["p"]
    assert white["excess"] and not red["excess"]


@pytest.mark.parametrize("shrink_rms, shrink_ss", [(10.0, 19.0), (5.0, 9.75)])
def test_thresholds_are_the_rms_thresholds_on_the_sum_of_squares(shrink_rms, shrink_ss):
    """1 − SS_after/SS_before = 1 − (RMS_after/RMS_before)²: the stated equivalence of the constants."""
    assert 100 * (1 - (1 - shrink_rms / 100) ** 2) == pytest.approx(shrink_ss)
    assert shrink_ss in (V.MIN_HELDOUT_SHRINK_PCT, V.MIN_HELDOUT_SHRINK_LO_PCT)


def test_a_computed_variant_replaces_the_fitted_one_only_when_the_heldout_data_cannot_tell():
    """End of the greedy chain (gap.diagnosis._prefer_computed): the swap costs at most
    PREFER_COMPUTED_PTS points of held-out shrink; a computed variant that predicts worse is not taken."""
    from types import SimpleNamespace

    from ringfit.gap.diagnosis import _prefer_computed
    from ringfit.gap.verdict import PREFER_COMPUTED_PTS

    m = 40
    y = np.zeros(m)
    problem = SimpleNamespace(y=y, standardised=lambda r, heldout=False: np.asarray(r),
                              sigma=np.ones(m))
    ss_b = 1000.0

    def fit_with(ss):  # a converged fit whose held-out residual has sum of squares ss
        return SimpleNamespace(converged=True, theta=np.zeros(1),
                               extra={"heldout_pred": np.full(m, -np.sqrt(ss / m))})

    import ringfit.gap.diagnosis as dg

    current = fit_with(20.0)
    for ss_alt, swapped in ((20.0 + 0.9 * PREFER_COMPUTED_PTS * ss_b / 100, True),
                            (20.0 + 1.1 * PREFER_COMPUTED_PTS * ss_b / 100, False)):
        part = SimpleNamespace(fits={("rotation@computed",): fit_with(ss_alt)})
        orig = dg._structure
        dg._structure = lambda problem, ho: {"structured": False}
        try:
            chain, fit, ho, note = _prefer_computed(problem, part, ("rotation",), current,
                                                    current.extra["heldout_pred"], ["rotation", "rotation@computed"],
                                                    ss_b)
        finally:
            dg._structure = orig
        assert (chain == ("rotation@computed",)) is swapped, (ss_alt, chain)
        assert (note is not None) is swapped


def test_prediction_jacobian_is_the_model_derivative_on_huber_rows(tmp_path):
    """predict_and_jacobian returns ∂pred/∂θ, not the Huber-weighted residual's derivative: checked against a
    central finite difference of predict on a damping problem whose rows are all robust, one far beyond c."""
    import shutil

    from ringfit.data import path as data_path
    from ringfit.gap.case import read_case
    from ringfit.gap.diagnosis import build_problems
    from ringfit.gap.effects import get
    from ringfit.gap.ranking import predict, predict_and_jacobian

    folder = tmp_path / "c"
    folder.mkdir()
    shutil.copy(data_path("table9.tyre.toml"), folder / "tyre.toml")
    for ext in ("csv", "json"):
        shutil.copy(data_path(f"free-ssi.modes.{ext}"), folder / f"free.modes.{ext}")
    damp = next(p for p in build_problems(read_case(folder), (get("wave_damping"),)) if p.domain == "damping")
    assert damp.robust.all() and damp.huber
    theta = damp.null_theta()
    j = 0  # the free table's damping level
    pred, J = predict_and_jacobian(damp, theta, [j])
    z = np.abs(pred - damp.y) / damp.sigma
    assert z.max() > 2 * damp.huber  # the n = 1 row's damping is far off the level
    h = 1e-6 * theta[j]
    up, down = theta.copy(), theta.copy()
    up[j] += h
    down[j] -= h
    fd = (predict(damp, up) - predict(damp, down)) / (2 * h)
    np.testing.assert_allclose(J[:, 0], fd, rtol=1e-5, atol=1e-8)


# --------------------------------------------------------------------------- the null decides the heuristic bars
def test_the_null_decides_a_shrink_between_the_floor_and_the_bar():
    """Condition 1's shrink bar is a heuristic: a candidate that passes every other condition with a shrink
    between the floor and the bar is refused by the rule alone but handed to its null (verdict.null_decides)."""
    c = good(heldout_shrink_pct=0.5 * (V.MIN_HELDOUT_SHRINK_FLOOR_PCT + V.MIN_HELDOUT_SHRINK_PCT))
    ok, why = V.acceptance(c)
    assert not ok and len(why) == 1 and "heldout shrink" in why[0]
    assert V.null_decides(dict(c, accepted=ok, rejected_because=why))
    assert V.acceptance(c, bars=False) == (True, [])
    # below the floor: not worth reporting, whatever the null says
    low = good(heldout_shrink_pct=V.MIN_HELDOUT_SHRINK_FLOOR_PCT - 0.1)
    ok, why = V.acceptance(low)
    assert not V.null_decides(dict(low, accepted=ok, rejected_because=why))
    assert "floor" in V.acceptance(low, bars=False)[1][0]
    # the floor reached on the deciding group only (an effect diluted over all rows)
    grp = good(heldout_shrink_pct=1.0, heldout_shrink_interval_pct=[-2.0, 4.0], group="tangential",
               heldout_shrink_in_group_pct=V.MIN_HELDOUT_SHRINK_FLOOR_PCT + 1.0,
               heldout_shrink_in_group_interval_pct=[0.0, 20.0])
    ok, why = V.acceptance(grp)
    assert not ok and V.null_decides(dict(grp, accepted=ok, rejected_because=why))


def test_the_null_decides_the_bootstrap_bound_but_never_a_physical_check():
    lb = good(heldout_shrink_interval_pct=[V.MIN_HELDOUT_SHRINK_LO_PCT - 5.0, 80.0])
    ok, why = V.acceptance(lb)
    assert not ok and V.null_decides(dict(lb, accepted=ok, rejected_because=why))
    mid = V.MIN_HELDOUT_SHRINK_FLOOR_PCT + 1.0
    for broken in ({"evidence": {"delta_bic": V.MAX_DELTA_BIC + 0.1}},
                   {"params": {"tilt_gain": {"value": 0.1, "excludes_null": False}}},
                   {"baseline_drift_max_relative": V.MAX_DRIFT_RELATIVE + 0.01},
                   {"reference_drift_sigma": V.MAX_REFERENCE_DRIFT_SIGMA + 0.01}):
        c = good(heldout_shrink_pct=mid, **broken)
        ok, why = V.acceptance(c)
        assert not ok and len(why) == 2
        assert not V.null_decides(dict(c, accepted=ok, rejected_because=why)), broken
    # a candidate the screen kept from being refitted has no evidence of its own
    assert not V.null_decides(good(heldout_shrink_pct=mid, screened_out=True, rejected_because=["screen"]))
    assert not V.null_decides(dict(good(), accepted=True))


def test_the_refit_gate_is_the_chi2_test_alone():
    """A residual 1.48 × the noise in the χ² over 340 effective dof (p ~ 1e-11) is an excess: no fixed bar on the
    reduced χ² refuses it; the same reduced χ² over 8 rows (p ~ 0.16) is not, except under the damping family's
    gate. The p the gate uses is scipy's χ² survival function."""
    from scipy.stats import chi2

    z = np.full(340, math.sqrt(1.48))
    out = V.residual_test(z, np.zeros(340))
    assert out["p"] == pytest.approx(chi2.sf(1.48 * 340, 340), rel=1e-9)
    assert out["excess"] and not out["structured"]
    few = V.residual_test(np.full(8, math.sqrt(1.48)), np.zeros(8))
    assert few["p"] == pytest.approx(chi2.sf(1.48 * 8, 8), rel=1e-9) and not few["excess"]
    assert V.residual_test(np.full(8, math.sqrt(1.48)), np.zeros(8), p_try=V.P_TRY_DAMPING)["excess"]
    # below its median the χ² never opens the damping gate
    assert not V.residual_test(np.full(8, 0.8), np.zeros(8), p_try=V.P_TRY_DAMPING)["excess"]


@pytest.mark.parametrize("p_try, groups", [(V.P_NOISE, 2), (V.P_TRY_DAMPING, 1)])
def test_the_refit_gate_opens_on_pure_noise_at_its_nominal_rate(p_try, groups):
    """20 000 white-noise residuals (40 rows per group): the gate opens on a share p_try (Bonferroni over the
    groups: at most p_try, about p_try for one group), inside its binomial 99.9 % band."""
    from scipy.stats import binom

    rng = np.random.default_rng(21)
    n, rows = 20000, 40
    lab = np.repeat(np.arange(groups), rows)
    z = rng.standard_normal((n, rows * groups))
    # the test in closed form per draw (residual_test's loop is the reference on the first 200)
    chi = (z**2).reshape(n, groups, rows).sum(axis=2)
    from scipy.stats import chi2

    opened = (chi2.sf(chi, rows) < p_try / groups).any(axis=1)
    assert [V.residual_test(z[i], lab, p_try=p_try)["excess"] for i in range(200)] == opened[:200].tolist()
    lo, hi = binom.ppf([0.0005, 0.9995], n, p_try)
    assert opened.sum() <= hi
    if groups == 1:
        assert opened.sum() >= lo
