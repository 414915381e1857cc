"""fit-rolling reads profiles with the profile block's likelihood (issue 31 item 1): the same rows, nuisances, prior
and noise model as ``ringfit identify``'s profiles block, and it recovers a known truth within its intervals.

Truths are made here (the one forward model at a known ring, each run read through a known gain and angle offset,
coloured noise from :func:`ringfit.synth.cases.coloured_noise`); the identify side is
:class:`ringfit.fit.identify.JointResiduals` on profiles alone, driven by identify's pass loop written out below.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.fit.engine import Problem, least_squares, residuals
from ringfit.fit.free_block import SCALE_PASSES, hat_diagonal
from ringfit.fit.identify import JointArrays, JointResiduals, joint_coords
from ringfit.fit.least_squares import ring_vector
from ringfit.fit.priors import BOUNDS
from ringfit.fit.profile_block import (SENSOR_FIELDS, noise_from_residual, nuisance_names, nuisance_prior,
                                       nuisance_start, profile_rows, sensor_coords, sensor_names, sensor_prior,
                                       sensor_start)
from ringfit.fit.rolling import (RollingResiduals, block_rows, fit_rolling, rolling_coords, rolling_data,
                                 sample_rolling_posterior)
from ringfit.io.profiles import Profile
from ringfit.params import table9
from ringfit.physics.contact import ContactSolver, as_traced
from ringfit.physics.profile import ProfileModel, flat_or_drum, full_band
from ringfit.physics.sensor import shift_angle
from ringfit.synth.cases import coloured_noise
from ringfit.synth.profiles import synthetic_profile

GEOMETRY, RING = table9()
TRUTH = RING.replace(k_tread=25e6, damping_ratio=0.03)
SPEEDS = (20.0, 30.0, 40.0, 50.0)
DRUM = 1.2192
SOLVER = ContactSolver()


def clean_profiles():
    """The four drum profiles of the truth, noise-free (the one forward model)."""
    return [synthetic_profile(TRUTH, GEOMETRY, v, drum_diameter_m=DRUM) for v in SPEEDS]


CLEAN = None


def make_case(seed: int, colour: str = "pink"):
    """Four profiles of the truth, each read through its own gain and angle offset (one sensor: a common gain and
    offset plus a small per-run part), with coloured noise of ~1 % of the radial channel's RMS. Returns the
    profiles and the true gains and offsets [rad]."""
    global CLEAN
    if CLEAN is None:
        CLEAN = clean_profiles()
    rng = np.random.default_rng(seed)
    common_gain, common_offset = math.exp(rng.normal(0.0, 0.1)), math.radians(rng.uniform(-1.0, 1.0))
    gains = common_gain * np.exp(rng.normal(0.0, 0.02, len(SPEEDS)))
    offsets = common_offset + math.radians(0.3) * rng.normal(size=len(SPEEDS))
    out = []
    for p, g, a in zip(CLEAN, gains, offsets):
        ch = np.stack([p.acc_radial_ms2, p.acc_tangential_ms2])
        # the recorded angle α = φ − offset: the reading at α is the model at α + offset (docs/physics.md §5 layer 6)
        ch = g * np.asarray(shift_angle(jnp.asarray(ch), a))
        sigma = 0.01 * float(np.std(ch[0]))
        n = ch.shape[-1]
        ch = ch + np.stack([coloured_noise(rng, n, sigma, colour), coloured_noise(rng, n, sigma, colour)])
        out.append(Profile(p.angle_deg, ch[0], ch[1], condition=p.condition))
    return out, gains, offsets


def joint_arrays(rows, sigma):
    """identify's JointArrays holding the profiles block only (no free table)."""
    empty = np.zeros(0)
    P = rows["P"]
    return as_traced(JointArrays(
        geometry=GEOMETRY, f_n=empty, f_freq=empty, f_sigma=np.ones(0), d_zeta=None, d_sigma=None, l_n=None,
        l_sin=None, l_table=None, l_freq=None, l_sigma=None, l_load=None, l_roads=None, p_omega=rows["omega"],
        p_load=rows["load"], p_roads=flat_or_drum(rows["drum"], P), p_band=full_band(P, SOLVER.n_grid),
        p_measured=rows["measured"], p_sigma=sigma))


def identify_profiles_only(profiles, ring, sensor=False):
    """identify's profiles block alone, the ring but k_tread held: identify's pass loop (ringfit/fit/identify.py
    ``_identify``) written out — fit, then σ from the fit's residual, until a converged pass after the first;
    with ``sensor`` each run's sensor nuisances as identify adds them (its default)."""
    rows = profile_rows(profiles, GEOMETRY, ring, SOLVER)
    P = rows["P"]
    model = JointResiduals(P, SOLVER, ProfileModel(), k_top=rows["k_top"], sensor=sensor)
    free = ("k_tread",) + nuisance_names(P) + (sensor_names(P) if sensor else ())
    theta = np.concatenate([ring_vector(ring), nuisance_start(P)] + ([sensor_start(P)] if sensor else []))
    coords = joint_coords(P) + (sensor_coords(P) if sensor else ())
    prior = nuisance_prior(P).combine(sensor_prior(P)) if sensor else nuisance_prior(P)
    sigma = rows["sigma"]
    for passes in range(1, SCALE_PASSES + 1):
        problem = Problem(model, joint_arrays(rows, sigma), coords, prior=prior, plausible=BOUNDS)
        fit = least_squares(problem, theta, free, max_steps=256 if sensor else 64, rtol=1e-8, atol=1e-8)
        if fit.converged:
            theta = fit.theta.copy()
        m = rows["measured"].size
        sigma = noise_from_residual(fit.residuals[:m].reshape(rows["measured"].shape) * sigma,
                                    hat_diagonal(fit.jacobian)[:m])
        if fit.converged and passes > 1:
            break
    return fit


@pytest.fixture(scope="module")
def case():
    return make_case(3)


@pytest.mark.parametrize("sensor", [False, True])
def test_rows_and_weighted_residuals_are_identifys(case, sensor):
    """Same profiles, same θ, same σ: fit-rolling's rows are identify's profile rows, number for number — with each
    run's sensor nuisances too (tilt, IEPE corner, liner offset, tangential gain away from their priors' centres)."""
    profiles, gains, offsets = case
    rows = profile_rows(profiles, GEOMETRY, RING, SOLVER)
    mine = block_rows(rolling_data(profiles, GEOMETRY, RING, solver=SOLVER))
    assert mine["k_top"] == rows["k_top"]
    np.testing.assert_array_equal(mine["measured"], rows["measured"])
    np.testing.assert_array_equal(mine["sigma"], rows["sigma"])
    P = rows["P"]
    theta = np.concatenate([ring_vector(TRUTH), np.ravel(np.column_stack([offsets, gains]))])
    rng = np.random.default_rng(0)
    if sensor:  # per run: tilt gain, corner [Hz], liner offset [m], tangential gain
        theta = np.concatenate([theta, np.ravel([[0.3 + 0.1 * i, 0.4 + 0.2 * i, 1e-3 * (i - 1), 1.0 + 0.01 * i]
                                                 for i in range(P)])])
        assert len(SENSOR_FIELDS) == 4
    sigma = rows["sigma"] * np.exp(rng.normal(0.0, 0.3, rows["sigma"].shape))  # any σ, the same to both
    joint = Problem(JointResiduals(P, SOLVER, ProfileModel(), k_top=rows["k_top"], sensor=sensor),
                    joint_arrays(rows, sigma), joint_coords(P) + (sensor_coords(P) if sensor else ()))
    from ringfit.fit.rolling import _arrays

    data = rolling_data(profiles, GEOMETRY, RING, solver=SOLVER)
    roll = Problem(RollingResiduals(P, ProfileModel(), SOLVER, k_top=mine["k_top"], sensor=sensor),
                   _arrays(data, GEOMETRY, mine["measured"], sigma, SOLVER.n_grid), rolling_coords(P, sensor))
    r_joint, _ = residuals(joint, theta)
    r_roll, _ = residuals(roll, theta)
    assert r_roll.shape == r_joint.shape == (rows["measured"].size,)
    np.testing.assert_allclose(r_roll, r_joint, rtol=1e-9, atol=1e-9 * float(np.max(np.abs(r_joint))))
    # at the truth the weighted rows are the noise: far below the model's own size (a sanity check of θ's order;
    # the sensor case's θ reads through a sensor the data do not have)
    model_only = np.asarray(rows["measured"]) / sigma
    assert (np.sqrt(np.mean(r_roll**2)) < 0.1 * np.sqrt(np.mean(model_only**2))) != sensor


@pytest.mark.slow
def test_same_tread_stiffness_gains_and_offsets_as_identify(case):
    """Profiles only, the ring held at the same values: fit-rolling and identify's profiles block (its passes) find
    the same k_tread, gains and offsets to the solver's tolerance."""
    profiles, _, _ = case
    start = RING.replace(damping_ratio=0.03)
    roll = fit_rolling(profiles, GEOMETRY, start, sensor_nuisances=False)
    joint = identify_profiles_only(profiles, start)
    assert roll.converged and joint.converged
    assert roll.extra["passes"] == 2
    assert roll.values["k_tread"] == pytest.approx(joint.values["k_tread"], rel=1e-6)
    for name in nuisance_names(len(profiles)):
        assert roll.values[name] == pytest.approx(joint.values[name], rel=1e-6, abs=1e-8)
        assert roll.stderr[name] == pytest.approx(joint.stderr[name], rel=1e-4)
    assert roll.stderr["k_tread"] == pytest.approx(joint.stderr["k_tread"], rel=1e-4)


@pytest.mark.slow
def test_with_the_sensors_nuisances_the_same_answer_as_identify(case):
    """fit-rolling with each run's sensor nuisances (``sensor_nuisances``) and identify's profiles block with its
    default ``sensor``: the same k_tread, gains, offsets and sensor nuisances, and the same intervals."""
    profiles, _, _ = case
    start = RING.replace(damping_ratio=0.03)
    roll = fit_rolling(profiles, GEOMETRY, start, sensor_nuisances=True)
    joint = identify_profiles_only(profiles, start, sensor=True)
    assert roll.converged and joint.converged
    P = len(profiles)
    assert set(roll.names) == {"k_tread", *nuisance_names(P), *sensor_names(P)}
    _same_to_convergence(roll, joint, ("k_tread",) + nuisance_names(P) + sensor_names(P))
    np.testing.assert_allclose(roll.extra["sensor"]["corner_hz"], [roll.values[f"corner_hz_{i + 1}"] for i in range(P)])


def _same_to_convergence(roll, joint, names):
    """Each parameter the same to the fits' convergence (``least_squares(dtol=DECREMENT_TOL)``: each optimum within
    ~1e-3 standard errors of the exact one, docs/physics.md §11 *convergence*): values within 1e-2 of a standard
    error, standard errors within 1e-3."""
    for name in names:
        assert abs(roll.values[name] - joint.values[name]) <= 1e-2 * joint.stderr[name], name
        assert roll.stderr[name] == pytest.approx(joint.stderr[name], rel=1e-3), name


def _inside(fit, gains, offsets, z):
    """Which of (k_tread, each gain, each offset) lie within ±z standard errors of the fit."""
    out = [abs(fit.values["k_tread"] - TRUTH.k_tread) <= z * fit.stderr["k_tread"]]
    for i, (g, a) in enumerate(zip(gains, offsets)):
        out.append(abs(fit.values[f"gain_{i + 1}"] - g) <= z * fit.stderr[f"gain_{i + 1}"])
        out.append(abs(fit.values[f"angle_offset_{i + 1}"] - a) <= z * fit.stderr[f"angle_offset_{i + 1}"])
    return np.array(out)


def test_recovers_tread_stiffness_gains_and_offsets_under_coloured_noise(case):
    profiles, gains, offsets = case
    fit = fit_rolling(profiles, GEOMETRY, RING.replace(damping_ratio=0.03))
    assert fit.converged, fit.message
    assert set(fit.names) == {"k_tread", *nuisance_names(4), *sensor_names(4)}
    # one case: every one of the 9 within 3 standard errors (P(a miss) ≈ 2.4 % for honest intervals)
    assert _inside(fit, gains, offsets, 3.0).all()
    assert abs(fit.values["k_tread"] / TRUTH.k_tread - 1) < 0.01
    ex = fit.extra
    assert ex["sigma_ms2"].shape == (4, 2, ex["harmonics"].size) and ex["harmonics"][0] == 2
    np.testing.assert_allclose(ex["gain"], gains, atol=4 * ex["gain_sd"].max())
    assert ex["model"].shape == ex["measured"].shape == (4, 2, SOLVER.n_grid)


@pytest.mark.slow
@pytest.mark.parametrize("colour", ["pink", "red"])
def test_intervals_cover_the_truth_over_many_cases(colour):
    """Coverage of the 95 % intervals of k_tread, gains and offsets over 10 random cases (90 intervals): at least
    80 inside (for 95 % coverage, P(≤ 79 of 90) ≈ 0.3 %)."""
    inside = []
    for seed in range(100, 110):
        profiles, gains, offsets = make_case(seed, colour)
        fit = fit_rolling(profiles, GEOMETRY, RING.replace(damping_ratio=0.03))
        assert fit.converged, fit.message
        inside.append(_inside(fit, gains, offsets, 1.959964))
    inside = np.concatenate(inside)
    assert inside.sum() >= 80, f"{inside.sum()} of {inside.size} inside their 95 % intervals"


@pytest.mark.slow
def test_posterior_samples_the_blocks_likelihood(case):
    """The posterior of k_tread and the nuisances: its spread is the fit's standard error (the weighted rows and the
    prior are the fit's), and it holds the truth."""
    profiles, gains, offsets = case
    fit = fit_rolling(profiles, GEOMETRY, RING.replace(damping_ratio=0.03))
    post = sample_rolling_posterior(fit, steps=300, seed=2)
    rows = {r["name"]: r for r in post.summary_table(level=0.6827)}
    for name, truth in (("k_tread", TRUTH.k_tread), ("gain_2", gains[1]), ("angle_offset_3", offsets[2])):
        half = (rows[name]["hi"] - rows[name]["lo"]) / 2
        assert half == pytest.approx(fit.stderr[name], rel=0.35), name
        assert abs(rows[name]["median"] - truth) < 4 * half, name


def test_noise_pooled_over_many_series_counts_their_degrees_of_freedom():
    """σ from the RMS of many residual series (a recording's revolutions): their degrees of freedom add, so the
    ν/(ν − 4) widening meant for one series' neighbours (×1.33 at ν = 16) nearly vanishes (×1.016 at 16 series).
    Checked on white noise of known σ = 1: the mean σ̂² is 1 to 4 %; with ``series=1`` (the negative
    control) σ̂² reads ≥ 25 % high."""
    rng = np.random.default_rng(5)
    H, n = 60, 16
    pooled, single = [], []
    for _ in range(200):
        rows = rng.standard_normal((n, 2 * H))
        rms = np.sqrt(np.mean(rows**2, axis=0))
        pooled.append(noise_from_residual(rms, np.zeros(2 * H), series=n) ** 2)
        single.append(noise_from_residual(rms, np.zeros(2 * H)) ** 2)
    # interior harmonics (the power law's ends are fitted on one side only)
    inner = np.r_[10 : H - 10, H + 10 : 2 * H - 10]
    assert abs(np.mean(np.asarray(pooled)[:, inner]) - 1.0) < 0.04
    assert np.mean(np.asarray(single)[:, inner]) > 1.25


@pytest.mark.slow
def test_a_sensor_that_tilts_and_high_passes_is_read_through_its_nuisances():
    """Profiles read by a sensor with a typical tilt (γ 0.6), IEPE corner (0.8 Hz) and liner offset (2 mm): the
    plain reading (gain and offset only) puts k_tread far off and calls it converged; fit-rolling's default reading,
    through each run's sensor nuisances, holds the truth within 3 standard errors and reads the sensor back."""
    from ringfit.physics.sensor import SensorModel

    sensor = SensorModel(tilt_gain=0.6, corner_hz=0.8, offset=2e-3)
    rng = np.random.default_rng(5)
    profiles = []
    for v in SPEEDS:
        p = synthetic_profile(TRUTH, GEOMETRY, v, drum_diameter_m=DRUM, sensor=sensor)
        ch = np.stack([p.acc_radial_ms2, p.acc_tangential_ms2])
        s = 0.01 * float(np.std(ch[0]))
        ch = ch + np.stack([coloured_noise(rng, ch.shape[-1], s, "pink") for _ in range(2)])
        profiles.append(Profile(p.angle_deg, ch[0], ch[1], condition=p.condition))
    start = RING.replace(damping_ratio=0.03)
    plain = fit_rolling(profiles, GEOMETRY, start, sensor_nuisances=False)
    read = fit_rolling(profiles, GEOMETRY, start)
    assert read.converged, read.message
    assert abs(plain.values["k_tread"] - TRUTH.k_tread) > 10 * plain.stderr["k_tread"]
    assert abs(read.values["k_tread"] - TRUTH.k_tread) < 3 * read.stderr["k_tread"]
    sens = read.extra["sensor"]
    np.testing.assert_allclose(sens["tilt_gain"], 0.6, atol=0.05)
    np.testing.assert_allclose(sens["corner_hz"], 0.8, rtol=0.1)
    np.testing.assert_allclose(sens["liner_offset_m"], 2e-3, atol=2e-4)
