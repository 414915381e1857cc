"""The engine's public surface (issue 22 item 4): residuals, Jacobian, log-probability at given parameters.

Expected values come from outside the code under test: the residual formula written here, central finite
differences of it, and the Gaussian log density written here.
"""

import math

import jax.numpy as jnp
import pytest
import numpy as np

from ringfit.fit.engine import (LINEAR, LOG, AbstractResiduals, Coordinate, GaussianPrior, Problem, evaluate,
                                least_squares, linearize, log_probability, residuals, residuals_batch)

T = np.linspace(0.0, 2.0, 25)


class Decay(AbstractResiduals):
    def __call__(self, theta, data):
        t, y, s = data
        model = theta[0] * jnp.exp(-theta[1] * t) + theta[2]
        return (model - y) / s, model


def _problem(prior=None):
    rng = np.random.default_rng(1)
    y = 3.0 * np.exp(-1.3 * T) + 0.2 + 0.01 * rng.standard_normal(T.size)
    coords = (Coordinate("a", LOG), Coordinate("k", LOG, lo=0.01, hi=100.0), Coordinate("c", LINEAR, scale=0.1))
    return Problem(Decay(), (T, y, np.full(T.size, 0.01)), coords, prior=prior), y


def _rows(theta, y):
    return (theta[0] * np.exp(-theta[1] * T) + theta[2] - y) / 0.01


def test_residuals_and_batch_match_the_formula():
    problem, y = _problem()
    theta = np.array([2.5, 1.1, 0.3])
    r, aux = residuals(problem, theta)
    np.testing.assert_allclose(r, _rows(theta, y), rtol=1e-12)
    np.testing.assert_allclose(aux, r * 0.01 + y, rtol=1e-12)
    thetas = theta * np.array([[1.0, 1.0, 1.0], [1.1, 0.9, 1.0], [0.8, 1.2, 0.5]])
    np.testing.assert_allclose(residuals_batch(problem, thetas, chunk=2), [_rows(t, y) for t in thetas], rtol=1e-12)


def test_linearize_jacobian_matches_finite_differences_in_solver_coordinates():
    problem, y = _problem()
    theta = np.array([2.5, 1.1, 0.3])
    lin = linearize(problem, theta, ("k", "a", "c"), pad_to=5)
    assert lin.jacobian.shape == (T.size, 3)
    np.testing.assert_allclose(lin.residuals, _rows(theta, y), rtol=1e-12)
    h = 1e-6
    # u = ln k, ln a, c / 0.1
    for j, (i, step) in enumerate([(1, "log"), (0, "log"), (2, "lin")]):
        up, dn = theta.copy(), theta.copy()
        if step == "log":
            up[i], dn[i] = theta[i] * math.exp(h), theta[i] * math.exp(-h)
        else:
            up[i], dn[i] = theta[i] + 0.1 * h, theta[i] - 0.1 * h
        fd = (_rows(up, y) - _rows(dn, y)) / (2 * h)
        np.testing.assert_allclose(lin.jacobian[:, j], fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_evaluate_at_the_optimum_gives_the_fits_standard_errors():
    problem, _ = _problem(prior=GaussianPrior.independent({"a": (math.log(3.0), 0.5)}))
    fit = least_squares(problem, np.array([2.0, 1.0, 0.0]), ("a", "k", "c"))
    assert fit.converged
    ev = evaluate(problem, fit.theta, ("a", "k", "c"))
    assert ev.status == "evaluated"
    for name in ("a", "k", "c"):
        assert ev.stderr[name] == np.float64(ev.stderr[name])
        np.testing.assert_allclose(ev.stderr[name], fit.stderr[name], rtol=1e-6)


def test_log_probability_is_the_gaussian_density_and_respects_bounds():
    prior = GaussianPrior.independent({"a": (math.log(3.0), 0.5)})
    problem, y = _problem(prior=prior)
    theta = np.array([2.5, 1.1, 0.3])
    logp = log_probability(problem, theta, ("a", "k"), sigma_scale=2.0, chunk=4)
    u = np.array([[math.log(2.5), math.log(1.1)], [math.log(2.9), math.log(1.4)], [math.log(3.0), math.log(200.0)]])
    got = logp(u)
    for row, value in zip(u[:2], got[:2]):
        th = theta.copy()
        th[:2] = np.exp(row)
        expect = -0.5 * (np.sum(_rows(th, y) ** 2) / 4.0 + ((row[0] - math.log(3.0)) / 0.5) ** 2)
        np.testing.assert_allclose(value, expect, rtol=1e-12)
    assert got[2] == -np.inf  # k = 200 is beyond its bound of 100


def test_an_unknown_sigma_mode_is_refused_when_the_problem_is_made():
    """``Problem(sigma=…)`` is one of ``SigmaMode``; a misspelt mode used to behave silently as ``"fixed"``."""
    import pytest

    from ringfit.fit.engine import Coordinate, Problem

    with pytest.raises(ValueError, match="sigma='estimte'"):
        Problem(model=None, data=None, coords=(Coordinate("a", "log"),), sigma="estimte")


def test_gauss_newton_decrement_is_the_drop_the_linearised_rows_promise():
    """The decrement against numpy's least squares: |r|² − min_δ |r + Jδ|², the same with the columns rescaled,
    and with a column of zeros (a padded free set) added."""
    from ringfit.fit._steps import gauss_newton_decrement

    rng = np.random.default_rng(7)
    for m, p in ((40, 3), (300, 12)):
        J, r = rng.standard_normal((m, p)), rng.standard_normal(m)
        delta, *_ = np.linalg.lstsq(J, -r, rcond=None)
        expected = r @ r - np.sum((r + J @ delta) ** 2)
        assert float(gauss_newton_decrement(jnp.asarray(r), jnp.asarray(J))) == pytest.approx(expected, rel=1e-9)
        scaled = J * np.logspace(-4, 4, p)[None, :]
        assert float(gauss_newton_decrement(jnp.asarray(r), jnp.asarray(scaled))) == pytest.approx(expected, rel=1e-6)
        padded = np.concatenate([J, np.zeros((m, 2))], axis=1)
        assert float(gauss_newton_decrement(jnp.asarray(r), jnp.asarray(padded))) == pytest.approx(expected, rel=1e-9)


class _HighPass(AbstractResiduals):
    """A gain read through a first-order high-pass at frequencies f: the corner is told only weakly (its data
    want it at 0, its log-normal prior at 0.3), the case where Gauss–Newton crawls (docs/physics.md §11)."""

    def __call__(self, theta, data):
        f, y, s = data
        m = theta[0] / (1.0 - 1j * theta[1] / f)
        return jnp.concatenate([(m.real - y.real) / s, (m.imag - y.imag) / s]), m


def test_the_decrement_stop_ends_a_linear_crawl_at_the_optimum():
    """With ``dtol`` a weakly told corner's fit ends in fewer steps, at the Cauchy test's optimum to 1e-2 of a
    standard error, on every one of 8 noise draws; started far away, it does not stop early."""
    from ringfit.fit.engine import DECREMENT_TOL

    f = np.arange(2, 40) * 2.7
    coords = (Coordinate("a", LOG), Coordinate("fc", LOG))
    prior = GaussianPrior.independent({"fc": (math.log(0.3), 2.0)})
    steps = []
    for seed in range(8):
        rng = np.random.default_rng(seed)
        y = 1.0 + 0.02 * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size))
        problem = Problem(_HighPass(), (f, y, np.full(f.size, 0.02)), coords, prior=prior, sigma="fixed")
        cauchy = least_squares(problem, np.array([1.0, 0.3]), ("a", "fc"), rtol=1e-8, atol=1e-8)
        for start in ([1.0, 0.3], [3.0, 5.0]):
            fit = least_squares(problem, np.array(start), ("a", "fc"), rtol=1e-8, atol=1e-8, dtol=DECREMENT_TOL)
            assert cauchy.converged and fit.converged
            for j, name in enumerate(("a", "fc")):
                off = (math.log(fit.values[name]) - math.log(cauchy.values[name])) / math.sqrt(cauchy.covariance_log[j, j])
                assert abs(off) < 1e-2, (seed, start, name, off)
        steps.append((cauchy.iterations, least_squares(problem, np.array([1.0, 0.3]), ("a", "fc"), rtol=1e-8,
                                                       atol=1e-8, dtol=DECREMENT_TOL).iterations))
    cauchy_steps, dtol_steps = np.array(steps).T
    assert np.all(dtol_steps <= cauchy_steps) and dtol_steps.sum() < 0.7 * cauchy_steps.sum(), steps
