"""Layers point one way (issue 11 item 5): the import-linter contracts of pyproject.toml hold, they
catch a violation, and report/ draws saved results without calling a fitting function."""

import ast
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

importlinter_cli = pytest.importorskip("importlinter.cli", reason="pip install -e '.[test]' (import-linter)")

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "ringfit"


def _lint(cwd: Path, pythonpath: Path | None = None) -> subprocess.CompletedProcess:
    env = None
    if pythonpath is not None:
        import os

        env = dict(os.environ, PYTHONPATH=str(pythonpath))
    code = ("import sys; from importlinter.cli import lint_imports; "
            "sys.exit(lint_imports(config_filename='pyproject.toml', no_cache=True, no_logo=True))")
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=120)


def test_layer_contracts_hold():
    out = _lint(ROOT)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "6 kept, 0 broken" in out.stdout


def test_contracts_catch_violations(tmp_path):
    """A copy of the package with bad imports (inside functions, as ringfit's lazy imports are)."""
    shutil.copytree(PACKAGE, tmp_path / "ringfit", ignore=shutil.ignore_patterns("__pycache__", "data"))
    (tmp_path / "ringfit" / "data").mkdir()
    shutil.copy(PACKAGE / "data" / "__init__.py", tmp_path / "ringfit" / "data" / "__init__.py")
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    bad = {
        "io/modes.py": "\n\ndef _bad():\n    from ringfit.fit.least_squares import fit_natural_frequencies\n",
        "targets/frf.py": "\n\ndef _bad():\n    import jax.numpy\n",
        "cli/rolling.py": "\n\ndef _bad():\n    from ringfit.synth import cases\n",
        "fit/estimate/harmonics.py": "\n\ndef _bad():\n    from ringfit.fit.estimate.load import estimate_load\n",
        "fit/profile_block.py": "\n\ndef _bad():\n    from ringfit.fit.identify import identify\n",
    }
    for rel, text in bad.items():
        with open(tmp_path / "ringfit" / rel, "a") as fh:
            fh.write(text)
    out = _lint(tmp_path, pythonpath=tmp_path)
    assert out.returncode == 1, out.stdout + out.stderr
    assert "0 kept, 6 broken" in out.stdout, out.stdout  # synth -> io.modes -> fit breaks the synth contract too
    for fragment in ("ringfit.io.modes -> ringfit.fit.least_squares", "ringfit.targets.frf -> jax",
                     "ringfit.cli.rolling -> ringfit.synth",
                     "ringfit.fit.estimate.harmonics -> ringfit.fit.estimate.load",
                     "ringfit.fit.profile_block -> ringfit.fit.identify"):
        assert fragment in out.stdout, fragment


#: What a report must never call: fits, samplers, the diagnosis (a report draws saved results).
FITTING = re.compile(r"^(fit_\w+|sample_\w*|sample|diagnose|least_squares|identifiability|profile_natural\w*|"
                     r"source_study_fit|fit_chain|refit\w*)$")


def _names_used(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("ringfit"):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.Call):
            f = node.func
            names.add(f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", ""))
    return names


@pytest.mark.parametrize("path", sorted((PACKAGE / "report").glob("*.py")), ids=lambda p: p.name)
def test_report_calls_no_fitting_function(path):
    assert sorted(n for n in _names_used(path) if FITTING.match(n)) == []


def test_the_fitting_pattern_sees_a_fit():
    # the check above is not vacuous: the demo (a workflow, not a report) calls fits and a sampler
    used = _names_used(PACKAGE / "demo.py")
    assert {"fit_natural_frequencies", "sample_posterior", "identifiability"} <= {n for n in used if FITTING.match(n)}
