"""One case-folder reader (issue 31): ``diagnose`` and ``identify`` accept and refuse a case folder by the same
rules (ringfit/io/case.py), with the same one-line message naming the file and the field, exit status 2 and
nothing written. Each bad folder is made by hand from a good one."""

from __future__ import annotations

import json
import shutil

import pytest

from ringfit.cli import main
from ringfit.io.case import read_case_folder


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    root = tmp_path_factory.mktemp("reader")
    assert main(["example", "identify", "--out", str(root / "ex"), "--quiet"]) == 0
    return root / "ex" / "case"


def _edit_json(path, **changes):
    d = json.loads(path.read_text())
    for k, v in changes.items():
        if v is None:
            d.pop(k, None)
        else:
            d[k] = v
    path.write_text(json.dumps(d))


def _no_load(case):
    _edit_json(case / "run2.profile.json", load_n=None)
    return "run2.profile.json", "load_n"


def _zero_speed(case):
    _edit_json(case / "run1.profile.json", speed_kmh=-5.0)
    return "run1.profile.json", "speed_kmh"


def _no_sidecar(case):
    (case / "loaded5000.modes.json").unlink()
    return "loaded5000.modes.csv", "missing sidecar loaded5000.modes.json"


def _free_rolling(case):
    _edit_json(case / "free.modes.json", state="rolling", speed_kmh=30.0, load_n=3000.0)
    return "free.modes.json", "static, free tyre"


def _free_with_load(case):
    _edit_json(case / "loaded3000.modes.json", state="free")
    return "loaded3000.modes.json", "'state': 'free' with load_n"


@pytest.mark.parametrize("spoil", [_no_load, _zero_speed, _no_sidecar, _free_rolling, _free_with_load])
def test_diagnose_and_identify_refuse_a_bad_folder_alike(good, tmp_path, capsys, spoil):
    case = tmp_path / "case"
    shutil.copytree(good, case)
    name, what = spoil(case)
    lines = {}
    for command, out in (("diagnose", tmp_path / "d.diagnosis.json"), ("identify", tmp_path / "i.tyre.toml")):
        capsys.readouterr()
        assert main([command, str(case), "--out", str(out), "--quiet"]) == 2
        err = [ln for ln in capsys.readouterr().err.splitlines() if "error:" in ln]
        assert len(err) == 1, err
        assert name in err[0] and what in err[0], err[0]
        lines[command] = err[0].split("error: ", 1)[1]
        assert not out.exists()
    assert lines["diagnose"] == lines["identify"]


def test_profiles_are_read_in_load_then_speed_order(good, tmp_path):
    case = tmp_path / "case"
    shutil.copytree(good, case)
    # run3 (5000 N, 70 km/h) stated at 2000 N: first by load; run1 and run2 keep their order
    _edit_json(case / "run3.profile.json", load_n=2000.0)
    got = [p.source.name if hasattr(p.source, "name") else str(p.source).rsplit("/", 1)[-1]
           for p in read_case_folder(case).profiles]
    assert got == ["run3.profile.csv", "run1.profile.csv", "run2.profile.csv"]
