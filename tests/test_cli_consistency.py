"""One command line (issue 11 item 9, issue 14): help everywhere, one quiet flag, one meaning of
--max-steps, one-line usage errors, `ringfit --help` without JAX, no import cycles in the package."""

import argparse
import ast
import subprocess
import sys
from pathlib import Path

import pytest

from ringfit.cli import build_parser, main

PACKAGE = Path(__file__).resolve().parents[1] / "ringfit"


def _subparsers():
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices


def test_every_option_has_help():
    missing = []
    for name, p in _subparsers().items():
        for action in p._actions:
            if isinstance(action, argparse._HelpAction) or action.help == argparse.SUPPRESS:
                continue
            if not (action.help or "").strip():
                missing.append(f"{name} {'/'.join(action.option_strings) or action.dest}")
    assert missing == []


def test_one_quiet_flag():
    for name, p in _subparsers().items():
        shown = {s for a in p._actions if a.help != argparse.SUPPRESS for s in a.option_strings}
        assert "--no-progress" not in shown, name  # hidden alias only
    for name in ("sample", "ssi", "profile", "cleat", "diagnose", "demo"):  # the commands with a progress bar
        shown = {s for a in _subparsers()[name]._actions for s in a.option_strings}
        assert "--quiet" in shown, name


def test_max_steps_means_chain_steps_only(capsys):
    owners = {name: a.help for name, p in _subparsers().items() for a in p._actions
              if "--max-steps" in a.option_strings and a.help != argparse.SUPPRESS}
    # campaign passes it on to `ringfit sample`; identify's counts the steps of its --posterior chain
    assert sorted(owners) == ["campaign", "identify", "sample"]
    assert "ringfit sample --max-steps" in owners["campaign"]
    assert "chain steps" in owners["identify"]
    assert main(["fit", "m.modes.csv", "--tyre", "t.toml", "--out", "o.toml", "--max-steps", "10"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--max-iterations" in err


def test_usage_errors_are_one_line(capsys):
    assert main(["ssi", "x.npz", "--out", "y.modes.csv", "--skip", "nan"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.splitlines() == [err] and err.startswith("ringfit ssi: error: argument --skip")
    assert main(["nonsense"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def _fresh_python(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_help_does_not_import_jax_and_ringfit_enables_float64():
    code = (
        "import sys, contextlib, io\n"
        "from ringfit.cli import main, build_parser\n"
        "names = ['--help'] + [[c, '--help'] for c in ('fit', 'ssi', 'cleat', 'diagnose', 'example')]\n"
        "for argv in names:\n"
        "    with contextlib.redirect_stdout(io.StringIO()):\n"
        "        assert main(argv if isinstance(argv, list) else [argv]) == 0\n"
        "print('jax' in sys.modules)\n"
        "import jax.numpy as jnp\n"
        "print(jnp.zeros(1).dtype)\n"
    )
    assert _fresh_python(code).split() == ["False", "float64"]
    # the other order: JAX first, ringfit after
    assert _fresh_python("import jax, ringfit, jax.numpy as jnp; print(jnp.ones(2).dtype)") == "float64"


def _imports(path: Path, modules: set[str]) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        names = []
        if isinstance(node, ast.ImportFrom) and node.module:
            names = [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        for n in names:
            while n and n not in modules:
                n = n.rpartition(".")[0]
            if n:
                found.add(n)
    return found


def test_no_import_cycles_in_the_package():
    """Module-level and function-level imports alike: layers point one way (e.g. params ↛ io, uff ↛ records)."""
    paths = {".".join(p.relative_to(PACKAGE.parent).with_suffix("").parts).removesuffix(".__init__"): p
             for p in PACKAGE.rglob("*.py")}
    graph = {m: _imports(p, set(paths)) - {m} for m, p in paths.items()}
    cycles, state = [], {}

    def visit(m, stack):
        state[m] = 1
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                cycles.append(stack[stack.index(n):] + [n])
            elif n not in state:
                visit(n, stack + [n])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    assert cycles == []


@pytest.mark.parametrize("module, forbidden", [
    ("ringfit.params", "ringfit.io"),
    ("ringfit.io.uff", "ringfit.io.records"),
])
def test_broken_cycles_stay_broken(module, forbidden):
    path = PACKAGE.parent / (module.replace(".", "/") + ".py")
    mods = {m for m in (forbidden, "ringfit.io.tyre", "ringfit.io.records")}
    assert not any(i == forbidden or i.startswith(forbidden + ".") for i in _imports(path, mods))
