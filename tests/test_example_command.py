"""`ringfit example KIND --out DIR`: synthetic inputs with a README of their truth; every README command runs.

(records and case here; profiles and cleat take 10–20 s to generate and were checked by hand: their README
commands are the same kind of one-liners.)
"""

import re
import shlex

import numpy as np
import pytest

from ringfit.cli import build_parser, main


def _commands(readme: str) -> list[list[str]]:
    blocks = re.findall(r"```bash\n(.*?)```", readme, flags=re.S)
    return [shlex.split(line)[1:] for b in blocks for line in b.strip().splitlines() if line.startswith("ringfit ")]


def test_records_example_truth_and_commands(tmp_path, capsys, monkeypatch):
    from ringfit.io.records import read_records
    from ringfit.params import table9
    from ringfit.synth.records import ring_modes

    out = tmp_path / "ex"
    assert main(["example", "records", "--out", str(out), "--quiet"]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["README.md", "impact.records.npz", "impact.uff", "tyre.toml"]
    readme = (out / "README.md").read_text()
    cmds = _commands(readme)
    assert [c[0] for c in cmds] == ["ssi", "frf", "ssi", "fit", "sample", "report"]
    parser = build_parser()
    for c in cmds:
        parser.parse_args(c)  # every command of the README is a valid command line
    # the truth table is the generator's truth
    geometry, ring = table9()
    truth = ring_modes(ring.replace(rho_a=2.60, ei=0.60, kw=1.40e6, kv=1.08e6, k_tread=15.0e6), geometry,
                       n_values=range(1, 10), seed=11)
    for n, f in zip(truth.n[truth.structural()], truth.freq_hz[truth.structural()]):
        assert f"| {n} | structural | {f:.2f} |" in readme
    npz, uff = read_records(out / "impact.records.npz"), read_records(out / "impact.uff")
    assert np.array_equal(npz.acc, uff.acc) and npz.acc.shape == (48, 2, 3200)
    # the first README command, run as written in the example's folder, finds the true modes
    monkeypatch.chdir(out)
    assert main(cmds[0] + ["--quiet", "--orders", "2:80:2"]) == 0  # fewer orders than the default: faster
    from ringfit.io.modes import read_mode_table

    t = read_mode_table(out / "ssi.modes.csv")
    assert (out / "ssi.png").stat().st_size > 10_000
    for n, f in zip(truth.n[truth.structural()], truth.freq_hz[truth.structural()]):
        rows = np.flatnonzero(t.n == n)
        assert rows.size >= 1 and np.min(np.abs(t.freq_hz[rows] - f)) / f < 0.003


def test_example_never_overwrites_without_force(tmp_path, capsys):
    out = tmp_path / "ex"
    assert main(["example", "case", "--out", str(out)]) == 0
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert {p.relative_to(out).as_posix() for p in before} >= {"README.md", "case/tyre.toml", "case/free.modes.csv"}
    readme = (out / "README.md").read_text()
    assert "injected effect: **ground_contact**" in readme
    for c in _commands(readme):
        build_parser().parse_args(c)
    capsys.readouterr()
    assert main(["example", "case", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--force" in err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
    assert not [p for p in out.iterdir() if p.name.startswith(".ringfit-example")]  # no leftovers
    assert main(["example", "case", "--out", str(out), "--force"]) == 0


@pytest.mark.parametrize("argv", [["example", "records", "--out", "{f}"], ["example", "nonsense", "--out", "x"]])
def test_example_bad_input(tmp_path, capsys, argv):
    f = tmp_path / "file.txt"
    f.write_text("x")
    assert main([a.replace("{f}", str(f)) for a in argv]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert f.read_text() == "x"


def test_case_example_with_an_effect(tmp_path, capsys):
    """`--effect NAME` hides that effect (wheel_suspension: an extra table whose sidecar states the fixture)."""
    import json

    out = tmp_path / "ex"
    assert main(["example", "case", "--out", str(out), "--effect", "wheel_suspension", "--quiet"]) == 0
    side = json.loads((out / "case" / "suspended.modes.json").read_text())
    assert side["fixture"] == "suspension" and side["wheel_mass_kg"] > 0
    readme = (out / "README.md").read_text()
    assert "wheel_suspension" in readme
    # a README states only what its data determine: the modal case's tables do not carry k_tread (issue 34)
    assert "k_tread =" not in readme and "k_tread is not stated" in readme
    assert main(["example", "case", "--out", str(tmp_path / "b"), "--effect", "belt_wear"]) == 2
    assert "--effect" in capsys.readouterr().err
    assert main(["example", "records", "--out", str(tmp_path / "c"), "--effect", "none"]) == 2


@pytest.mark.slow
def test_case_example_with_a_profile_effect(tmp_path):
    """`--effect tread_shear` writes a case of rolling profiles (the lever truth of ringfit.synth.cases)."""
    out = tmp_path / "ex"
    assert main(["example", "case", "--out", str(out), "--effect", "tread_shear", "--quiet"]) == 0
    assert len(list((out / "case").glob("run*.profile.csv"))) == 4
    assert (out / "case" / "tyre.toml").is_file() and (out / "case" / "free.modes.csv").is_file()
    assert "tread_shear" in (out / "README.md").read_text()
