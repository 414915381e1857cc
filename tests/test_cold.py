"""The first answer fast (issue 24 item 1) and the benchmarks' shared bits (item 2).

- The engine traces a model once per compiled solve (it used to trace it three times: the
  solver's primal, its JVP rule and the start's column norms), with the same answer as a
  closed-form least-squares solution.
- Every command runs with JAX's persistent compilation cache, turned on without importing JAX;
  a cold ``ringfit fit`` fills it and imports none of arviz, matplotlib, dask.
- ``benchmarks/_common.py``: one-line argument errors (exit 2), refusal to print figures after a
  failed task (exit 1), interleaved order, CPU time of waited-for children, spans.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import ringfit  # noqa: F401  (float64)
from ringfit.fit.engine import AbstractResiduals, Coordinate, LINEAR, Problem, least_squares, least_squares_batch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import _common as bc  # noqa: E402

CALLS = {"n": 0}


class _CountingLine(AbstractResiduals):
    """Residuals of a straight line a + b x, counting how often Python runs the model (= traces)."""

    def __call__(self, theta, data):
        CALLS["n"] += 1
        x, y, sigma = data
        pred = theta[0] + theta[1] * x
        return (pred - y) / sigma, pred


def test_the_model_is_traced_once_per_solve():
    rng = np.random.default_rng(3)
    x = np.linspace(0.0, 2.0, 11)
    y = 0.3 + 1.7 * x + 0.01 * rng.standard_normal(x.size)
    sigma = np.full(x.size, 0.01)
    problem = Problem(_CountingLine(), (x, y, sigma), (Coordinate("a", LINEAR), Coordinate("b", LINEAR)))
    CALLS["n"] = 0
    fit = least_squares(problem, np.array([0.0, 1.0]), ("a", "b"))
    assert CALLS["n"] == 1  # one trace serves the primal, the JVP rule and the column norms' evaluation
    # the answer: weighted linear least squares in closed form (normal equations), not the engine
    A = np.stack([np.ones_like(x), x], axis=1) / sigma[:, None]
    expected = np.linalg.solve(A.T @ A, A.T @ (y / sigma))
    assert fit.converged
    np.testing.assert_allclose(fit.theta, expected, rtol=1e-9, atol=1e-12)
    # its covariance: (AᵀA)⁻¹ (σ known), and the aux at the optimum is the prediction
    np.testing.assert_allclose(fit.covariance_log, np.linalg.inv(A.T @ A), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(fit.extra["aux"]), expected[0] + expected[1] * x, rtol=1e-12)
    # a second solve of the same structure traces nothing
    least_squares(problem, np.array([1.0, 0.0]), ("a", "b"))
    assert CALLS["n"] == 1


class _QuickLine(_CountingLine):
    compile_quick = True


def _line_problem(model, bounded=False):
    rng = np.random.default_rng(5)
    x = np.linspace(0.0, 2.0, 13)
    y = 0.3 + 1.7 * x + 0.01 * rng.standard_normal(x.size)
    sigma = np.full(x.size, 0.01)
    b = Coordinate("b", LINEAR, lo=-10.0, hi=10.0) if bounded else Coordinate("b", LINEAR)
    return Problem(model, (x, y, sigma), (Coordinate("a", LINEAR), b)), x, y, sigma


def test_fits_linearisations_and_evaluations_of_a_problem_share_one_compiled_solve():
    """Cold start: :func:`linearize` (and so every gap prediction and the calibration's linearisation) runs the
    fit's own compiled solve with a step limit of 0 — no second program; its rows and Jacobian are the closed
    form's (the straight line: ∂r/∂a = 1/σ, ∂r/∂b = x/σ)."""
    from ringfit.fit import engine

    problem, x, y, sigma = _line_problem(_CountingLine(), bounded=True)
    CALLS["n"] = 0
    fit = least_squares(problem, np.array([0.0, 1.0]), ("a", "b"), pad_to=3)
    before = engine._solve._cache_size()
    traces = CALLS["n"]
    theta = np.array([0.2, 1.5])
    lin = engine.linearize(problem, theta, ("a", "b"), pad_to=3)
    assert engine._solve._cache_size() == before and CALLS["n"] == traces  # nothing traced or compiled
    A = np.stack([np.ones_like(x), x], axis=1) / sigma[:, None]
    np.testing.assert_allclose(lin.jacobian, A, rtol=1e-12)
    np.testing.assert_allclose(lin.residuals, (theta[0] + theta[1] * x - y) / sigma, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.asarray(lin.aux), theta[0] + theta[1] * x, rtol=1e-13)
    # the same at the optimum: the fit's own residuals
    at_fit = engine.linearize(problem, fit.theta, ("a", "b"), pad_to=3)
    np.testing.assert_allclose(at_fit.residuals, fit.residuals, rtol=1e-10, atol=1e-12)
    assert engine._solve._cache_size() == before


def test_a_quick_compile_gives_the_fit_of_the_optimised_program():
    """A model with ``compile_quick`` is solved by the program compiled with XLA's backend optimisation off:
    the same optimum (the closed-form least-squares line) as the optimised program's."""
    from ringfit.fit import engine

    quick, x, y, sigma = _line_problem(_QuickLine())
    default, *_ = _line_problem(_CountingLine())
    n_quick, n_default = engine._solve_quick._cache_size(), engine._solve._cache_size()
    a = least_squares(quick, np.array([0.0, 1.0]), ("a", "b"))
    assert engine._solve_quick._cache_size() == n_quick + 1 and engine._solve._cache_size() == n_default
    b = least_squares(default, np.array([0.0, 1.0]), ("a", "b"))
    A = np.stack([np.ones_like(x), x], axis=1) / sigma[:, None]
    expected = np.linalg.solve(A.T @ A, A.T @ (y / sigma))
    assert a.converged and b.converged
    np.testing.assert_allclose(a.theta, expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(a.theta, b.theta, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(a.covariance_log, b.covariance_log, rtol=1e-10)


@pytest.mark.parametrize("warm_start", [False, True])  # vmapped fits, and fits chained by lax.scan
def test_batched_and_chained_solves_trace_the_model_once(warm_start):
    x = np.linspace(0.0, 2.0, 11)
    sigma = np.full(x.size, 0.01)
    truth = np.array([[0.3, 1.7], [-1.0, 0.5], [2.0, -1.0]])
    ys = truth[:, :1] + truth[:, 1:] * x  # exact lines: the fit must return them
    problem = Problem(_CountingLine(), (x, ys[0], sigma), (Coordinate("a", LINEAR), Coordinate("b", LINEAR)))
    CALLS["n"] = 0
    batch = least_squares_batch(problem, np.array([0.0, 1.0]), ("a", "b"),
                                (np.tile(x, (3, 1)), ys, np.tile(sigma, (3, 1))), warm_start=warm_start)
    assert CALLS["n"] == 1
    assert list(batch.status) == ["converged"] * 3
    np.testing.assert_allclose(np.asarray(batch.theta), truth, rtol=1e-9, atol=1e-9)


def _run(code: str, env: dict, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=600)


def _env(tmp_path: Path, **extra) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_")}
    env.update(PYTHONPATH=os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep),
               RINGFIT_CACHE_DIR=str(tmp_path / "cache"), **extra)
    return env


def test_enabling_the_cache_imports_no_jax_and_jax_reads_it(tmp_path):
    code = ("import sys, ringfit\n"
            "path = ringfit.enable_compilation_cache()\n"
            "assert 'jax' not in sys.modules\n"
            "import jax\n"
            "print(jax.config.jax_compilation_cache_dir, jax.config.jax_persistent_cache_min_compile_time_secs,\n"
            "      jax.config.jax_persistent_cache_min_entry_size_bytes, path)\n")
    out = _run(code, _env(tmp_path))
    assert out.returncode == 0, out.stderr
    directory, secs, size, path = out.stdout.split()
    assert directory == path == str(tmp_path / "cache") and float(secs) == 0.0 and int(size) == 0


def test_enabling_the_cache_after_jax_is_loaded(tmp_path):
    code = ("import jax, ringfit\n"
            "ringfit.enable_compilation_cache()\n"
            "print(jax.config.jax_compilation_cache_dir)\n")
    out = _run(code, _env(tmp_path))
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == str(tmp_path / "cache")


def test_a_cold_fit_fills_the_cache_and_imports_nothing_it_does_not_use(tmp_path):
    """Through ``ringfit.cli.main`` (every command goes there): the cache directory is filled, and
    the plotting, diagnostics and cluster libraries stay unimported."""
    out_toml = tmp_path / "fitted.tyre.toml"
    code = ("import sys, json\n"
            "from ringfit.cli import main\n"
            "from ringfit.data import path\n"
            f"rc = main(['fit', str(path('free-ssi.modes.csv')), '--tyre', str(path('table9.tyre.toml')),"
            f" '--out', {str(out_toml)!r}])\n"
            "heavy = [m for m in ('arviz', 'matplotlib', 'dask', 'distributed', 'xarray', 'pandas', 'scipy.stats')"
            " if m in sys.modules]\n"
            "print(json.dumps({'rc': rc, 'heavy': heavy}))\n")
    out = _run(code, _env(tmp_path), cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result == {"rc": 0, "heavy": []}
    assert out_toml.exists()
    entries = list((tmp_path / "cache").iterdir())
    assert any("solve" in p.name for p in entries), [p.name for p in entries]


def test_diagnose_imports_no_scipy_stats():
    code = ("import sys\n"
            "import ringfit.gap.diagnosis, ringfit.gap.modal, ringfit.gap.verdict, ringfit.fit.result\n"
            "print('scipy.stats' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_the_verdict_tail_probabilities_equal_scipy_stats():
    """The χ² tail and quantile the verdict now takes from scipy.special, against scipy.stats (outside)."""
    from scipy.special import chdtrc, chdtri, ndtri
    from scipy.stats import chi2, norm

    for k in (1, 2, 3.5, 12, 80):
        for x in (0.05, 1.0, 7.0, 60.0, 300.0):
            assert chdtrc(k, x) == pytest.approx(chi2.sf(x, k), rel=1e-12, abs=1e-300)
        assert chdtri(k, 1 - 0.95) == pytest.approx(chi2.ppf(0.95, k), rel=1e-12)
    assert ndtri(0.975) == pytest.approx(norm.ppf(0.975), rel=1e-15)


# --------------------------------------------------------------------------- benchmarks/_common.py
def test_bench_arguments_fail_in_one_line_with_status_2(capsys):
    p = bc.parser("test")
    p.add_argument("tyres", type=bc.count("a number of tyres", 1, 10))
    p.add_argument("--fs", type=bc.number("a rate > 0", 0.0, lo_open=True), default=1.0)
    for argv in (["0"], ["x"], ["3", "--fs", "nan"], ["3", "--fs", "0"]):
        with pytest.raises(SystemExit) as exc:
            p.parse_args(argv)
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "error:" in err
    assert p.parse_args(["3", "--fs", "2.5", "--quick"]).quick


def test_bench_refuses_figures_after_a_failed_task(capsys):
    failures = bc.Failures()
    failures.refuse()  # nothing failed: returns
    assert failures.check(True, "fine")
    failures.check(False, "sample tyre03", "exit status 2: --min-steps must be >= 100")
    with pytest.raises(SystemExit) as exc:
        failures.refuse()
    assert exc.value.code == 1
    captured = capsys.readouterr()
    assert captured.out == ""  # no figures
    assert "REFUSED" in captured.err and "sample tyre03" in captured.err


def test_interleaved_runs_alternate_and_failures_are_recorded():
    order = []

    def make(name, ok=True):
        def run():
            order.append(name)
            return bc.Sample(1.0, 0.5, ok, "" if ok else "boom")
        return run

    failures = bc.Failures()
    out = bc.interleaved({"a": make("a"), "b": make("b", ok=False)}, 3, failures)
    assert order == ["a", "b"] * 3
    assert [len(v) for v in out.values()] == [3, 3]
    assert len(failures.items) == 3 and failures.items[0][0] == "b (round 1)"


def test_a_process_cpu_time_counts_its_work():
    """CPU time of a child that spins ~0.3 s of CPU is ~0.3 s (children's rusage), its wall at least that."""
    spin = "import time\nt = time.process_time()\nwhile time.process_time() - t < 0.3: pass\n"
    r = bc.run_process([sys.executable, "-c", spin])
    assert r.ok and r.returncode == 0
    assert 0.3 <= r.cpu < 3.0
    assert r.wall >= 0.3 - 1e-3
    bad = bc.run_process([sys.executable, "-c", "import sys; sys.exit('bad input')"])
    assert not bad.ok and bad.returncode == 1 and "bad input" in bad.detail


def test_span_and_ratio_are_min_median_max():
    assert bc.span([3.0, 1.0, 2.0, 10.0, 4.0]) == "1.00 / 3.00 / 10.00"
    assert bc.span([2.0]) == "2.00"
    a = [bc.Sample(2.0, 4.0), bc.Sample(3.0, 9.0), bc.Sample(1.0, 1.0)]
    b = [bc.Sample(1.0, 2.0), bc.Sample(1.0, 3.0), bc.Sample(1.0, 1.0)]
    assert bc.ratio_span(a, b) == "1.00 / 2.00 / 3.00"  # round by round: 2, 3, 1
    assert bc.ratio_span(a, b, "wall") == "1.00 / 2.00 / 3.00"
