"""A baseline that moved (docs/physics.md §6.4 "A baseline that moved", docs/formats.md §5 ``baseline.drift``):
how far the baseline left its prior, in σ, in % and as a Mahalanobis D², and the nonlinear screen — each
candidate refitted from the reference baseline, scored by the drop of the refit's objective.

Expected values are computed here independently: the D² and the χ² quantile with numpy/scipy.stats, the
refit's optimum with scipy.optimize on the same objective written out in the test."""

from types import SimpleNamespace

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import optimize, stats

import ringfit  # noqa: F401  (x64)
from ringfit.gap.effects.base import Effect, Parameter
from ringfit.gap.problem import GapProblem, ProblemMeta
from ringfit.gap.ranking import baseline_movement, fit_chain
from ringfit.gap.screening import nonlinear_screen, objective, reference_start, screen


def _problem(y, sigma, x, effects=(), prior_mean=(1.0,), prior_cov=((0.05**2,),), predictor=None):
    nb = len(prior_mean)
    return GapProblem(
        domain="modes", data_files=[], y=np.asarray(y, float), sigma=np.full(len(y), sigma), unit="-",
        scale=np.ones(len(y)), folds=np.arange(len(y)) % 2, fold_kind="toy", labels={"group": np.full(len(y), "a")},
        base=tuple(f"p{i}" for i in range(nb)), base_values=np.asarray(prior_mean, float),
        base_prior_sd=np.sqrt(np.diag(np.asarray(prior_cov, float))), effects=tuple(effects), data=jnp.asarray(x),
        noise_method="toy", baseline_model="toy", meta=ProblemMeta(prior_guarded=tuple(range(nb)), tangents=3),
        base_prior_mean=np.asarray(prior_mean, float), base_prior_cov=np.asarray(prior_cov, float),
        predictor=predictor)


def test_movement_against_a_correlated_prior():
    mean = np.array([2.0, 5.0, 0.3])
    cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.0], [0.0, 0.0, 1.0]])
    p = _problem([0.0] * 4, 1.0, np.zeros(4), prior_mean=mean, prior_cov=cov)
    theta = np.array([2.0 * np.exp(0.5), 5.0 * np.exp(-0.2), 0.3 * 3.0])
    fit = SimpleNamespace(theta=theta)
    out = baseline_movement(p, fit, fit)
    d = np.log(theta / mean)
    assert out["against"] == "prior"
    for i, name in enumerate(p.base):
        assert out["parameters"][name]["sigma"] == pytest.approx(d[i] / np.sqrt(cov[i, i]), rel=1e-12)
        assert out["parameters"][name]["pct"] == pytest.approx(100 * (theta[i] / mean[i] - 1), rel=1e-12)
    d2 = float(d @ np.linalg.solve(cov, d))
    pd = out["prior_distance"]
    assert pd["d2"] == pytest.approx(d2, rel=1e-10) and pd["k"] == 3
    assert pd["limit"] == pytest.approx(stats.chi2.ppf(0.999, 3), rel=1e-8)
    assert pd["outside"] == (d2 > stats.chi2.ppf(0.999, 3))
    assert out["max_abs_sigma"] == pytest.approx(max(abs(d / np.sqrt(np.diag(cov)))))
    # inside: a small move
    small = baseline_movement(p, SimpleNamespace(theta=mean * np.exp([0.1, -0.1, 0.5])), fit)
    assert not small["prior_distance"]["outside"]
    # no prior and the reference is the fit itself: nothing to compare with
    p.meta.prior_guarded = ()
    assert baseline_movement(p, fit, fit) is None


class _Bend(Effect):
    name = "toy_bend"
    parameters = (Parameter("a", "-", null=0.0, lo=-1.0, hi=3.0, start=0.3),)


class _Toy(eqx.Module):
    """y = k·x + a·x³ (k: the baseline's positive parameter, a: the effect's)."""

    def __call__(self, theta, x):
        return theta[0] * x + theta[1] * x**3


def test_nonlinear_screen_scores_the_refit_from_the_reference_baseline():
    """The baseline (k, tight prior at 1) absorbs a cubic it does not model and leaves its prior; the nonlinear
    screen's refit from the prior mean reaches the joint optimum (found here by scipy on the same objective),
    its score is the objective's drop, and the effect's linearised score at the moved baseline is smaller."""
    rng = np.random.default_rng(3)
    x = np.linspace(0.1, 1.5, 40)
    sigma, k_true, a_true = 0.01, 1.0, 0.8
    y = k_true * x + a_true * x**3 + sigma * rng.normal(size=x.size)
    p = _problem(y, sigma, x, effects=(_Bend(),), predictor=_Toy())
    base = fit_chain(p, ())
    assert base.converged
    p.base_values = base.theta[:1].copy()
    moved = baseline_movement(p, base, base)
    assert moved["prior_distance"]["outside"] and moved["parameters"]["p0"]["pct"] > 50

    def resid(v):  # the same objective, written out: data rows and the log-normal prior row of k
        k, a = v
        return np.concatenate([(k * x + a * x**3 - y) / sigma, [np.log(k) / 0.05]])

    ref = optimize.least_squares(resid, [1.0, 0.3], bounds=([1e-3, -1.0], [1e3, 3.0]), xtol=1e-14, ftol=1e-14)
    base_obj = float(np.sum(((base.extra["pred"] - y) / sigma) ** 2) + (np.log(base.theta[0]) / 0.05) ** 2)
    assert objective(p, base) == pytest.approx(base_obj, rel=1e-9)
    assert reference_start(p, base)[0] == pytest.approx(1.0)
    out = nonlinear_screen(p, base, ["toy_bend"])["toy_bend"]
    assert out["fit"].converged
    assert out["fit"].theta[1] == pytest.approx(ref.x[1], rel=1e-5)
    assert out["score"] == pytest.approx(base_obj - 2 * ref.cost, rel=1e-6)
    r2 = float(np.sum(((y - base.extra["pred"]) / sigma) ** 2))
    assert out["alignment"] == pytest.approx(np.sqrt(out["score"] / r2), rel=1e-9)
    assert out["fit"].extra["prior_chi2"] == pytest.approx((np.log(ref.x[0]) / 0.05) ** 2, rel=1e-4)
    lin = screen(p, base, ["toy_bend"])["toy_bend"]
    assert lin["score"] < out["score"]


def test_movement_in_the_json_and_the_report():
    """``baseline.drift`` as docs/formats.md §5 has it, the sentence naming the worst parameters, and the report."""
    from ringfit.gap.diagnosis import _movement_json
    from ringfit.report.gap_report import _drift_html

    moved = {"against": "prior", "max_abs_sigma": 5.04,
             "parameters": {"k_tread": {"reference": 19e6, "value": 8.5e6, "sigma": -0.804, "pct": -55.26},
                            "ei": {"reference": 0.88, "value": 0.25, "sigma": -5.04, "pct": -71.59}},
             "prior_distance": {"d2": 41.3, "k": 5, "limit": 20.52, "outside": True}}
    j = _movement_json(moved)
    assert j["parameters"]["ei"] == {"reference": 0.88, "value": 0.25, "sigma": -5.04, "pct": -71.6}
    assert j["prior_distance"]["outside"] is True
    assert j["sentence"].startswith("the baseline fit left its prior (D^2 41.3 > 20.5")
    assert j["sentence"].index("ei -72 % (-5.0 sigma)") < j["sentence"].index("k_tread -55 %")
    html = _drift_html(j)
    assert "ei -71.6 % (-5.04 σ)" in html and "<b>outside</b>" in html
    inside = dict(moved, prior_distance={"d2": 3.0, "k": 5, "limit": 20.52, "outside": False})
    assert "stayed inside its prior" in _movement_json(inside)["sentence"]
    assert _drift_html(None) == ""
