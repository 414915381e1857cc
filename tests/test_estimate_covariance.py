"""The tyre's whole [ring.covariance] in the load estimate (issue 22 item 2; docs/physics.md §10).

- the split of the covariance into k_trd given the rest and the rest (closed form of a Gaussian);
- the propagated sensitivities ∂ln load/∂ln θ against refits with the ring moved (finite differences);
- the known-load case: a tyre file whose k_trd is 10 % off, identified with a profile at a known load, gives
  load intervals that cover the truth on profiles at other loads (and the wrong k_trd held fixed does not).
"""

import math

import numpy as np
import pytest

from ringfit.fit.estimate import EstimateSettings, estimate_load
from ringfit.fit.estimate.load import ring_spread
from ringfit.io.profiles import Profile
from ringfit.io.tyre import RingCovariance
from ringfit.params import table9
from ringfit.physics.contact import ContactSolver
from ringfit.physics.profile import ProfileModel, simulate_profile
from ringfit.synth.cases import coloured_noise

GEOMETRY, RING = table9()


def test_ring_spread_is_the_conditional_gaussian():
    # independent: the 2×2 conditional of a Gaussian, var(k | q) = Σkk − Σkq²/Σqq, E[k | q] moves by Σkq/Σqq
    cov = RingCovariance(("ei", "k_tread"), np.array([[0.04, 0.006], [0.006, 0.0025]]))
    spread = ring_spread(cov)
    assert spread["names"] == ("ei",)
    assert spread["k_tread_sd"] == pytest.approx(math.sqrt(0.0025 - 0.006**2 / 0.04), rel=1e-12)
    assert spread["shift"] == pytest.approx([0.006 / 0.04], rel=1e-12)
    # a σ given by the user wins: k_trd is not taken from the covariance
    user = ring_spread(cov, use_k_tread=False)
    assert user["k_tread_sd"] is None and user["shift"] == pytest.approx([0.0])
    # three parameters: against draws (the conditional variance is the residual variance of the regression)
    rng = np.random.default_rng(3)
    A = rng.normal(size=(3, 3))
    full = A @ A.T * 1e-3
    cov = RingCovariance(("kw", "k_tread", "ei"), full)
    spread = ring_spread(cov)
    x = rng.multivariate_normal(np.zeros(3), full, size=200000)
    q, k = x[:, [0, 2]], x[:, 1]
    beta = np.linalg.lstsq(q, k, rcond=None)[0]
    assert spread["shift"] == pytest.approx(beta, rel=0.02, abs=1e-3)
    assert spread["k_tread_sd"] == pytest.approx(np.std(k - q @ beta), rel=0.01)
    # parameters that are not ring fields are not propagated
    assert ring_spread(RingCovariance(("gain_1", "ei"), np.eye(2)))["names"] == ("ei",)


def _profile(ring, load, speed=50.0, seed=0, points=1000, noise=0.01):
    solver = ContactSolver(n_grid=1024, window_deg=40.0)
    prof = simulate_profile(ring, GEOMETRY, speed_kmh=speed, load_n=load, model=ProfileModel(), solver=solver,
                            n_points=points)
    rng = np.random.default_rng(seed)
    sigma = noise * float(np.std(prof.channels[0]))
    ch = prof.channels + np.stack([coloured_noise(rng, points, sigma, "pink") for _ in range(2)])
    cond = {k: v for k, v in prof.condition.items() if k != "load_n"}
    return Profile(prof.angle_deg, ch[0], ch[1], condition=cond, source=f"{load:g} N")


@pytest.mark.slow  # one estimate and six refits of its problem (~1 min CPU)
def test_propagated_sensitivities_match_refits_with_the_ring_moved():
    """∂ln load/∂ln θ of the propagation against refits of the same problem (same weights) with the ring moved
    by ±h and the k_trd prior's mean moved with it (k_trd given the rest): finite differences."""
    import dataclasses

    import equinox as eqx

    from ringfit.fit.engine import least_squares

    settings = EstimateSettings(grid_check=False)
    prof = _profile(RING, 3500.0)
    names = ("ei", "kw", "k_tread", "damping_ratio")
    sd = np.array([0.05, 0.04, 0.03, 0.1])
    corr = np.array([[1.0, 0.3, -0.5, 0.0], [0.3, 1.0, 0.2, 0.0], [-0.5, 0.2, 1.0, 0.1], [0.0, 0.0, 0.1, 1.0]])
    cov = RingCovariance(names, corr * np.outer(sd, sd))
    est = estimate_load(prof, GEOMETRY, RING, settings=settings, ring_covariance=cov)
    prop, fit = est.ring_propagation, est.fit
    spread = ring_spread(cov)
    assert prop["names"] == ["ei", "kw", "damping_ratio"]
    problem = fit.problem
    ik = list(problem.prior.names).index("k_tread")
    h = 0.005
    for j, name in enumerate(prop["names"]):
        ln_load = []
        for sign in (1, -1):
            ring = RING.replace(**{name: getattr(RING, name) * math.exp(sign * h)})
            mean = problem.prior.mean.copy()
            mean[ik] += sign * h * spread["shift"][j]
            data = eqx.tree_at(lambda a: a.ring, problem.data, ring)  # the same rows and weights, the ring moved
            moved = dataclasses.replace(problem, data=data, prior=dataclasses.replace(problem.prior, mean=mean))
            refit = least_squares(moved, fit.theta, fit.names, max_steps=200, rtol=1e-11, atol=1e-11)
            assert refit.converged
            ln_load.append(math.log(refit.values["load_n"]))
        fd = (ln_load[0] - ln_load[1]) / (2 * h)
        assert prop["sensitivity"][name] == pytest.approx(fd, rel=0.05, abs=0.005), name
    g = np.array([prop["sensitivity"][n] for n in prop["names"]])
    assert prop["load_sd_pct"] == pytest.approx(100 * math.sqrt(g @ spread["cov"] @ g), rel=1e-9)
    # the interval holds the statistical σ and the ring's in quadrature
    s_stat = math.sqrt(fit.covariance_log[list(fit.names).index("load_n"), list(fit.names).index("load_n")])
    s = math.log(est.hi / est.lo) / (2 * 1.959963984540054)
    assert s == pytest.approx(math.hypot(s_stat, prop["load_sd_pct"] / 100), rel=1e-6)
    assert est.to_record("x")["fit"]["ring_propagation"]["load_sd_pct"] == prop["load_sd_pct"]


@pytest.mark.slow  # six identifications and twelve estimates (several minutes CPU)
def test_known_load_identification_makes_the_intervals_cover_a_wrong_k_tread(tmp_path):
    """The tyre file's k_trd is 10 % off; identify (with profiles at known loads) corrects it and carries its
    uncertainty; the estimate at other loads covers the truth. With the file's wrong k_trd fixed, it does not."""
    from ringfit.fit.identify import identify, read_identify_folder
    from ringfit.io.tyre import read_tyre, write_tyre
    from ringfit.synth.identify import make_identify_case

    covered, covered_wrong, n = 0, 0, 6
    for seed in range(n):
        folder = tmp_path / f"case{seed}"
        truth = make_identify_case(folder, seed=500 + seed)
        ring_true = truth["ring_object"]
        tyre = read_tyre(folder / "tyre.toml")
        wrong = tyre.geometry, ring_true.replace(k_tread=ring_true.k_tread * 1.1)
        # the tyre file: every ring value, k_trd 10 % off (the identification starts there)
        write_tyre(tyre.with_ring(wrong[1]), folder / "tyre.toml", overwrite=True)
        ident = identify(read_identify_folder(folder))
        assert ident.converged
        rng = np.random.default_rng(seed)
        load = float(rng.uniform(2500.0, 5500.0))
        prof = _profile(ring_true, load, speed=float(rng.uniform(30.0, 80.0)), seed=seed)
        est = estimate_load(prof, tyre.geometry, ident.ring, ring_covariance=ident.covariance)
        covered += est.lo <= load <= est.hi
        fixed = estimate_load(prof, tyre.geometry, wrong[1])
        covered_wrong += fixed.lo <= load <= fixed.hi
    # P(≤ 4 of 6 | 95 %) = 3.3 %
    assert covered >= n - 1, f"{covered}/{n} covered"
    assert covered_wrong <= n // 2, f"the wrong k_trd held fixed covered {covered_wrong}/{n}: the test cannot fail"
