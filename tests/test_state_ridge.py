"""Intervals along the load–pressure–tread-depth ridge and the model-discrepancy term of the state estimate
(docs/physics.md §13.4 *intervals along the ridge*, §11's discrepancy ratio reused).

The blind coverage on the independent simulator is ``benchmarks/bench_state.py``'s; here the parts: the harmonic
bands the discrepancy ratio holds out, the slices' weights (an integrated Laplace written out by hand), each
slice's deviance against a separate fit with the depth held, and the coverage of the intervals on a light load
(where the ridge is flat) over many noise draws of the forward model.
"""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import numpy as np
import pytest

from ringfit.fit.engine import least_squares, residuals
from ringfit.fit.estimate.state import (QUANTITIES, STATE_COORDS, STATE_PARAMETERS, TREAD, TREAD_PRIOR_SD, RidgeProfile,
                                        estimate_state, state_priors)
from ringfit.fit.identify import band_folds
from ringfit.io.profiles import Profile, grid_angles_deg
from ringfit.params import TyreLaws, table9
from ringfit.physics.profile import ProfileModel
from ringfit.physics.sensor import STANDARD_GRAVITY
from ringfit.physics.state import TyreState, solve_state

GEO, RING = table9()
LAWS = TyreLaws(tread_depth_ref=0.008, k_x=15e6, kw_share=0.5, kv_share=0.3, has_tread_depth=True, has_brush=True)
OMEGA = 2 * math.pi * 12.0
SENSOR = ProfileModel().with_sensor(gravity=STANDARD_GRAVITY, tilt_gain=0.8, corner_hz=0.5)


def _profile(ch):
    return Profile(grid_angles_deg(ch.shape[-1]), ch[0], ch[1],
                   condition={"speed_kmh": 50.0, "rotation_hz": OMEGA / (2 * math.pi)}, source="synthetic")


def test_band_folds_hold_out_each_band_of_harmonics_in_every_channel_and_part():
    K = 8  # rows: radial Re k, radial Im k, tangential Re k, tangential Im k; k = 0…7 in each run
    folds = band_folds(np.arange(4 * K), K, 4)
    assert len(folds) == 4
    for b, fold in enumerate(folds):
        expected = sorted(run * K + k for run in range(4) for k in (2 * b, 2 * b + 1))
        assert fold.tolist() == expected
    assert sorted(np.concatenate(folds).tolist()) == list(range(4 * K))


def test_ridge_weights_are_the_integrated_laplace_of_the_slices():
    """w_j ∝ exp(−Δ_j/2κ)·√det(κC_j) over the converged slices (evenly spaced in ln d), by hand."""
    dev = np.array([3.0, 0.0, 1.5, 40.0, 0.5])
    covs = np.array([np.diag([a, b]) for a, b in ((1.0, 2.0), (0.5, 0.5), (2.0, 2.0), (1.0, 1.0), (9.0, 1.0))])
    conv = np.array([True, True, True, True, False])
    r = RidgeProfile(depth=np.linspace(2e-3, 10e-3, 5), theta=np.zeros((5, 10)), deviance=dev, converged=conv,
                     cov_u=covs, free=("a", "b"))
    for kappa in (1.0, 4.0):
        raw = [math.exp(-d / (2 * kappa)) * math.sqrt(np.prod(kappa * np.diag(c))) if ok else 0.0
               for d, c, ok in zip(dev, covs, conv)]
        assert r.weights(kappa) == pytest.approx(np.array(raw) / sum(raw), rel=1e-12)


def test_a_ridge_steeper_than_its_slices_keeps_its_width_at_the_new_tread():
    """A depth held on the new tread's bound whose likelihood falls below it within a fraction of the slices'
    spacing (the blind recordings whose true depth was 7.9 mm of 8 read [8.0, 8.0] mm): the ridge read as a curve
    gives the truncated normal's interval — Δ(u) = ((u − u*)/σ)² in u = ln d, the free optimum u* one σ beyond the
    bound, slices 10 σ apart — within a fifth of σ, where the slices alone put every weight on the last one."""
    from scipy.stats import truncnorm

    from ringfit.fit.estimate.problem import EstimateSettings
    from ringfit.fit.estimate.state import ANGLE_OFFSET, GAIN, LOAD, PRESSURE, SLIP, _along_ridge

    d_new, sigma = 0.008, 0.02
    u_new = math.log(d_new)
    u_star = u_new + sigma
    u = u_new - 10 * sigma * np.arange(12, -1, -1)  # 13 slices ending at the bound
    free = (LOAD, PRESSURE, SLIP, GAIN, ANGLE_OFFSET)
    theta = np.array([[3000.0, 2.2e5, 0.0, math.exp(x), 1.0, 0.0, 0.5, 0.8, 1.0, 1e-3] for x in u])
    assert [STATE_PARAMETERS[i] for i in (0, 1, 2, 3, 4, 5)] == [LOAD, PRESSURE, SLIP, TREAD, GAIN, ANGLE_OFFSET]
    dev = ((u - u_star) / sigma) ** 2 - ((u_new - u_star) / sigma) ** 2
    ridge = RidgeProfile(depth=np.exp(u), theta=theta, deviance=dev, converged=np.ones(u.size, bool),
                         cov_u=np.repeat(1e-8 * np.eye(len(free))[None], u.size, axis=0), free=free)
    assert ridge.weights()[-1] > 1 - 1e-12  # the slices alone: every weight on the bound
    held = free + (TREAD,)
    along = _along_ridge(ridge, 1.0, theta[-1], held, GEO, RING, LAWS, OMEGA, None, EstimateSettings(),
                         np.zeros(len(QUANTITIES)))
    q = list(QUANTITIES).index("tread_depth_mm")
    lo_u, hi_u = math.log(along["lo"][q]), math.log(along["hi"][q])
    b = (u_new - u_star) / sigma
    want = truncnorm.ppf([0.025, 0.975], -np.inf, b, loc=u_star, scale=sigma)
    assert lo_u == pytest.approx(want[0], abs=0.2 * sigma)
    assert hi_u == pytest.approx(want[1], abs=0.2 * sigma)
    # and every revolution's held depth carries that spread (its variance in u about the bound)
    j = held.index(TREAD)
    mean_sq = truncnorm.stats(-np.inf, b, loc=0.0, scale=1.0, moments="mv")
    second = (float(mean_sq[1]) + float(mean_sq[0]) ** 2) * sigma**2  # E[(u − u*)²]
    m1 = float(mean_sq[0]) * sigma
    spread = second - 2 * m1 * (u_new - u_star) + (u_new - u_star) ** 2  # E[(u − u_new)²]
    assert along["spread_u"][j, j] == pytest.approx(spread, rel=0.15)


@pytest.mark.slow
def test_each_slice_is_the_fit_with_the_depth_held():
    """A light load (the ridge is flat): the weighted slices' deviance against a separate fit of the same rows
    with d held there, started from the truth, its −2 ln(L·prior) summed by hand from the residual rows and the
    weak priors; and the reported intervals are at least the Laplace ones."""
    truth = TyreState(1500.0, 2.2e5, 0.005, 0.004, OMEGA)
    _, ch, _ = solve_state(GEO, RING, LAWS, truth, model=SENSOR)
    rng = np.random.default_rng(3)
    ch = ch + np.array([[1.0], [0.15]]) * rng.standard_normal(ch.shape)
    est = estimate_state(_profile(ch), GEO, RING, LAWS)
    ridge = est.ridge
    assert ridge is not None and ridge.converged.sum() >= len(ridge.depth) - 2
    fit = est.fit
    s = fit.extra["sigma_scale"]
    data = eqx.tree_at(lambda a: a.weight, fit.problem.data, np.asarray(fit.problem.data.weight) / s)
    prob = dataclasses.replace(fit.problem, data=data, sigma="fixed")
    priors = state_priors(GEO, LAWS)

    def total(theta, free):
        r = residuals(prob, theta)[0]
        chi2 = float(r @ r)
        for n in free:
            if n in priors:
                c = STATE_COORDS[STATE_PARAMETERS.index(n)]
                mean, sd = priors[n]
                chi2 += ((c.to_u(float(theta[STATE_PARAMETERS.index(n)])) - mean) / sd) ** 2
        return chi2

    best = total(fit.theta, fit.names)
    rest = tuple(n for n in fit.names if n != TREAD)
    start = np.array([1500.0, 2.2e5, 0.004, 0.005, *fit.theta[4:]])
    # the slices that carry weight (Δ < 20; far up the walls a warm-started chain and a fit from elsewhere may stop
    # in different local minima, of no weight either way)
    near = np.flatnonzero(ridge.converged & (ridge.deviance < 20.0))
    assert near.size >= 2
    for j in near[:: max(1, near.size // 3)]:
        th = start.copy()
        th[STATE_PARAMETERS.index(TREAD)] = ridge.depth[j]
        alone = least_squares(prob, th, rest, max_steps=200, rtol=1e-10, atol=1e-10)
        assert alone.converged
        dev = total(alone.theta, fit.names) - best
        assert ridge.deviance[j] == pytest.approx(dev, abs=0.05 + 0.01 * abs(dev)), (ridge.depth[j], dev)
    # the slices span the prior's ±2.5 σ in ln d about d_ref
    assert math.log(ridge.depth[-1] / ridge.depth[0]) == pytest.approx(2 * 2.5 * TREAD_PRIOR_SD, rel=1e-6)
    from scipy.special import ndtri

    z = float(ndtri(0.975))
    keys = list(QUANTITIES)
    for key in ("load_n", "tread_depth_mm"):  # log-normal Laplace intervals, κ applied
        Q, scale = est.quantities[key], QUANTITIES[key][1]
        g = est.gradient_u[keys.index(key)]
        v = Q["value"] / scale
        s_rel = math.sqrt(est.discrepancy * float(g @ fit.covariance_log @ g)) / v
        assert Q["lo"] <= v * math.exp(-z * s_rel) * scale * (1 + 1e-9), key
        assert Q["hi"] >= v * math.exp(z * s_rel) * scale * (1 - 1e-9), key


@pytest.mark.slow
def test_intervals_cover_on_a_flat_ridge_over_noise_draws():
    """Light load, the forward model (on the 4M grid the estimate fits), 10 noise draws (a self-consistent case: no
    form error): the load's and the
    tread depth's 95 % intervals cover the truth in at least 8 of 10 (binomial at 95 %: P(≤ 7) ≈ 1 %)."""
    from ringfit.physics.contact import ContactSolver

    truth = TyreState(1600.0, 2.3e5, 0.006, -0.003, OMEGA)
    # solved on 2048 angles and sampled on 512: the estimate fits the 4M model (docs/physics.md §13.4)
    _, ch, _ = solve_state(GEO, RING, LAWS, truth, model=SENSOR, solver=ContactSolver(n_grid=2048))
    ch = np.asarray(ch)[:, ::4]
    inside = {"load_n": 0, "tread_depth_mm": 0}
    value = {"load_n": 1600.0, "tread_depth_mm": 6.0}
    rng = np.random.default_rng(2024)
    for _ in range(10):
        noisy = ch + np.array([[2.0], [0.3]]) * rng.standard_normal(ch.shape)
        est = estimate_state(_profile(noisy), GEO, RING, LAWS)
        for key in inside:
            Q = est.quantities[key]
            inside[key] += Q["lo"] <= value[key] <= Q["hi"]
    assert all(n >= 8 for n in inside.values()), inside
