"""Tread-stiffness fit to rolling profiles: known synthetic truth, the source study's sweep, posterior."""

import math

import numpy as np
import pytest

import ringfit.fit.engine as engine
import ringfit.fit.posterior as posterior
from ringfit.errors import InputError
from ringfit.fit.rolling import (
    fit_rolling,
    rolling_data,
    sample_rolling_posterior,
    sum_of_squares,
    tread_stiffness_sweep,
)
from ringfit.io.profiles import Profile
from ringfit.params import table9
from ringfit.physics.sensor import shift_angle
from ringfit.synth.profiles import synthetic_profile

GEOMETRY, RING = table9()
TRUTH = RING.replace(k_tread=25e6, damping_ratio=0.03)
SPEEDS = (20.0, 30.0, 40.0, 50.0)
NOISE = 2.0  # m/s², white, per sample of a 1024-point profile
DRUM = 1.2192


def compilations(jitted):
    """Executables compiled so far for a ``jax.jit`` function."""
    return jitted._cache_size()


@pytest.fixture(scope="module")
def profiles():
    return [synthetic_profile(TRUTH, GEOMETRY, v, drum_diameter_m=DRUM, noise_ms2=NOISE, seed=i)
            for i, v in enumerate(SPEEDS)]


@pytest.fixture(scope="module")
def fit4(profiles):
    return fit_rolling(profiles, GEOMETRY, RING.replace(damping_ratio=0.03))


def test_recovers_tread_stiffness_from_four_speeds(fit4):
    assert fit4.converged
    k = fit4.values["k_tread"]
    assert abs(k - 25e6) < 3 * fit4.stderr["k_tread"] + 1e-3 * 25e6
    assert abs(k / 25e6 - 1) < 0.01
    # the noise model's σ per harmonic row: the band-limited white noise (1024 → 512 points halves the variance;
    # a harmonic row of white noise of σ per sample has variance σ²), widened by ν/(ν − 4) for weights estimated
    # from ν = 16 residual parts (8 neighbouring harmonics, real and imaginary) — the interior harmonics'
    sigma = fit4.extra["sigma_ms2"]
    assert sigma.shape == (4, 2, fit4.extra["harmonics"].size)
    interior = sigma[..., 4:-4]
    assert np.median(interior) == pytest.approx(NOISE / math.sqrt(2) * math.sqrt(16 / 12), rel=0.05)
    assert fit4.extra["model"].shape == (4, 2, 512)
    # one sensor, no gain or offset in the data: every run's gain 1 and offset 0 within its error
    assert np.all(np.abs(fit4.extra["gain"] - 1) < 4 * fit4.extra["gain_sd"])
    assert np.all(np.abs(fit4.extra["angle_offset_deg"]) < 4 * fit4.extra["angle_offset_sd_deg"])


def test_refit_reuses_the_compiled_fit(profiles, fit4):
    """Another start and other data of the same structure (other speeds, other noise): nothing is traced or
    compiled (JAX's own monitoring events, tests/test_no_retrace.py), the engine's solve included."""
    from test_no_retrace import COMPILE, TRACE, count_traces

    before = compilations(engine._solve)
    other = [synthetic_profile(TRUTH, GEOMETRY, v, drum_diameter_m=DRUM, noise_ms2=NOISE, seed=10 + i)
             for i, v in enumerate((15.0, 25.0, 35.0, 60.0))]
    with count_traces() as seen:
        moved = fit_rolling(other, GEOMETRY, RING.replace(k_tread=15e6, damping_ratio=0.03))
    assert seen == {TRACE: 0, COMPILE: 0}
    assert moved.converged and moved.values["k_tread"] == pytest.approx(25e6, rel=0.01)
    res = fit_rolling(profiles[::-1], GEOMETRY, RING.replace(k_tread=15e6, damping_ratio=0.03))
    assert compilations(engine._solve) == before
    assert res.converged and res.values["k_tread"] == pytest.approx(fit4.values["k_tread"], rel=1e-4)


@pytest.mark.slow
def test_recovers_damping_and_a_common_angle_offset(profiles):
    """Every run recorded 0.5° late (one sensor): each run's offset found, with damping and k_tread."""
    offset = math.radians(0.5)
    shifted = []
    for p in profiles:  # recorded angle α = φ − offset ⇒ reading at α is the model at α + offset
        ch = np.asarray(shift_angle(np.stack([p.acc_radial_ms2, p.acc_tangential_ms2]), offset))
        shifted.append(Profile(p.angle_deg, ch[0], ch[1], condition=p.condition))
    res = fit_rolling(shifted, GEOMETRY, RING, free=("k_tread", "damping_ratio"))
    assert res.converged
    assert res.values["k_tread"] == pytest.approx(25e6, rel=0.01)
    assert abs(res.values["damping_ratio"] - 0.03) < 4 * res.stderr["damping_ratio"]
    for i in range(len(profiles)):
        name = f"angle_offset_{i + 1}"
        assert abs(res.values[name] - offset) < 4 * res.stderr[name]
        assert res.stderr[name] < math.radians(0.1)


@pytest.mark.slow
def test_matches_the_source_sweep_with_five_times_fewer_evaluations(profiles):
    """Source §5.3: sweep k_trd, keep the lowest error at 50 km/h. Grid 10–40 MN/m² in 0.1 MN/m² steps."""
    at50 = [p for p in profiles if p.speed_kmh == 50.0]
    before = compilations(engine._batched_sum_of_squares)
    sweep = tread_stiffness_sweep(at50, GEOMETRY, RING.replace(damping_ratio=0.03), np.arange(10e6, 40.001e6, 0.1e6))
    assert compilations(engine._batched_sum_of_squares) <= before + 1  # 301 points in equal chunks: one compilation
    fit = fit_rolling(at50, GEOMETRY, RING.replace(damping_ratio=0.03), sensor_nuisances=False)  # the study's reading
    assert fit.converged
    # the fit weighs harmonic rows by their noise and reads the run through its gain and offset: not the sweep's
    # criterion, but the same truth — the two optima agree within the grid step and the fit's own error
    assert abs(fit.values["k_tread"] - sweep.best) <= 0.1e6 + 2 * fit.stderr["k_tread"]
    # sum_of_squares is the sweep's error of the fitted model: near the sweep's best (white noise: the fit's
    # criterion is almost the same sum), never far above it
    assert sum_of_squares(fit) <= sweep.best_sse * 1.01
    # two fits (the noise model's passes: σ weights the fit, the fit's residual gives σ), each run's gain and offset
    # through the readout only (no tangent through the solve): 36 evaluation equivalents here against 301
    assert fit.extra["passes"] == 2
    assert 5 * fit.extra["evaluations"] <= sweep.evaluations


def test_omega_from_speed_when_no_encoder():
    p = synthetic_profile(TRUTH, GEOMETRY, 30.0, write_rotation_hz=False)
    data = rolling_data([p], GEOMETRY, TRUTH)
    assert "R_e" in data.omega_source[0]
    r_e = 30 / 3.6 / data.omega[0]
    assert GEOMETRY.outer_radius - 0.0143 / 3 * 1.5 < r_e < GEOMETRY.outer_radius  # R_out − δ/3, δ ≈ 13 mm


def test_bad_requests_are_input_errors(profiles):
    flat = synthetic_profile(TRUTH, GEOMETRY, 30.0)
    with pytest.raises(InputError, match="mix flat-road and drum"):
        fit_rolling([profiles[0], flat], GEOMETRY, RING)
    with pytest.raises(InputError, match="cannot fit 'chi'"):
        fit_rolling(profiles[:1], GEOMETRY, RING, free=("chi",))
    with pytest.raises(InputError, match="each run's angle offset and gain"):
        fit_rolling(profiles[:1], GEOMETRY, RING, free=("k_tread", "angle_offset"))


@pytest.mark.slow
def test_posterior_brackets_truth(fit4):
    from ringfit.fit import ensemble

    before = compilations(ensemble._block)
    post = sample_rolling_posterior(fit4, steps=120, seed=1)  # 9 parameters: 18 walkers
    assert compilations(ensemble._block) <= before + 1  # one block program
    row = next(r for r in post.summary_table(level=0.6827) if r["name"] == "k_tread")
    lo, med, hi = row["lo"], row["median"], row["hi"]
    assert lo < med < hi
    assert abs(med - 25e6) < 4 * (hi - lo) / 2 + 1e-3 * 25e6
    assert (hi - lo) / 2 == pytest.approx(fit4.stderr["k_tread"], rel=0.5)
    assert 0.1 < np.mean(post.acceptance) < 0.9
