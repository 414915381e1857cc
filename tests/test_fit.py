"""Least-squares fit, the source study's procedure and identifiability."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.data import path as data_path
from ringfit.errors import InputError
from ringfit.fit.identifiability import identifiability, profile_natural_frequencies
from ringfit.fit.least_squares import fit_natural_frequencies, frequency_data
from ringfit.fit.source_procedure import source_study_fit
from ringfit.io.modes import ModeTable, read_mode_table
from ringfit.params import table9
from ringfit.physics.natural import natural_frequencies

GEO, RING = table9()
SSI = read_mode_table(data_path("free-ssi.modes.csv"))
N9 = np.arange(1, 10)


def synthetic_table(ring=RING, rel_noise=0.0, seed=0, std=None):
    f = np.asarray(natural_frequencies(ring, GEO, N9))
    rng = np.random.default_rng(seed)
    f = f * (1 + rel_noise * rng.standard_normal(f.shape))
    return ModeTable(freq_hz=f, n=N9, freq_std_hz=std if std is not None else None)


def test_source_procedure_reproduces_table9():
    """The thesis solved EI, kw, kv from (1,0), (3,0), (7,0) and stepped ρA: Table 9 must come back."""
    s = source_study_fit(SSI, GEO)
    assert float(s.ring.rho_a) == pytest.approx(2.715, abs=0.0015)
    assert float(s.ring.ei) == pytest.approx(0.9426, rel=2e-3)
    assert float(s.ring.kw) == pytest.approx(1.294e6, rel=2e-3)
    assert float(s.ring.kv) == pytest.approx(1.161e6, rel=2e-3)
    np.testing.assert_allclose(s.model_hz, [107.0, 119.8, 140.0, 164.7, 192.3, 222.0, 253.4, 286.2, 320.3], atol=0.05)


def test_recovers_known_parameters_noise_free():
    truth = RING.replace(rho_a=2.4, ei=1.7, kw=1.5e6, kv=0.9e6)
    res = fit_natural_frequencies(synthetic_table(truth), GEO, RING)
    assert res.converged, res.message
    for k in ("rho_a", "ei", "kw", "kv"):
        assert res.values[k] == pytest.approx(getattr(truth, k), rel=1e-6)
    # exact data: the estimated σ stops at its floor (1 ppm of f), the model meets every frequency far inside it
    assert np.max(np.abs(res.extra["model_hz"] / res.extra["freq_hz"] - 1)) < 1e-9
    assert res.extra["sigma_hz"] == pytest.approx(1e-6 * res.extra["freq_hz"], rel=1e-9)


def test_fixed_parameters_stay_fixed_and_mode_selection():
    res = fit_natural_frequencies(SSI, GEO, RING, free=("kw", "kv"), modes=range(1, 7))
    assert res.converged
    assert res.values["rho_a"] == RING.rho_a and res.values["ei"] == RING.ei
    assert res.n_data == 6 and list(res.extra["n"]) == [1, 2, 3, 4, 5, 6]
    assert res.jacobian.shape == (6 + 2, 2)


def test_default_sigma_is_one_percent_and_std_column_used():
    d = frequency_data(SSI)
    np.testing.assert_allclose(d.sigma_hz, 0.01 * SSI.freq_hz[:9])
    t = synthetic_table(std=np.full(9, 0.5))
    assert np.all(frequency_data(t).sigma_hz == 0.5) and frequency_data(t).sigma_source == "freq_std_hz"


def test_jacobian_matches_finite_differences():
    res = fit_natural_frequencies(SSI, GEO, RING, prior="physical")
    d = frequency_data(SSI)
    y = np.log([res.values[k] for k in res.names])
    sigma = res.extra["sigma_hz"]  # the σ the fit's rows are weighted by (the block's settled scale × 1 %)
    np.testing.assert_allclose(sigma, res.extra["noise_scale"] * d.sigma_hz, rtol=1e-12)

    def r(yy):
        ring = RING.replace(**dict(zip(res.names, np.exp(yy))))
        return (np.asarray(natural_frequencies(ring, GEO, d.n)) - d.freq_hz) / sigma

    h = 1e-6
    J = np.stack([(r(y + h * e) - r(y - h * e)) / (2 * h) for e in np.eye(4)], 1)
    np.testing.assert_allclose(res.jacobian[:9], J, rtol=1e-5, atol=1e-7)


def test_standard_errors_are_calibrated():
    """Monte Carlo: the fit's 95 % intervals cover the truth about 95 % of the time (2 free parameters)."""
    truth = RING
    hits, trials = 0, 120
    for seed in range(trials):
        t = synthetic_table(truth, rel_noise=0.01, seed=seed)
        res = fit_natural_frequencies(t, GEO, RING.replace(kw=1e6, kv=1e6), free=("kw", "kv"))
        lo, hi = res.interval("kw")
        hits += lo <= truth.kw <= hi
    assert 0.88 <= hits / trials <= 0.99


def test_prior_pulls_towards_its_median():
    res = fit_natural_frequencies(SSI, GEO, RING, prior={"ei": (3.0, 1e-4)})
    assert res.converged and res.values["ei"] == pytest.approx(3.0, rel=1e-3)


def test_unconstrained_fit_on_seed_table_is_flagged():
    """The issue's finding: on the free-tyre SSI table EI runs towards zero; the tool must say so."""
    res = fit_natural_frequencies(SSI, GEO, RING, prior="none")
    assert res.values["ei"] < 0.05  # driven far below any belt value
    ident = identifiability(res, profile=("ei",),
                            fit_again=profile_natural_frequencies(SSI, GEO, RING, res.names), grid_points=9)
    assert any("ei" in f for f in ident.flags)
    weakest = ident.eigenvectors[:, 0]
    assert abs(weakest[res.names.index("ei")]) > 0.9
    grid, chi2 = ident.profiles["ei"]
    small = grid < 1.0
    assert np.ptp(chi2[small]) < 3.84  # flat: no 95 % bound from below
    # with the physical prior the fit converges and EI stays within the prior's 95 % range
    res2 = fit_natural_frequencies(SSI, GEO, RING, prior="physical")
    assert res2.converged and 0.05 < res2.values["ei"] < 4.0


def test_non_convergence_is_reported_not_hidden():
    res = fit_natural_frequencies(SSI, GEO, RING.replace(ei=50.0, kw=5e6), max_steps=2)
    assert not res.converged and res.status == "max_steps_reached"
    assert any("did not converge" in f for f in res.flags)


def test_bad_arguments():
    with pytest.raises(InputError, match="unknown or non-positive parameter"):
        fit_natural_frequencies(SSI, GEO, RING, free=("ei", "stiffness"))
    with pytest.raises(InputError, match="n in \\[12\\]"):
        fit_natural_frequencies(SSI, GEO, RING, modes=[1, 2, 12])
    with pytest.raises(InputError, match="positive"):
        fit_natural_frequencies(SSI, GEO, RING.replace(ei=-1.0))


def test_no_recompilation_across_calls():
    from ringfit.fit import engine

    fit_natural_frequencies(SSI, GEO, RING)
    before = engine._solve._cache_size()
    for k in (1.0, 2.0, 3.0):
        fit_natural_frequencies(SSI, GEO, RING.replace(ei=k))
    assert engine._solve._cache_size() == before
    _ = jax  # noqa
