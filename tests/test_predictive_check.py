"""Posterior predictive check per measured table (ringfit.fit.posterior.predictive_check): the p-value of each
table's χ² — calibrated where the model and σ are right, small where a table's scatter is understated, and equal
to a brute-force replication of the data."""

import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.fit.engine import LINEAR, AbstractResiduals, Coordinate, Problem, least_squares
from ringfit.fit.posterior import predictive_check, sample

X = np.linspace(-1.0, 1.0, 30)


class _TwoLines(AbstractResiduals):
    """Two tables of a straight line y = a + b x, each row over its stated σ."""

    def __call__(self, theta, data):
        x, y, sigma = data
        return ((theta[0] + theta[1] * x - y) / sigma).ravel(), None


def _fit(y, sigma):
    coords = (Coordinate("a", LINEAR), Coordinate("b", LINEAR))
    problem = Problem(_TwoLines(), (jnp.asarray(np.stack([X, X])), jnp.asarray(y), jnp.asarray(sigma)), coords)
    fit = least_squares(problem, np.array([0.0, 0.0]), ("a", "b"))
    assert fit.converged
    return fit


TABLES = {"first": slice(0, 30), "second": slice(30, 60)}


def _data(rng, scatter=(1.0, 1.0)):
    """Both tables of a = 0.3, b = −1.2 with stated σ = 0.1; the actual scatter is ``scatter`` × σ."""
    y = 0.3 - 1.2 * np.stack([X, X]) + 0.1 * np.asarray(scatter)[:, None] * rng.standard_normal((2, X.size))
    return _fit(y, np.full((2, X.size), 0.1))


def _posterior(fit, seed):
    return sample(fit, walkers=8, min_steps=600, max_steps=600, check_every=600, seed=seed, progress=False,
                  tables=TABLES)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_p_values_are_calibrated_where_the_model_is_right_and_small_where_not():
    """40 data sets where the stated σ is right: no more than 6 of the 80 p-values below 0.05 (posterior
    predictive p-values are conservative: expected ≤ 4); 10 where the second table's scatter is 3× its stated σ:
    its p-value < 1e-3 every time while the first table's stays above 0.01 in at least 8 of them."""
    rng = np.random.default_rng(5)
    low = 0
    for i in range(40):
        post = _posterior(_data(rng), i)
        ppc = post.meta["predictive_check"]
        assert set(ppc) == {"first", "second"} and ppc["first"]["rows"] == 30
        low += sum(ppc[t]["p_value"] < 0.05 for t in TABLES)
    assert low <= 6
    first_ok = 0
    for i in range(10):
        ppc = _posterior(_data(rng, scatter=(1.0, 3.0)), 100 + i).meta["predictive_check"]
        assert ppc["second"]["p_value"] < 1e-3, ppc
        first_ok += ppc["first"]["p_value"] > 0.01
    assert first_ok >= 8  # the line the bad table pulls is shared: the good table's χ² grows a little


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_p_value_equals_brute_force_replication():
    """The χ²_m survival function averaged over draws against data replicated explicitly from each draw
    (y_rep = model + σ ε, 200 replications per draw), for a table whose p-value is neither 0 nor 1."""
    rng = np.random.default_rng(8)
    fit = _data(rng, scatter=(1.0, 1.1))
    post = _posterior(fit, 3)
    u = post.chain[post.burn :: post.thin].reshape(-1, 2)
    ppc = predictive_check(fit, u, TABLES, draws=100, seed=1)
    # brute force, written here: the same 100 draws
    pick = np.random.default_rng(1).choice(u.shape[0], 100, replace=False) if u.shape[0] > 100 else np.arange(len(u))
    a, b = u[pick, 0], u[pick, 1]
    y = np.asarray(fit.problem.data[1])
    hits = []
    for t in range(2):
        model = a[:, None] + b[:, None] * X[None, :]
        chi_obs = np.sum(((model - y[t]) / 0.1) ** 2, axis=1)
        rep = model[:, None, :] + 0.1 * rng.standard_normal((model.shape[0], 200, X.size))
        chi_rep = np.sum(((model[:, None, :] - rep) / 0.1) ** 2, axis=2)
        hits.append(np.mean(chi_rep >= chi_obs[:, None]))
    for t, name in enumerate(TABLES):
        assert 0.001 < ppc[name]["p_value"] < 0.999
        assert ppc[name]["p_value"] == pytest.approx(hits[t], abs=4 * np.sqrt(0.25 / 20000) + 0.01)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_one_table_reads_its_chi2_from_the_log_density():
    """With one block of every row the χ² comes from the sampler's log densities (less the prior rows): the same
    p-value as the model evaluated at the draws."""
    from ringfit.fit.engine import GaussianPrior

    rng = np.random.default_rng(2)
    fit = _data(rng, scatter=(1.0, 1.1))
    problem = fit.problem
    prior = GaussianPrior.independent({"a": (0.2, 0.5), "b": (-1.0, 0.8)})
    fit = least_squares(Problem(problem.model, problem.data, problem.coords, prior=prior), fit.theta, ("a", "b"))
    post = sample(fit, walkers=8, min_steps=400, max_steps=400, check_every=400, seed=1, progress=False)
    u = post.chain[post.burn :: post.thin].reshape(-1, 2)
    lp = post.log_prob[post.burn :: post.thin].reshape(-1)
    via_lp = predictive_check(fit, u, {"all": slice(None)}, log_prob=lp)
    via_model = predictive_check(fit, u, {"all": slice(None)})
    assert via_lp["all"]["rows"] == via_model["all"]["rows"] == 60
    assert via_lp["all"]["p_value"] == pytest.approx(via_model["all"]["p_value"], rel=1e-9)
    assert via_lp["all"]["chi2_median"] == pytest.approx(via_model["all"]["chi2_median"], rel=1e-9)
