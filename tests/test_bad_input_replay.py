"""Every bad input of issue 14 gets the promised answer (tests/bad_input_cases.py).

Each case runs ``ringfit.cli.main`` in-process in a fresh copy of small valid
fixtures and must end in exit status 2 with ONE stderr line that names the
file, row, field or option, with no file written or changed in the folder
(input bytes included) — or, for the cases marked documented, in the
behaviour the docs promise. ``benchmarks/bench_bad_input.py`` prints the count.
"""

import shutil

import pytest

from bad_input_cases import CASES, build_fixtures, replay

QUICK = [c for c in CASES if not c.slow]
SLOW = [c for c in CASES if c.slow]


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory):
    return build_fixtures(tmp_path_factory.mktemp("fixtures") / "d")


def _run(case, fixtures, tmp_path, monkeypatch):
    d = tmp_path / "d"
    shutil.copytree(fixtures, d, symlinks=True)
    monkeypatch.chdir(d)
    outcome = replay(case, d)
    assert outcome.ok, f"{case.id}: {outcome.why}\n{outcome.err}"


@pytest.mark.parametrize("case", QUICK, ids=[c.id for c in QUICK])
def test_bad_input_answered_cleanly(case, fixtures, tmp_path, monkeypatch):
    _run(case, fixtures, tmp_path, monkeypatch)


@pytest.mark.slow
@pytest.mark.parametrize("case", SLOW, ids=[c.id for c in SLOW])
def test_documented_behaviour(case, fixtures, tmp_path, monkeypatch):
    _run(case, fixtures, tmp_path, monkeypatch)


def test_cases_cover_every_command():
    commands = {c.argv[0] for c in CASES}
    assert commands >= {"fit", "sample", "report", "demo", "ssi", "frf", "roll", "fit-rolling", "profile", "cleat",
                        "diagnose"}
