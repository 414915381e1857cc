"""Exported programs kept beside the compilation cache (issue 24 item 1: a warm process skips tracing).

- A program kept as an exported program is loaded by the next process (here: a fresh memo) instead of
  traced; (slow) the engine's solve kept so gives the jitted solve's answer bit for bit, and a
  closed-form least-squares solution.
- A corrupt entry, or an entry whose arguments are not the call's, is ignored with a debug line and
  written again — never trusted; without the compilation cache nothing is written.
- The key: a changed source (or library) is a new program; a static argument without a stable
  description (a closure, an object without attributes) gets no exported program.
- Slow: a warm ``ringfit diagnose`` of ``ringfit example case`` loads every solve and writes the same JSON.
"""

from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import ringfit  # noqa: F401  (float64)
from ringfit import _cache
from ringfit._cache import ExportedJit, _describe, _Unstable
from ringfit.fit import engine
from ringfit.fit.engine import LINEAR, AbstractResiduals, Coordinate, Problem, least_squares

CALLS = {"n": 0}


class _Line(AbstractResiduals):
    """``(a + b x − y)/σ``, counting traces; compiled quickly (a test)."""

    compile_quick = True

    def __call__(self, theta, data):
        CALLS["n"] += 1
        x, y, sigma = data
        pred = theta[0] + theta[1] * x
        return (pred - y) / sigma, pred


def _problem(seed=3, m=11):
    rng = np.random.default_rng(seed)
    x = np.linspace(0.0, 2.0, m)
    y = 0.3 + 1.7 * x + 0.01 * rng.standard_normal(m)
    sigma = np.full(m, 0.01)
    return Problem(_Line(), (x, y, sigma), (Coordinate("a", LINEAR), Coordinate("b", LINEAR))), x, y, sigma


def _closed_form(x, y, sigma):
    A = np.stack([np.ones_like(x), x], axis=1) / sigma[:, None]
    return np.linalg.solve(A.T @ A, A.T @ (y / sigma))


@pytest.fixture
def kept(tmp_path, monkeypatch):
    """A fresh kept quick solve whose cache folder is ``tmp_path`` (JAX's own cache settings untouched)."""
    program = ExportedJit(engine._solve_one, engine._solve_quick, quick=True)
    monkeypatch.setattr(engine, "_solve_quick_kept", program)
    monkeypatch.setattr(_cache, "_kept_folder", lambda: str(tmp_path))
    return program, tmp_path / _cache.EXPORT_FOLDER


def _fresh(program):
    """As a new process would find it: no program in memory."""
    program._programs.clear()


@pytest.mark.slow
def test_a_kept_solve_gives_the_jits_answer_and_is_loaded_instead_of_traced(kept, monkeypatch):
    program, folder = kept
    problem, x, y, sigma = _problem()
    fit = least_squares(problem, np.array([0.0, 1.0]), ("a", "b"))
    assert program.sources == ["exported"] and len(list(folder.glob("*.bin"))) == 1
    np.testing.assert_allclose(fit.theta, _closed_form(x, y, sigma), rtol=1e-9, atol=1e-12)
    # the plain jitted solve (no cache) gives the same numbers, bit for bit
    monkeypatch.setattr(_cache, "_kept_folder", lambda: None)
    plain = least_squares(problem, np.array([0.0, 1.0]), ("a", "b"))
    assert np.array_equal(plain.theta, fit.theta) and np.array_equal(plain.jacobian, fit.jacobian)
    monkeypatch.undo()
    monkeypatch.setattr(engine, "_solve_quick_kept", program)
    monkeypatch.setattr(_cache, "_kept_folder", lambda: str(folder.parent))
    _fresh(program)
    CALLS["n"] = 0
    again = least_squares(problem, np.array([0.0, 1.0]), ("a", "b"))
    assert program.sources[-1] == "loaded" and CALLS["n"] == 0  # deserialised: the model is not traced
    assert np.array_equal(again.theta, fit.theta) and np.array_equal(again.covariance_log, fit.covariance_log)
    # other data of the same shapes: the same program, the right answer
    problem2, x2, y2, s2 = _problem(seed=8)
    other = least_squares(problem2, np.array([0.0, 1.0]), ("a", "b"))
    np.testing.assert_allclose(other.theta, _closed_form(x2, y2, s2), rtol=1e-9, atol=1e-12)
    assert program.sources[-1] == "loaded" and len(program.sources) == 2


def _toy(x, y, *, scale):
    CALLS["n"] += 1
    return jnp.sin(x) * scale + y @ y


@pytest.fixture
def toy(tmp_path, monkeypatch):
    """A kept toy program (quick to compile) whose cache folder is ``tmp_path``."""
    monkeypatch.setattr(_cache, "_kept_folder", lambda: str(tmp_path))
    return ExportedJit(_toy, jax.jit(_toy, static_argnames="scale")), tmp_path / _cache.EXPORT_FOLDER


def _toy_args(n=5):
    return np.linspace(0.0, 1.0, n), np.arange(3.0)


def _toy_expected(x, y, scale):
    return np.sin(x) * scale + y @ y


def test_a_kept_program_is_loaded_without_tracing(toy):
    program, folder = toy
    x, y = _toy_args()
    np.testing.assert_allclose(program(x, y, scale=2.0), _toy_expected(x, y, 2.0), rtol=1e-15)
    assert program.sources == ["exported"] and len(list(folder.glob("*.bin"))) == 1
    _fresh(program)
    CALLS["n"] = 0
    np.testing.assert_allclose(program(x + 1, y, scale=2.0), _toy_expected(x + 1, y, 2.0), rtol=1e-15)
    assert program.sources[-1] == "loaded" and CALLS["n"] == 0
    program(x, y, scale=3.0)  # another static argument: another program
    assert program.sources[-1] == "exported" and len(list(folder.glob("*.bin"))) == 2


def _assert_reexported(program, x, y, caplog, why):
    """A fresh process's call ignores the kept entry (a debug line saying ``why``), exports the program again
    and gives the right answer."""
    _fresh(program)
    with caplog.at_level(logging.DEBUG, logger="ringfit.cache"):
        out = program(x, y, scale=2.0)
    assert program.sources[-1] == "exported"
    assert any(why in r.getMessage() for r in caplog.records)
    np.testing.assert_allclose(out, _toy_expected(x, y, 2.0), rtol=1e-15)


def test_a_corrupt_or_foreign_entry_is_ignored_and_written_again(toy, caplog):
    program, folder = toy
    x, y = _toy_args()
    program(x, y, scale=2.0)
    (entry,) = folder.glob("*.bin")
    # 1. garbage in the file
    entry.write_bytes(b"not a program" + entry.read_bytes()[:100])
    _assert_reexported(program, x, y, caplog, "ignoring the exported program")
    _fresh(program)
    program(x, y, scale=2.0)
    assert program.sources[-1] == "loaded"  # written again, and readable
    # 2. a valid program of other arguments (another length) under this call's name
    caplog.clear()
    program(*_toy_args(7), scale=2.0)
    entry.write_bytes(next(p for p in folder.glob("*.bin") if p != entry).read_bytes())
    _assert_reexported(program, x, y, caplog, "not this call's")


def test_without_the_cache_nothing_is_kept(tmp_path, monkeypatch):
    monkeypatch.setattr(_cache, "_kept_folder", lambda: None)
    program = ExportedJit(_toy, jax.jit(_toy, static_argnames="scale"))
    x, y = _toy_args()
    np.testing.assert_allclose(program(x, y, scale=2.0), _toy_expected(x, y, 2.0), rtol=1e-15)
    assert program.sources == [] and not any(tmp_path.iterdir())


def test_a_changed_source_is_a_new_program(toy, monkeypatch):
    program, folder = toy
    x, y = _toy_args()
    program(x, y, scale=2.0)
    monkeypatch.setattr(_cache, "_environment", lambda: "jax=other;ringfit-source=changed")
    _fresh(program)
    program(x, y, scale=2.0)
    assert program.sources == ["exported", "exported"] and len(list(folder.glob("*.bin"))) == 2


@dataclass(frozen=True)
class _Config:
    name: str
    table: np.ndarray


class _Slots:
    __slots__ = ("a",)

    def __init__(self):
        self.a = 1


def test_descriptions_are_stable_or_refused():
    a = _Config("x", np.arange(3.0))
    assert _describe(a) == _describe(_Config("x", np.arange(3.0)))  # equal values, equal text
    assert _describe(a) != _describe(_Config("x", np.arange(3.0) + 1e-12))  # the array's bytes count
    assert _describe(a) != _describe(_Config("y", np.arange(3.0)))
    assert "0x" not in _describe({"model": _Line(), "n": (1, 2.5, None)})
    for unstable in (lambda x: x, _Slots()):  # a closure's captures and a slotted object are not described
        with pytest.raises(_Unstable):
            _describe(unstable)


@pytest.mark.slow
def test_a_warm_diagnose_loads_every_solve_and_writes_the_same_answer(tmp_path):
    env = {**os.environ, "RINGFIT_CACHE_DIR": str(tmp_path / "cache")}
    env = {k: v for k, v in env.items() if not k.startswith("JAX_COMPILATION")}

    def ringfit_(*args):
        return subprocess.run([sys.executable, "-m", "ringfit", *args], env=env, capture_output=True, text=True,
                              timeout=600)

    assert ringfit_("example", "case", "--out", str(tmp_path / "ex"), "--quiet").returncode == 0
    outs = []
    for i in range(2):
        r = ringfit_("diagnose", str(tmp_path / "ex" / "case"), "--out", str(tmp_path / f"d{i}.diagnosis.json"),
                     "--quiet")
        assert r.returncode == 0, r.stderr
        outs.append(json.loads((tmp_path / f"d{i}.diagnosis.json").read_text()))
        if i == 0:
            kept_files = sorted((tmp_path / "cache" / _cache.EXPORT_FOLDER).glob("*.bin"))
            assert len(kept_files) >= 3  # the reference fit's, the frequency and the damping problems' solves
            stamps = {p: p.stat().st_mtime_ns for p in kept_files}

    def strip(d):
        if isinstance(d, dict):
            return {k: strip(v) for k, v in d.items() if k not in ("elapsed_s", "null_elapsed")}
        return [strip(v) for v in d] if isinstance(d, list) else d

    assert json.dumps(strip(outs[0]), sort_keys=True) == json.dumps(strip(outs[1]), sort_keys=True)
    # the warm run loaded them: no entry was written again
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps


def _with_callback(x, *, scale):
    host = jax.pure_callback(lambda v: np.asarray(v) * 2.0, jax.ShapeDtypeStruct(x.shape, x.dtype), x)
    return host * scale


def test_a_program_that_cannot_be_exported_is_traced_as_usual(toy, caplog):
    _, folder = toy
    program = ExportedJit(_with_callback, jax.jit(_with_callback, static_argnames="scale"))
    x = np.linspace(0.0, 1.0, 4)
    with caplog.at_level(logging.DEBUG, logger="ringfit.cache"):
        out = program(x, scale=3.0)
    np.testing.assert_allclose(out, 6.0 * x, rtol=1e-15)
    assert program.sources == ["jit"] and not list(folder.glob("*.bin"))
    assert any("no exported program" in r.getMessage() for r in caplog.records)
