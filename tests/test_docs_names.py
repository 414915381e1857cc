"""Every code name the documentation cites resolves (issue 31 item 5): a dotted ``ringfit.…`` name in
docs/*.md or README.md imports (the longest importable module, then attributes), and every cited file
path (``ringfit/…/x.py``, ``benchmarks/…``, ``tests/…``, ``notebooks/…``, ``experiments/…``) exists.

A rename that leaves the docs pointing at nothing fails here instead of in a newcomer's hands."""

import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted((ROOT / "docs").glob("*.md")) + [ROOT / "README.md"]
DOTTED = re.compile(r"(?<![\w/.'\"])ringfit(?:\.[A-Za-z_][A-Za-z0-9_]*)+")
PATH = re.compile(r"(?<![\w/.-])((?:ringfit|benchmarks|tests|notebooks|experiments)/[A-Za-z0-9_/.-]*[A-Za-z0-9_])")


def _cited(pattern):
    out = {}
    for doc in DOCS:
        for i, line in enumerate(doc.read_text(encoding="utf-8").splitlines(), 1):
            for m in pattern.finditer(line):
                out.setdefault(m.group(1) if m.groups() else m.group(0), f"{doc.name}:{i}")
    return out


def _resolves(name: str) -> bool:
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        try:
            for attr in parts[cut:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return False
        return True
    return False


def test_docs_cite_names():
    assert len(_cited(DOTTED)) > 50  # the pattern finds the docs' names at all


@pytest.mark.parametrize("name", sorted(_cited(DOTTED)))
def test_every_dotted_name_the_docs_cite_resolves(name):
    assert _resolves(name.rstrip(".")), f"{_cited(DOTTED)[name]}: {name} does not resolve"


def test_every_file_the_docs_cite_exists():
    missing = []
    for path, where in sorted(_cited(PATH).items()):
        p = ROOT / path.rstrip("/")
        if "*" in path or "…" in path or p.exists() or p.with_suffix(".py").exists():
            continue
        missing.append(f"{where}: {path}")
    assert not missing, "\n".join(missing)
