"""Pieces of the state's blind check (``benchmarks/bench_state.py``) and of the estimate's report that it leans on:
the bound test, the "not told apart" flags, the per-revolution truth and the Clopper–Pearson interval. Expected
values are hand-computed or closed forms."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from ringfit.fit.estimate.state import CORRELATED, ONE_QUANTITY, STATE_PARAMETERS, near_bound

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_state as bench  # noqa: E402


def _theta(**kw):
    base = dict(load_n=4000.0, pressure_pa=2.2e5, slip=0.0, tread_depth_m=8e-3, gain=1.0, angle_offset=0.0,
                corner_hz=0.5, tilt_gain=0.5, gain_tangential=1.0, liner_offset_m=1e-3)
    base.update(kw)
    return np.array([base[n] for n in STATE_PARAMETERS])


def test_near_bound_catches_a_parameter_creeping_to_its_bound():
    assert near_bound(_theta(), STATE_PARAMETERS) == []
    # 7.9996 bar of the 8 bar bound: ln(8/7.9996) = 5e-5, far inside the engine's 1e-6·span but at the bound
    assert near_bound(_theta(pressure_pa=7.9996e5), STATE_PARAMETERS) == ["pressure_pa"]
    # 0.2001 mm of 0.2 mm: ln ratio 5.0e-4 < 1e-3·ln(30/0.2) = 5.0e-3
    assert near_bound(_theta(tread_depth_m=0.2001e-3), STATE_PARAMETERS) == ["tread_depth_m"]
    # 0.21 mm: ln ratio 0.049 > 5.0e-3 — not at it
    assert near_bound(_theta(tread_depth_m=0.21e-3), STATE_PARAMETERS) == []
    # a linear coordinate: κ = −0.2999 of [−0.3, 0.3]: 1e-4/0.6 < 1e-3
    assert near_bound(_theta(slip=-0.2999), STATE_PARAMETERS) == ["slip"]
    # only the free ones are looked at
    assert near_bound(_theta(pressure_pa=7.9996e5), ("load_n", "slip")) == []


def test_one_quantity_pairs_are_reported_quantities():
    for pair in ONE_QUANTITY:
        assert pair <= set(CORRELATED)


def test_truth_over_is_the_time_weighted_mean_of_the_simulated_revolutions():
    truth = {"t_start_s": np.array([0.0, 1.0, 2.0]), "t_end_s": np.array([0.99, 1.99, 2.99]),
             "load_n": np.array([100.0, 200.0, 400.0])}
    # [0.5, 1.5]: half of revolution 0 (held until 1.0) and half of revolution 1
    assert bench.truth_over(truth, "load_n", 0.5, 1.5) == pytest.approx(150.0)
    # [1.75, 2.5]: 0.25 s at 200 and 0.5 s at 400
    assert bench.truth_over(truth, "load_n", 1.75, 2.5) == pytest.approx((0.25 * 200 + 0.5 * 400) / 0.75)
    assert math.isnan(bench.truth_over(truth, "load_n", 5.0, 6.0))


def test_clopper_pearson_closed_forms():
    # k = 0: upper = 1 − (α/2)^(1/n); k = n: lower = (α/2)^(1/n)
    assert bench.clopper_pearson(0, 10) == pytest.approx((0.0, 1 - 0.025 ** 0.1))
    assert bench.clopper_pearson(10, 10) == pytest.approx((0.025 ** 0.1, 1.0))
    lo, hi = bench.clopper_pearson(95, 100)
    assert lo < 0.95 < hi and 0.88 < lo < 0.90 and 0.98 < hi < 0.99


def test_errors_in_the_issue_units():
    assert bench.error_of("load", 4020.0, 4000.0, 4000.0) == pytest.approx(0.5)
    assert bench.error_of("fx", 580.0, 500.0, 4000.0) == pytest.approx(2.0)  # % of the load
    assert bench.error_of("tread", 5.3, 5.0, 4000.0) == pytest.approx(0.3)  # mm
