"""The engine's active set of bounds (docs/physics.md §11 *bounds*).

A bounded parameter is solved for through the sine transform u = mid + half·sin z, whose slope vanishes on the
bound: an optimum beyond the bound makes Levenberg–Marquardt creep towards it, and a solve with a step limit ends
there without meeting its tolerances. The active set holds such a parameter on its bound and solves the rest.
Expected values are the closed-form least-squares answers of a straight line, written here.
"""

import numpy as np
import jax.numpy as jnp
import pytest

from ringfit.fit import engine
from ringfit.fit.engine import LINEAR, AbstractResiduals, Coordinate, Problem, _hold_on_bounds, least_squares

T = np.linspace(0.0, 2.0, 30)


class Line(AbstractResiduals):
    def __call__(self, theta, data):
        t, y, s = data
        model = theta[0] * t + theta[1]
        return (model - y) / s, model


def _problem(slope: float, seed: int = 0):
    rng = np.random.default_rng(seed)
    y = slope * T + 0.2 + 0.01 * rng.standard_normal(T.size)
    coords = (Coordinate("a", LINEAR, lo=0.0, hi=1.0), Coordinate("c", LINEAR, scale=0.1))
    return Problem(Line(), (T, y, np.full(T.size, 0.01)), coords), y


@pytest.mark.parametrize("max_steps", [12, 18, 40])
def test_a_solve_that_creeps_onto_its_bound_is_finished_there(max_steps):
    """The line's slope is 1.5, its range [0, 1]: the constrained optimum is a = 1, c = mean(y − t)."""
    problem, y = _problem(1.5)
    plain = least_squares(problem, np.array([0.5, 0.0]), ("a", "c"), max_steps=max_steps, active_set=False)
    fit = least_squares(problem, np.array([0.5, 0.0]), ("a", "c"), max_steps=max_steps)
    if max_steps < 40:  # the step limit reached while creeping (the case the active set is for)
        assert plain.status == "max_steps_reached" and 1.0 - plain.values["a"] < 1e-3
    assert fit.converged, fit.message
    assert fit.values["a"] == 1.0
    np.testing.assert_allclose(fit.values["c"], np.mean(y - T), rtol=1e-8)
    if fit.extra["held"]:
        assert fit.extra["held"] == ("a",) and "held" in fit.message
        assert any("held there" in f for f in fit.flags)
    # the covariance is the full free set's: c's σ given a free slope (closed form), not a's σ cut away
    X = np.stack([T, np.ones_like(T)], axis=1) / 0.01
    cov = np.linalg.inv(X.T @ X)
    np.testing.assert_allclose(fit.stderr["c"], np.sqrt(cov[1, 1]), rtol=1e-6)


def test_a_parameter_the_gradient_pulls_inside_is_released():
    """Started with the slope on its upper bound when the data's slope (0.4) is inside the range: the active set
    holds it, finds the cost gradient pointing inwards (Karush–Kuhn–Tucker fails), releases it and solves again;
    the answer is the unconstrained least squares."""
    problem, y = _problem(0.4, seed=3)
    on_bound = least_squares(problem, np.array([1.0, 0.2]), ("a", "c"), max_steps=0, active_set=False)
    kw = dict(max_steps=256, rtol=1e-10, atol=1e-10, n_data=None, method="levenberg_marquardt")
    fit = _hold_on_bounds(problem, on_bound, ("a", "c"), None, kw)
    assert fit.converged and fit.extra["held"] == () and "released" in fit.message
    slope, icept = np.polyfit(T, y, 1)
    np.testing.assert_allclose([fit.values["a"], fit.values["c"]], [slope, icept], rtol=1e-7)


def test_a_fit_far_from_its_bounds_is_left_as_it_ended():
    """A step limit reached in the middle of the range is not the active set's business: reported as it is."""
    problem, _ = _problem(0.4, seed=3)
    fit = least_squares(problem, np.array([0.9, 5.0]), ("a", "c"), max_steps=1)
    assert fit.status == "max_steps_reached" and fit.extra["held"] == ()


def test_a_creeping_solve_is_finished_at_the_check_not_at_the_end_of_its_budget(monkeypatch):
    """With a long budget the creep is caught at the check after ``ACTIVE_SET_AFTER`` steps: the slope is within
    the active set's reach of its bound after 12 steps of this solve (a plain solve takes 26 to meet its
    tolerances), so the answer is the constrained optimum in fewer steps than the plain solve's."""
    monkeypatch.setattr(engine, "ACTIVE_SET_AFTER", 12)
    problem, y = _problem(1.5)
    plain = least_squares(problem, np.array([0.5, 0.0]), ("a", "c"), max_steps=400, active_set=False)
    early = least_squares(problem, np.array([0.5, 0.0]), ("a", "c"), max_steps=12, active_set=False)
    assert early.status == "max_steps_reached" and 1.0 - early.values["a"] < engine.ACTIVE_SET_NEAR
    fit = least_squares(problem, np.array([0.5, 0.0]), ("a", "c"), max_steps=400)
    assert fit.converged and fit.extra["held"] == ("a",), fit.message
    assert fit.iterations < plain.iterations
    assert fit.values["a"] == 1.0
    np.testing.assert_allclose(fit.values["c"], np.mean(y - T), rtol=1e-8)


def test_a_solve_with_nothing_on_a_bound_at_the_check_is_the_solve_without_it(monkeypatch):
    """At a check after 4 steps the slope is still 4 % of its range from the bound (not the active set's
    business): the solve runs on with its whole budget as it would without the check, to the same point and in
    the same steps (a solve stopped and resumed from step 4 would be another solve: Levenberg–Marquardt's
    damping would start afresh), and it is compiled and run once."""
    problem, y = _problem(1.5)
    monkeypatch.setattr(engine, "ACTIVE_SET_AFTER", 4)
    early = least_squares(problem, np.array([0.5, 0.0]), ("a", "c"), max_steps=4, active_set=False)
    assert early.status == "max_steps_reached" and 1.0 - early.values["a"] > 10 * engine.ACTIVE_SET_NEAR
    plain = least_squares(problem, np.array([0.5, 0.0]), ("a", "c"), max_steps=400, active_set=False)
    runs = []
    program = engine._solve_program
    monkeypatch.setattr(engine, "_solve_program", lambda model: lambda *a, **k: runs.append(a[6]) or program(model)(
        *a, **k))
    fit = least_squares(problem, np.array([0.5, 0.0]), ("a", "c"), max_steps=400)
    assert fit.converged and fit.iterations == plain.iterations > 4, fit.message
    assert [int(x) for x in runs] == [400]
    np.testing.assert_array_equal(fit.theta, plain.theta)
    np.testing.assert_allclose(fit.values["c"], np.mean(y - T), rtol=1e-8)
