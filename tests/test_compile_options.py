"""XLA compile options of ringfit's programs (issue 24 item 1: the cold start).

- Every program ringfit compiles itself carries :data:`ringfit._cache.CPU_COMPILE` (the CPU backend's
  classic fusion emitters), the quick ones :data:`ringfit._cache.QUICK_COMPILE` too; the jitted function is
  made at its first use, never at import.
- An option this jaxlib refuses is left out from then on, and the program is compiled again without it and runs
  (a plain program and a kept exported one).
- The options change no answer beyond the fit's tolerance: eq. 18's fit of the bundled SSI table, compiled
  with them (quick) and by a plain ``jax.jit`` without any, against each other.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest

import ringfit  # noqa: F401  (float64)
from ringfit import _cache
from ringfit.data import path
from ringfit.fit import engine
from ringfit.fit.least_squares import fit_natural_frequencies
from ringfit.io.modes import read_mode_table
from ringfit.io.tyre import read_tyre


def _options_of(lowered) -> dict:
    """The XLA options a lowered program will be compiled with (JAX keeps them on its lowering)."""
    return dict(lowered._lowering._compiler_options_kvs)


def test_the_options_reach_the_programs_and_nothing_is_made_at_import():
    fn = _cache.jit(lambda x: 2.0 * x)
    quick = _cache.jit(lambda x: 3.0 * x, quick=True)
    assert fn._jitted is None and quick._jitted is None  # made at first use
    x = np.float64(1.5)
    assert _options_of(fn.lower(x)) == _cache.CPU_COMPILE
    assert _options_of(quick.lower(x)) == _cache.QUICK_COMPILE
    assert float(fn(x)) == 3.0 and float(quick(x)) == 4.5
    # the engine's solves and the contact solve are such programs
    assert engine._solve.jitted is not None and engine._solve._quick is False
    assert engine._solve_quick._quick is True
    from ringfit.physics import contact

    assert contact._solve_rolling_compiled._quick is True


def test_a_jitted_function_keeps_its_name_doc_and_static_arguments():
    def scaled(x, *, k):
        """Doc of scaled."""
        return k * x

    fn = _cache.jit(scaled, static_argnames="k")
    assert fn.__name__ == "scaled" and fn.__doc__ == "Doc of scaled." and fn.__wrapped__ is scaled
    assert float(fn(np.float64(2.0), k=3)) == 6.0
    assert fn._cache_size() == 1
    fn(np.float64(5.0), k=3)
    assert fn._cache_size() == 1  # no retrace for a new value
    fn(np.float64(5.0), k=4)
    assert fn._cache_size() == 2  # a static argument is static


def test_a_jitted_function_pickles_as_what_it_wraps():
    import pickle

    from ringfit.physics.natural import natural_frequencies, natural_frequencies_jit

    natural_frequencies_jit.jitted  # made (a compiled function does not pickle)
    again = pickle.loads(pickle.dumps(natural_frequencies_jit))
    assert again._fun is natural_frequencies and again._jitted is None and again._quick is False


def test_an_unknown_option_is_left_out_and_the_program_still_runs(monkeypatch, caplog):
    bogus = "xla_cpu_no_such_option_anywhere"
    monkeypatch.setattr(_cache, "CPU_COMPILE", {**_cache.CPU_COMPILE, bogus: True})
    monkeypatch.setattr(_cache, "_REFUSED", set())
    # a plain jax.jit with the unknown option is refused: that is what the wrapper must survive
    with pytest.raises(Exception, match=bogus):
        jax.jit(lambda x: x - 1.0, compiler_options={bogus: True})(1.0)
    fn = _cache.jit(lambda x: x + 1.0)
    assert bogus in _options_of(fn.lower(np.float64(1.0)))  # tried first: a jaxlib that knows it pays nothing
    with caplog.at_level("DEBUG", logger="ringfit.cache"):
        assert float(fn(np.float64(1.0))) == 2.0
    assert _cache._REFUSED == {bogus} and bogus in caplog.text  # said on the debug log
    assert _cache.compiler_options() == {"xla_cpu_use_fusion_emitters": False}
    assert _options_of(fn.lower(np.float64(1.0))) == {"xla_cpu_use_fusion_emitters": False}
    # an error of the program itself is not taken for a refused option
    failing = _cache.jit(lambda x: x.undefined_attribute)
    with pytest.raises(AttributeError):
        failing(np.float64(1.0))


def test_a_kept_program_survives_a_refused_option(monkeypatch, tmp_path):
    bogus = "xla_cpu_no_such_option_anywhere"
    monkeypatch.setattr(_cache, "CPU_COMPILE", {**_cache.CPU_COMPILE, bogus: True})
    monkeypatch.setattr(_cache, "_REFUSED", set())
    monkeypatch.setattr(_cache, "_kept_folder", lambda: str(tmp_path))

    def double(x, *, k):
        return k * x

    kept = _cache.ExportedJit(double, _cache.jit(double, static_argnames="k"))
    assert float(kept(np.float64(2.0), k=2)) == 4.0
    assert _cache._REFUSED == {bogus}
    # exported again under a key without the refused option, then kept in memory
    assert kept.sources == ["exported", "exported"]
    assert float(kept(np.float64(3.0), k=2)) == 6.0 and len(kept.sources) == 2


def test_the_options_change_no_answer_beyond_the_fits_tolerance():
    """eq. 18's fit (quick) and the same solve compiled by a plain jax.jit, no options."""
    tyre = read_tyre(path("table9.tyre.toml"))
    table = read_mode_table(path("free-ssi.modes.csv"))
    captured = {}
    real = engine._solve_program

    def capture(model):
        program = real(model)

        def run(*args, **static):
            captured["args"], captured["static"] = args, static
            return program(*args, **static)

        return run

    engine._solve_program = capture
    try:
        fit = fit_natural_frequencies(table, tyre.geometry, tyre.ring, prior="physical")
    finally:
        engine._solve_program = real
    assert fit.converged
    plain = jax.jit(engine._solve_one, static_argnames=engine._STATIC)(*captured["args"], **captured["static"])
    u_plain, code = np.asarray(plain[0]), int(plain[1])
    assert code == 0
    u_ours = np.array([fit.problem.coordinate(k).to_u(fit.values[k]) for k in fit.names])
    # log-coordinates: an absolute difference is a relative one in the parameter
    np.testing.assert_allclose(u_ours, u_plain[: len(fit.names)], rtol=0, atol=1e-6)
    model_hz = np.asarray(fit.extra["model_hz"])
    np.testing.assert_allclose(model_hz, np.asarray(plain[5])[: model_hz.size], rtol=1e-9)
