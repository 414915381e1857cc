"""The free-modes block's noise model (ringfit.fit.free_block, docs/physics.md §11 "Noise per block"): one model for
`ringfit fit` and `ringfit identify` — same table, same ring, same interval; the scale against hand computations;
a stated σ only scaled up; the intervals' coverage over many tables."""

import math
import shutil

import numpy as np
import pytest
from scipy import stats

from ringfit.data import path as data_path
from ringfit.fit.free_block import block_scale, hat_diagonal
from ringfit.fit.least_squares import fit_natural_frequencies
from ringfit.io.modes import ModeTable, write_mode_table
from ringfit.params import table9
from ringfit.physics.natural import natural_frequencies

GEO, RING = table9()
N9 = np.arange(1, 10)
TRUTH = RING.replace(rho_a=2.72, ei=1.02, kw=1.39e6, kv=1.13e6)


def _table(rel_noise, seed, std=None, ring=TRUTH):
    f = np.asarray(natural_frequencies(ring, GEO, N9.astype(float)))
    f = f * (1 + rel_noise * np.random.default_rng(seed).standard_normal(f.size))
    return ModeTable(freq_hz=f, n=N9, freq_std_hz=None if std is None else std * f, condition={"state": "free"})


# ----------------------------------------------------------------------------- the scale by hand


def test_block_scale_of_a_full_rank_linear_block_is_the_residual_over_m_minus_k():
    """Data rows alone, J of full rank k: tr H = k, so s² = Σr²/(m − k) (the textbook unbiased σ²)."""
    rng = np.random.default_rng(0)
    m, k = 9, 4
    J = rng.standard_normal((m, k))
    r = rng.standard_normal(m)
    H = J @ np.linalg.inv(J.T @ J) @ J.T  # written out, not the module's SVD
    np.testing.assert_allclose(hat_diagonal(J), np.diag(H), atol=1e-12)
    s, dof = block_scale(r, np.diag(H), stated=False)
    assert dof == pytest.approx(m - k, abs=1e-10)
    assert s == pytest.approx(math.sqrt(r @ r / (m - k)), rel=1e-12)


def test_a_prior_row_leaves_the_data_more_degrees_of_freedom():
    """One level μ seen by m rows of weight 1 and a prior row of weight w: each data row's leverage is 1/(m + w²)
    (closed form), so the block keeps m − m/(m + w²) degrees of freedom."""
    m, w = 6, 2.0
    J = np.concatenate([np.ones((m, 1)), [[w]]])
    h = hat_diagonal(J)
    np.testing.assert_allclose(h[:m], 1.0 / (m + w**2), rtol=1e-12)
    r = np.array([0.3, -1.2, 0.5, 0.9, -0.4, 1.1])
    s, dof = block_scale(r, h[:m], stated=False)
    assert dof == pytest.approx(m - m / (m + w**2), rel=1e-12)
    assert s == pytest.approx(math.sqrt(r @ r / (m - m / (m + w**2))), rel=1e-12)


def test_fit_scale_without_a_prior_is_the_rms_relative_misfit_over_the_starting_sigma():
    """No prior: the optimum does not depend on a common σ scale, 4 parameters of full rank take 4 degrees of
    freedom, so the settled scale is √(Σ((f_model − f)/(0.01 f))² / (9 − 4)) — from the model frequencies alone."""
    fit = fit_natural_frequencies(_table(0.003, 1), GEO, RING, prior="none")
    assert fit.converged
    rel = (fit.extra["model_hz"] - fit.extra["freq_hz"]) / (0.01 * fit.extra["freq_hz"])
    expect = math.sqrt(float(rel @ rel) / (9 - 4))
    assert fit.extra["noise_scale"] == pytest.approx(expect, rel=1e-6)
    assert fit.extra["noise_dof"] == pytest.approx(5.0, abs=1e-6)
    np.testing.assert_allclose(fit.extra["sigma_hz"], expect * 0.01 * fit.extra["freq_hz"], rtol=1e-6)
    # χ² of the settled rows is the degrees of freedom left; the widening is t_{5,0.975}/z = 2.5706/1.96
    assert fit.chi2 == pytest.approx(5.0, rel=1e-5)
    assert fit.extra["t_widening"] == pytest.approx(2.570581835636314 / 1.959963984540054, rel=1e-9)


@pytest.mark.parametrize("seed", [2, 7])
def test_the_interval_is_the_widened_one(seed):
    """The covariance is the Gauss–Newton one of the settled rows with the data rows divided by t/z · √κ: with no
    prior, every variance is (t/z)²·κ times the unwidened one (computed here from the fit's own Jacobian), and κ is
    the held-out ratio of round-robin folds written out here (r_Fᵀ H_FF (I − H_FF)⁻¹ r_F over tr H_FF)."""
    fit = fit_natural_frequencies(_table(0.003, seed), GEO, RING, free=("rho_a", "kw", "kv"), prior="none")
    J = fit.jacobian[: fit.n_data]
    r = fit.residuals
    plain = np.linalg.inv(J.T @ J)
    H = J @ plain @ J.T
    D = T = 0.0
    for F in (np.arange(0, 9, 3), np.arange(1, 9, 3), np.arange(2, 9, 3)):
        HFF = H[np.ix_(F, F)]
        D += float(r[F] @ HFF @ np.linalg.solve(np.eye(F.size) - HFF, r[F]))
        T += float(np.trace(HFF))
    kappa = max(1.0, D / T)
    assert 1.0 + fit.extra["discrepancy"] == pytest.approx(kappa, rel=1e-8)
    widen2 = fit.extra["t_widening"] ** 2 * kappa
    np.testing.assert_allclose(fit.covariance_log, plain * widen2, rtol=1e-8)
    np.testing.assert_allclose(fit.extra["row_scale"][:9], math.sqrt(widen2), rtol=1e-12)
    for j, k in enumerate(fit.names):
        assert fit.stderr[k] == pytest.approx(fit.values[k] * math.sqrt(plain[j, j] * widen2), rel=1e-8)


# ----------------------------------------------------------------------------- a stated σ


def test_a_stated_sigma_that_is_too_small_is_scaled_up():
    """freq_std_hz 0.05 % of f on 0.5 % noise: the scale is the misfit over the stated σ (no prior: as above),
    and the intervals are widened by Student's t of its 5 degrees of freedom."""
    table = _table(0.005, 3, std=0.0005)
    fit = fit_natural_frequencies(table, GEO, RING, prior="none")
    assert fit.converged
    z = (fit.extra["model_hz"] - table.freq_hz) / table.freq_std_hz
    expect = math.sqrt(float(z @ z) / 5)
    assert expect > 3  # the test's premise: the stated σ is far too small
    assert fit.extra["noise_scale"] == pytest.approx(expect, rel=1e-6)
    np.testing.assert_allclose(fit.extra["sigma_hz"], expect * table.freq_std_hz, rtol=1e-6)
    assert fit.extra["noise_dof"] == pytest.approx(5.0, abs=1e-6) and fit.extra["t_widening"] > 1.3
    assert fit.extra["sigma_source"] == "freq_std_hz"


def test_a_stated_sigma_that_is_too_large_is_kept():
    """freq_std_hz 2 % of f on 0.1 % noise: the stated σ holds — one fit, σ as stated, no widening."""
    table = _table(0.001, 4, std=0.02)
    fit = fit_natural_frequencies(table, GEO, RING, prior="physical")
    assert fit.converged
    np.testing.assert_array_equal(fit.extra["sigma_hz"], table.freq_std_hz)
    assert fit.extra["noise_scale"] == 1.0 and fit.extra["t_widening"] == 1.0
    assert math.isinf(fit.extra["noise_dof"]) and fit.extra["scale_passes"] == 1
    # the same as the known-σ fit
    known = fit_natural_frequencies(table, GEO, RING, prior="physical", noise="fixed")
    for k in fit.names:
        assert fit.values[k] == known.values[k] and fit.stderr[k] == known.stderr[k]


def test_a_stated_relative_sigma_is_stated_like_freq_std_hz():
    """`--default-std` is a statement: 2 % on 0.1 % noise holds; 0.01 % is scaled up to the misfit."""
    table = _table(0.001, 5)
    big = fit_natural_frequencies(table, GEO, RING, prior="none", default_relative_std=0.02)
    assert big.extra["noise_scale"] == 1.0 and big.extra["sigma_source"] == "stated 2.0% of frequency"
    small = fit_natural_frequencies(table, GEO, RING, prior="none", default_relative_std=1e-4)
    z = (small.extra["model_hz"] - table.freq_hz) / (1e-4 * table.freq_hz)
    assert small.extra["noise_scale"] == pytest.approx(math.sqrt(float(z @ z) / 5), rel=1e-6)
    assert small.extra["noise_scale"] > 1


def test_a_bad_noise_model_name_is_refused():
    from ringfit.errors import InputError

    with pytest.raises(InputError, match="noise model 'robust'"):
        fit_natural_frequencies(_table(0.001, 0), GEO, RING, noise="robust")


# ----------------------------------------------------------------------------- same data, same answer


def _free_only_folder(tmp_path, table):
    folder = tmp_path / "case"
    folder.mkdir()
    shutil.copy(data_path("table9.tyre.toml"), folder / "tyre.toml")
    write_mode_table(table, folder / "free.modes.csv")
    return folder


@pytest.mark.parametrize("std", [None, 0.0002, 0.02], ids=["no-std", "std-too-small", "std-too-large"])
def test_fit_and_identify_give_the_same_ring_and_interval_on_a_free_table(tmp_path, std):
    """Issue 31 item 3: a free table alone (no damping) through `ringfit fit` (physical prior, its default) and
    `ringfit identify` (which uses the same EI prior when it has only free modes): the same ring, the same 95 %
    intervals, the same noise scale, widening and discrepancy ratio."""
    from ringfit.fit.identify import identify, read_identify_folder

    table = _table(0.002, 6, std=std)
    fit = fit_natural_frequencies(table, GEO, RING, prior="physical")
    ident = identify(read_identify_folder(_free_only_folder(tmp_path, table)))
    assert fit.converged and ident.converged
    assert ident.free == ("rho_a", "ei", "kw", "kv")
    cov = ident.covariance
    for j, k in enumerate(fit.names):
        assert float(getattr(ident.ring, k)) == pytest.approx(fit.values[k], rel=1e-7)
        var_i = cov.ln[cov.names.index(k), cov.names.index(k)]
        assert math.sqrt(var_i) == pytest.approx(math.sqrt(fit.covariance_log[j, j]), rel=1e-5)
        lo, hi = fit.interval(k)
        sd = math.sqrt(var_i)
        v = float(getattr(ident.ring, k))
        assert (v * math.exp(-1.959963984540054 * sd), v * math.exp(1.959963984540054 * sd)) == pytest.approx(
            (lo, hi), rel=1e-6)
    block = ident.blocks["free modes"]
    assert block["t_widening"] == pytest.approx(fit.extra["t_widening"], rel=1e-6)
    assert block["discrepancy"] == pytest.approx(fit.extra["discrepancy"], rel=1e-5, abs=1e-9)
    if std == 0.02:
        assert block["sigma_scale"] == 1.0 == fit.extra["noise_scale"]
    else:  # identify reports the scale after its last pass's update (≤ SCALE_TOLERANCE from the one its fit used)
        assert block["sigma_scale"] == pytest.approx(fit.extra["noise_scale"], rel=0.02)


# ----------------------------------------------------------------------------- coverage


def _clopper_pearson(k, n, level=0.95):
    a = 1 - level
    lo = stats.beta.ppf(a / 2, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(1 - a / 2, k + 1, n - k) if k < n else 1.0
    return lo, hi


def test_the_fits_95_percent_intervals_cover_the_truth_over_many_free_tables():
    """400 free tables of eq. 18 at a known ring with 0.3 % Gaussian noise, no freq_std_hz (the σ unknown to the
    fit, its start 1 %): ρA, k_w, k_v free (EI held at the truth: a free tyre's modes barely pin it, docs §2.1),
    no prior. Each parameter's 95 % interval covers the truth 90–98 % of the time, with its Clopper–Pearson
    interval holding 95 %. Without the widening the rate would be that of t_6 inside ±1.96, ~90 %: the test can
    tell the two apart."""
    n, free = 400, ("rho_a", "kw", "kv")
    start = TRUTH.replace(rho_a=2.6, kw=1.3e6, kv=1.2e6)
    hits = {k: 0 for k in free}
    plain_hits = 0
    for seed in range(n):
        fit = fit_natural_frequencies(_table(0.003, 1000 + seed), GEO, start, free=free, prior="none")
        assert fit.converged
        for j, k in enumerate(free):
            t = math.log(getattr(TRUTH, k))
            sd = math.sqrt(fit.covariance_log[j, j])
            hits[k] += abs(math.log(fit.values[k]) - t) <= 1.959963984540054 * sd
            plain_hits += abs(math.log(fit.values[k]) - t) <= 1.959963984540054 * sd / fit.extra["row_scale"][0]
    for k in free:
        lo, hi = _clopper_pearson(hits[k], n)
        assert 0.90 <= hits[k] / n <= 0.98 and lo <= 0.95 <= hi, (k, hits[k], lo, hi)
    assert plain_hits / (3 * n) < 0.93  # the widening matters


def test_noise_passes_stop_rule():
    """The one pass loop (free block, profile block, identify): scripted fits and noise changes."""
    from types import SimpleNamespace

    from ringfit.fit.free_block import SCALE_PASSES, SCALE_TOLERANCE, noise_passes

    def run(converged, changes, holds=None):
        log = []
        holds = holds or [False] * len(changes)

        def fit_once():
            i = len(log)
            log.append(i)
            return SimpleNamespace(converged=converged[i], status="converged" if converged[i] else "max_steps")

        def renoise(fit):
            i = log[-1]
            return changes[i], holds[i]

        fit, passes = noise_passes(fit_once, renoise)
        assert passes == len(log)
        return passes

    small, big = 0.5 * SCALE_TOLERANCE, 10 * SCALE_TOLERANCE
    assert run([True] * 4, [big, small, small, small]) == 2  # settles on the refit
    assert run([True] * 4, [small] * 4) == 2  # never stops on the first pass: its σ was only a start
    assert run([True] * 4, [big] * 4, holds=[True, False, False, False]) == 1  # a stated σ that held: no refit
    assert run([False, False, True, True], [small] * 4) == 3  # an unconverged fit is refitted
    assert run([True] * 4, [big] * 4) == SCALE_PASSES  # at most SCALE_PASSES fits
    assert run([True, False, False, True], [big, small, small, small]) == 4 == SCALE_PASSES
