"""The warm fit in one dispatch (issue 24): Marquardt's column scaling is set inside the solve's first step.

- A Levenberg–Marquardt fit runs the compiled solve once (it used to run it twice: a step-0 call for
  the column norms, then the solve).
- The scaling is really applied before the first step's search and descent: Levenberg–Marquardt on
  ``s = d·z`` with ``d`` ∝ the Jacobian's column norms is invariant to the unit of a parameter, so a
  fit whose linear coordinate has a scale 2¹⁴ times smaller (a power of two: every product is exact)
  takes the same steps to the same optimum, bit for bit. Without the scaling (``d = 1``) the damping
  acts 2²⁸ times more weakly on that direction and the path changes (checked below against the
  unscaled solver, so the test can fail).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import ringfit  # noqa: F401  (float64)
from ringfit.fit import engine
from ringfit.fit.engine import LINEAR, LOG, AbstractResiduals, Coordinate, Problem, least_squares


class _Decay(AbstractResiduals):
    """A decaying exponential plus a cosine: A e^{−k t} + B cos(w t), rows (model − y)/σ."""

    def __call__(self, theta, data):
        t, y, sigma = data
        pred = theta[0] * jnp.exp(-theta[1] * t) + theta[2] * jnp.cos(theta[3] * t)
        return (pred - y) / sigma, pred


def _problem(b_scale: float) -> Problem:
    rng = np.random.default_rng(11)
    t = np.linspace(0.0, 3.0, 40)
    y = 2.0 * np.exp(-0.7 * t) + 0.5 * np.cos(3.0 * t) + 0.01 * rng.standard_normal(t.size)
    coords = (Coordinate("A", LOG), Coordinate("k", LOG), Coordinate("B", LINEAR, scale=b_scale),
              Coordinate("w", LOG, lo=1.0, hi=5.0))
    return Problem(_Decay(), (t, y, np.full(t.size, 0.01)), coords)


START = np.array([1.0, 0.3, 0.1, 2.7])
FREE = ("A", "k", "B", "w")
UNIT = 2.0**-14  # B's coordinate unit in the second fit


def test_a_levenberg_marquardt_fit_runs_the_compiled_solve_once(monkeypatch):
    problem = _problem(1.0)
    least_squares(problem, START, FREE)  # compiled
    runs = []
    program = engine._solve_program

    def counting(model):
        solve = program(model)

        def run(*args, **kwargs):
            runs.append((args[6], args[9]))  # the step limit and the creep check
            return solve(*args, **kwargs)

        return run

    monkeypatch.setattr(engine, "_solve_program", counting)
    fit = least_squares(problem, START, FREE)
    assert fit.converged
    # one compiled solve with the whole budget (256), told to look for a creep to a bound after
    # ACTIVE_SET_AFTER steps (inside its loop): a fit that converges is solved once
    assert fit.iterations < engine.ACTIVE_SET_AFTER < 256
    assert len(runs) == 1 and [int(x) for x in runs[0]] == [256, engine.ACTIVE_SET_AFTER]


def test_marquardt_scaling_makes_the_fit_independent_of_a_parameters_unit():
    a = least_squares(_problem(1.0), START, FREE)
    b = least_squares(_problem(UNIT), START, FREE)
    assert a.converged and b.converged
    assert a.iterations == b.iterations
    np.testing.assert_array_equal(b.theta, a.theta)
    np.testing.assert_allclose(b.covariance_log[2, 2] * UNIT**2, a.covariance_log[2, 2], rtol=1e-12)


@pytest.fixture
def unscaled(monkeypatch):
    """Levenberg–Marquardt without Marquardt's scaling (d = 1): the control of the test above."""
    monkeypatch.setattr(engine.SOLVERS["levenberg_marquardt"], "scaled", False)
    engine._solve.clear_cache()
    yield
    engine._solve.clear_cache()


def test_without_the_scaling_the_path_depends_on_the_unit(unscaled):
    a = least_squares(_problem(1.0), START, FREE)
    b = least_squares(_problem(UNIT), START, FREE)
    assert a.converged and b.converged
    assert a.iterations != b.iterations or not np.allclose(a.theta, b.theta, rtol=1e-9)
