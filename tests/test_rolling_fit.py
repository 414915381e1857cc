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
    # the residual σ estimate is the band-limited noise: 1024 → 512 points halves the variance
    assert fit4.extra["sigma_ms2"] == pytest.approx(NOISE / math.sqrt(2), rel=0.05)
    assert fit4.extra["model"].shape == (4, 2, 512)


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
def test_recovers_damping_and_angle_offset(profiles):
    offset = math.radians(0.5)
    shifted = []
    for p in profiles:  # recorded angle α = φ − offset ⇒ reading at α is the model at α + offset
        ch = np.asarray(shift_angle(np.stack([p.acc_radial_ms2, p.acc_tangential_ms2]), offset))
        shifted.append(Profile(p.angle_deg, ch[0], ch[1], condition=p.condition))
    res = fit_rolling(shifted, GEOMETRY, RING, free=("k_tread", "damping_ratio", "angle_offset"))
    assert res.converged
    assert res.values["k_tread"] == pytest.approx(25e6, rel=0.01)
    assert abs(res.values["damping_ratio"] - 0.03) < 4 * res.stderr["damping_ratio"]
    assert abs(res.values["angle_offset"] - offset) < 4 * res.stderr["angle_offset"]
    assert res.stderr["angle_offset"] < math.radians(0.05)


@pytest.mark.slow
def test_beats_the_source_sweep_with_twenty_times_fewer_evaluations(profiles):
    """Source §5.3: sweep k_trd, keep the lowest error at 50 km/h. Grid 10–40 MN/m² in 0.1 MN/m² steps."""
    at50 = [p for p in profiles if p.speed_kmh == 50.0]
    before = compilations(engine._batched_sum_of_squares)
    sweep = tread_stiffness_sweep(at50, GEOMETRY, RING.replace(damping_ratio=0.03), np.arange(10e6, 40.001e6, 0.1e6))
    assert compilations(engine._batched_sum_of_squares) <= before + 1  # 301 points in equal chunks: one compilation
    fit = fit_rolling(at50, GEOMETRY, RING.replace(damping_ratio=0.03))
    assert fit.converged
    assert sum_of_squares(fit) <= sweep.best_sse * (1 + 1e-12)
    assert abs(fit.values["k_tread"] - sweep.best) <= 0.1e6
    assert 20 * fit.extra["evaluations"] <= sweep.evaluations


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


@pytest.mark.slow
def test_posterior_brackets_truth(fit4):
    from ringfit.fit import ensemble

    before = compilations(ensemble._block)
    post = sample_rolling_posterior(fit4, walkers=8, steps=120, seed=1)
    assert compilations(ensemble._block) <= before + 1  # one block program
    row = next(r for r in post.summary_table(level=0.6827) if r["name"] == "k_tread")
    lo, med, hi = row["lo"], row["median"], row["hi"]
    assert lo < med < hi
    assert abs(med - 25e6) < 4 * (hi - lo) / 2 + 1e-3 * 25e6
    assert (hi - lo) / 2 == pytest.approx(fit4.stderr["k_tread"], rel=0.5)
    assert 0.1 < np.mean(post.acceptance) < 0.9
