"""emcee posterior: a statistical test with a fixed seed, storage round trip, predictive intervals."""

import numpy as np
import pytest

from ringfit.fit.least_squares import fit_natural_frequencies
from ringfit.fit.posterior import load_posterior, log_probability_function, natural_frequency_predictive, sample_posterior
from ringfit.io.modes import ModeTable
from ringfit.params import table9
from ringfit.physics.natural import natural_frequencies

GEO, RING = table9()
N9 = np.arange(1, 10)


@pytest.fixture(scope="module")
def posterior():
    f = np.asarray(natural_frequencies(RING, GEO, N9))
    f = f * (1 + 0.005 * np.random.default_rng(3).standard_normal(9))
    table = ModeTable(freq_hz=f, n=N9, freq_std_hz=0.005 * f)
    post = sample_posterior(table, GEO, RING.replace(kw=1.2e6, kv=1.2e6), free=("kw", "kv"), prior="none",
                            walkers=16, min_steps=1500, max_steps=6000, check_every=500, seed=1, progress=False)
    return table, post


def test_posterior_moments_match_laplace_approximation(posterior):
    """Nearly linear 2-parameter problem: posterior mean/sd ≈ least-squares value/std error."""
    table, post = posterior
    lsq = fit_natural_frequencies(table, GEO, RING, free=("kw", "kv"))
    s = post.samples
    for i, k in enumerate(("kw", "kv")):
        assert s[:, i].mean() == pytest.approx(lsq.values[k], abs=0.15 * lsq.stderr[k])
        assert s[:, i].std() == pytest.approx(lsq.stderr[k], rel=0.15)
    # the truth lies within 3 posterior standard deviations (fails with probability < 0.3 % per parameter)
    for i, k in enumerate(("kw", "kv")):
        assert abs(s[:, i].mean() - getattr(RING, k)) < 3 * s[:, i].std()


def test_sampler_diagnostics(posterior):
    _, post = posterior
    d = post.diagnostics()
    assert post.converged and post.steps > 50 * np.max(post.tau)
    assert 0.2 < d["acceptance_mean"] < 0.9
    assert np.all(d["rhat"] < 1.05)


def test_predictive_interval_contains_data(posterior):
    table, post = posterior
    p = natural_frequency_predictive(post, N9)
    inside = (table.freq_hz >= p["lo"]) & (table.freq_hz <= p["hi"])
    assert inside.sum() >= 8
    c = natural_frequency_predictive(post, N9, noise=False)
    assert np.all(c["hi"] - c["lo"] < p["hi"] - p["lo"])


def test_save_and_load_round_trip(posterior, tmp_path):
    _, post = posterior
    path = post.save(tmp_path / "p.h5")
    back = load_posterior(path)
    np.testing.assert_array_equal(back.chain, post.chain)
    assert back.names == post.names and back.burn == post.burn and back.thin == post.thin
    np.testing.assert_array_equal(back.samples, post.samples)
    with pytest.raises(Exception, match="refusing to overwrite"):
        post.save(path)


def test_log_probability_batch_and_nan_handling():
    f = np.asarray(natural_frequencies(RING, GEO, N9))
    fit = fit_natural_frequencies(ModeTable(freq_hz=f, n=N9), GEO, RING.replace(kw=1e6), free=("kw",))
    fn, lo, hi = log_probability_function(fit)
    np.testing.assert_allclose(np.exp([lo[0], hi[0]]), [1e4, 1e8])  # truncated to the plausible range
    y = np.log([[RING.kw], [RING.kw * 1.1], [1e9], [np.nan]])
    lp = fn(y)
    assert lp[0] == pytest.approx(0.0, abs=1e-12) and lp[1] < lp[0]
    assert lp[2] == -np.inf and lp[3] == -np.inf


@pytest.mark.parametrize("stated", [False, True], ids=["no-sigma", "stated-sigma"])
def test_the_scale_integrated_out_is_the_integral_over_s(stated):
    """The free block's estimated scale is integrated out of the sampled density (docs/physics.md §12.3): between
    any two parameter points its log density changes as ln ∫ s^(−m) exp(−χ²/(2 s²)) ds/s over s ≥ s_min does —
    the integral done here by quadrature, not by the code's closed form — and the prior rows as −½ |W u|²."""
    from scipy.integrate import quad

    from ringfit.fit.engine import residuals

    f = np.asarray(natural_frequencies(RING, GEO, N9))
    f = f * (1 + 0.004 * np.random.default_rng(7).standard_normal(9))
    # stated σ smaller than the scatter, so the block scales it up and estimates a scale (ν finite)
    table = ModeTable(freq_hz=f, n=N9, freq_std_hz=0.001 * f if stated else None)
    lsq = fit_natural_frequencies(table, GEO, RING, free=("kw", "kv"), prior="none")
    marg = lsq.extra["scale_marginal"]
    assert marg is not None and marg["rows"] == 9
    assert (marg["s_min"] > 0) == stated
    log_prob, _, _ = log_probability_function(lsq, row_scale=marg["row_scale"], scale_marginal=marg)
    names = lsq.names
    coords = [lsq.problem.coordinate(n) for n in names]
    u0 = np.array([c.to_u(lsq.values[n]) for c, n in zip(coords, names)])
    sd = np.array([lsq.stderr[n] / lsq.values[n] for n in names])  # log coordinates
    points = u0[None] + np.array([[0.0, 0.0], [2.0, -1.0], [-1.5, 2.5]]) * sd[None]
    lp = log_prob(points)

    def exact(u):
        theta = np.asarray(lsq.theta, dtype=np.float64).copy()
        for j, c in enumerate(coords):
            theta[list(lsq.problem.coords).index(c)] = c.from_u(u[j])
        r, _ = residuals(lsq.problem, theta)
        chi2 = float(np.sum((np.asarray(r)[:9] / marg["row_scale"][:9]) ** 2))
        smin = marg["s_min"]
        # substitute s = e^t: ∫ s^(−m−1) e^(−χ²/2s²) ds = ∫ e^(−m t − χ² e^(−2t)/2) dt, peaked at e^(2t) = χ²/m
        t0 = 0.5 * np.log(chi2 / 9)
        g = lambda t: np.exp(-9 * (t - t0) - 0.5 * chi2 * np.exp(-2 * t) + 0.5 * 9)  # noqa: E731 (scaled by the peak)
        lo = np.log(smin) if smin > 0 else t0 - 12.0
        val, _ = quad(g, lo, t0 + 12.0, points=[t0] if lo < t0 else None, limit=200)
        return np.log(val) - 9 * t0 - 0.5 * 9

    want = np.array([exact(u) for u in points])
    assert np.allclose(lp - lp[0], want - want[0], atol=1e-6), (lp - lp[0], want - want[0])


def test_sample_reads_the_fits_own_likelihood():
    """sample() takes the noise model the fit recorded (issue 31: one likelihood per data type): the free block's
    scale marginal and its widening when it estimated a scale, its row widening when the scale was stated, an
    identify-style ``shift_u``/``tables`` from ``extra``; an explicit row_scale beside a marginal is refused (two
    widenings of the same rows), and explicit values replace the fit's."""
    from ringfit.fit.posterior import fit_likelihood

    f = np.asarray(natural_frequencies(RING, GEO, N9))
    f = f * (1 + 0.004 * np.random.default_rng(7).standard_normal(9))
    est = fit_natural_frequencies(ModeTable(freq_hz=f, n=N9), GEO, RING, free=("kw", "kv"), prior="none")
    row, du, tables, marg = fit_likelihood(est)
    assert marg is est.extra["scale_marginal"] and marg is not None
    assert row is marg["row_scale"] and du is None and tables is None
    with pytest.raises(ValueError, match="beside a scale marginal"):
        fit_likelihood(est, row_scale=np.ones(9))
    row, _, _, marg = fit_likelihood(est, row_scale=np.full(9, 2.0), scale_marginal=None)
    assert marg is None and np.all(row == 2.0)
    # a stated σ the data agree with: no scale estimated, no marginal; the widening is the fit's row_scale
    fixed = fit_natural_frequencies(ModeTable(freq_hz=f, n=N9, freq_std_hz=0.004 * f), GEO, RING, free=("kw", "kv"),
                                    prior="none", noise="fixed")
    row, _, _, marg = fit_likelihood(fixed)
    assert marg is None and row is fixed.extra["row_scale"]
    fixed.extra.update(shift_u=np.array([0.1, 0.0]), tables={"t": slice(0, 9)})
    _, du, tables, _ = fit_likelihood(fixed)
    assert np.all(du == [0.1, 0.0]) and tables == {"t": slice(0, 9)}
    assert fit_likelihood(fixed, shift_u=None)[1] is None


def test_several_systematic_directions_are_convolved_into_the_draws(tmp_path):
    """``shift_u`` of shape (d, k) (identify's grid check and its held friction, docs/physics.md §12.3): the draws'
    covariance is the chain's plus Σ δu_j δu_jᵀ, and one direction given as (k,) or (1, k) draws the same numbers;
    the directions survive a save and load."""
    from ringfit.fit.posterior import Posterior, load_posterior

    rng = np.random.default_rng(5)
    steps, walkers, k = 4000, 8, 2
    chain = rng.standard_normal((steps, walkers, k)) * np.array([0.01, 0.02])
    base = dict(names=("a", "b"), kinds=("log", "log"), values0={"a": 1.0, "b": 2.0}, chain=chain,
                log_prob=np.zeros((steps, walkers)), acceptance=np.full(walkers, 0.4), tau=np.full(k, 1.0), burn=0,
                thin=1, seed=3)
    shifts = np.array([[0.03, 0.0], [0.02, -0.04]])
    post = Posterior(**base, shift_u=shifts)
    cov = np.cov(post.log_samples.T)
    expect = np.diag([0.01**2, 0.02**2]) + shifts.T @ shifts
    assert np.allclose(cov, expect, rtol=0.06, atol=2e-5)
    one = Posterior(**base, shift_u=shifts[1]).log_samples
    assert np.array_equal(one, Posterior(**base, shift_u=shifts[1:]).log_samples)
    post.save(tmp_path / "p.h5")
    back = load_posterior(tmp_path / "p.h5")
    assert np.array_equal(back.log_samples, post.log_samples)
