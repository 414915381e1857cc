"""One compilation serves every call with data of the same structure (issue 11 item 10).

Each public fitting or simulating function is called once to warm it, then again with new
values of the same structure (other frequencies, another start, other speeds and loads):
the second call must trace nothing and compile nothing. Counted from JAX's own monitoring
events (a trace and a backend compile each emit one), so any jit region the call goes
through — the public function's own or one inside it — is covered. ``fit_rolling``'s check is in
tests/test_rolling_fit.py (it reuses that file's compiled fit instead of compiling its own).
"""

import contextlib

import jax
import jax.monitoring
import numpy as np
import pytest

import ringfit  # noqa: F401  (float64)
from ringfit.data import path
from ringfit.fit.least_squares import fit_natural_frequencies
from ringfit.fit.posterior import log_probability_function
from ringfit.io.modes import read_mode_table
from ringfit.params import table9
from ringfit.physics.contact import ContactSolver
from ringfit.physics.profile import simulate_profile

GEOMETRY, RING = table9()
TRACE = "/jax/core/compile/jaxpr_trace_duration"
COMPILE = "/jax/core/compile/backend_compile_duration"


class _Events:
    counts = None

    @classmethod
    def listener(cls, event: str, duration: float, **_kw) -> None:
        if cls.counts is not None and event in cls.counts:
            cls.counts[event] += 1


jax.monitoring.register_event_duration_secs_listener(_Events.listener)


@contextlib.contextmanager
def count_traces():
    """Yields a dict that counts, while the block runs, the traces and XLA compilations of this process."""
    _Events.counts = {TRACE: 0, COMPILE: 0}
    try:
        yield _Events.counts
    finally:
        _Events.counts = None


def test_the_counter_sees_a_retrace():
    f = jax.jit(lambda x, k: x * k, static_argnums=1)
    f(np.ones(3), 2)
    with count_traces() as seen:
        f(np.ones(3), 3)  # a new static value: one trace, one compile
    assert seen[TRACE] >= 1 and seen[COMPILE] >= 1


@pytest.fixture(scope="module")
def table():
    return read_mode_table(path("free-ssi.modes.csv"))


def _other(table, factor):
    out = read_mode_table(path("free-ssi.modes.csv"))
    out.freq_hz = table.freq_hz * factor
    return out


def test_fit_natural_frequencies_does_not_retrace(table):
    fit_natural_frequencies(table, GEOMETRY, RING, prior="physical")
    with count_traces() as seen:  # other frequencies, another start, another step limit (traced)
        res = fit_natural_frequencies(_other(table, 1.02), GEOMETRY, RING.replace(ei=0.5, kw=1.2e6),
                                      prior="physical", max_steps=300)
    assert res.converged
    assert seen == {TRACE: 0, COMPILE: 0}


def test_log_probability_does_not_retrace(table):
    u = np.tile(np.log([2.5, 0.3, 1.1e6, 1.17e6]), (16, 1))
    logp, _, _ = log_probability_function(fit_natural_frequencies(table, GEOMETRY, RING, prior="physical"))
    first = logp(u)
    other = fit_natural_frequencies(_other(table, 0.98), GEOMETRY, RING.replace(rho_a=2.9), prior="physical")
    with count_traces() as seen:
        logp2, _, _ = log_probability_function(other)
        second = logp2(u + 0.01)
    assert seen == {TRACE: 0, COMPILE: 0}
    assert np.all(np.isfinite(first)) and np.all(np.isfinite(second)) and not np.allclose(first, second)


SOLVER = ContactSolver(n_grid=256)


def test_simulate_profile_does_not_retrace():
    simulate_profile(RING, GEOMETRY, speed_kmh=30.0, load_n=4000.0, drum_diameter_m=1.2192, solver=SOLVER)
    with count_traces() as seen:
        p = simulate_profile(RING.replace(k_tread=22e6, ei=0.7), GEOMETRY, speed_kmh=45.0, load_n=3500.0,
                             drum_diameter_m=1.5, solver=SOLVER)
    assert seen == {TRACE: 0, COMPILE: 0}
    assert p.condition["speed_kmh"] == 45.0 and np.all(np.isfinite(p.channels))
