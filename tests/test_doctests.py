"""The ``>>>`` examples in ringfit's docstrings run and print what they say (issue 24 item 4).

Every module of ringfit whose source holds an example is run here (a new example cannot go
unrun), and the main public functions must have one."""

import doctest
import importlib
from pathlib import Path

import pytest

import ringfit

ROOT = Path(__file__).resolve().parents[1]
#: The top-level names whose docstrings must show an example. The others are exercised by the
#: tutorials (notebooks) instead: their examples would need recordings, case folders or
#: compile-heavy rolling solves that do not fit a docstring or the suite's time budget.
MUST_HAVE_EXAMPLES = ("read_tyre", "read_mode_table", "natural_frequencies", "fit_natural_frequencies",
                      "identifiability", "load_posterior", "InputError", "enable_compilation_cache")


def _modules_with_examples() -> list[str]:
    out = []
    for path in sorted((ROOT / "ringfit").rglob("*.py")):
        if ">>>" in path.read_text(encoding="utf-8"):
            rel = path.relative_to(ROOT).with_suffix("")
            out.append(".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts))
    return out


MODULES = _modules_with_examples()


def test_main_public_functions_have_examples():
    for name in MUST_HAVE_EXAMPLES:
        assert name in ringfit.__all__, name
        assert ">>>" in (getattr(ringfit, name).__doc__ or ""), f"ringfit.{name} has no >>> example"


@pytest.mark.parametrize("module_name", MODULES)
def test_docstring_examples_run(module_name):
    module = importlib.import_module(module_name)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = [t for t in finder.find(module, module_name) if t.examples]
    assert tests, f"{module_name} has '>>>' in its source but doctest found no example"
    for test in tests:
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed in {module_name} (see stdout)"
