"""The cleat example and ``cleat --ssi --tyre`` labelling use one model of the rolling, loaded modes (issue 31 item 6).

Before: ``ringfit example cleat`` generated the free spinning ring's eq. 25/26 waves while ``campbell`` and
the labelling used the loaded model (docs/physics.md §3.7), so ``cleat --ssi --tyre`` flagged 9 of 12
correctly labelled modes and "corrected" them to wrong orders.
"""

import csv
import math

import numpy as np
import pytest

from ringfit.io.modes import ModeTable, read_mode_table


@pytest.mark.slow  # one contact solve, one Campbell compilation and the bench's modes: ≈ 60 s
def test_the_loaded_cleat_bench_has_the_campbell_diagram_modes():
    """The synthetic cleat field's modes are the diagram's branches at the bench's Ω, load and drum: same
    frequencies, same n and direction (the one model; no second copy of its labels)."""
    from ringfit.gap.campbell import table_conditions
    from ringfit.physics.campbell import campbell_diagram
    from ringfit.synth.examples import cleat_bench

    bench = cleat_bench()
    truth = bench.generating_modes()
    table = ModeTable(freq_hz=[100.0], condition={"state": "rolling", "load_n": bench.load_n,
                                                  "rotation_hz": bench.rotation_hz, "frame": "fixed"})
    cond = table_conditions([table], bench.ring, bench.geometry, drum_diameter_m=bench.drum_diameter_m)[0]
    assert math.isclose(cond.omega, bench.omega, rel_tol=1e-12)
    d = campbell_diagram(bench.ring, bench.geometry, bench.load_n, [0.0, cond.speed_kmh],
                         drum_diameter_m=bench.drum_diameter_m)
    assert math.isclose(float(d.omega[1]), bench.omega, rel_tol=1e-9)
    direction = d.direction()[1]
    assert len(truth["n"]) >= 12
    for j in range(len(truth["n"])):
        b = int(np.argmin(np.abs(d.fixed_hz[1] - truth["fixed_hz"][j])))
        assert abs(d.fixed_hz[1, b] - truth["fixed_hz"][j]) < 1e-6 * truth["fixed_hz"][j]
        assert int(d.order[1, b]) == truth["n"][j]
        assert direction[b] == truth["branch"][j]
    # the physics finding of docs/physics.md §3.7: at the rated load no forward-dominated mode in 100–300 Hz
    assert not np.any((truth["branch"] == "forward") & (truth["fixed_hz"] > 100) & (truth["fixed_hz"] < 300))
    # … while the free spinning ring has one per order (what the example used to generate)
    free = bench.__class__(geometry=bench.geometry, ring=bench.ring, steady="analytic").generating_modes()
    assert np.sum((free["branch"] == "forward") & (free["fixed_hz"] > 100) & (free["fixed_hz"] < 300)) >= 5


@pytest.mark.slow  # generates the 20 s example (≈ 80 s) and runs cleat --ssi on it (≈ 25 s)
def test_cleat_example_labelled_with_its_true_tyre_flags_no_correct_mode(tmp_path, capsys):
    from ringfit.cli import main

    out = tmp_path / "ex"
    assert main(["example", "cleat", "--out", str(out)]) == 0
    # the truth, from the example's README table (n, branch, fixed-frame Hz)
    truth = []
    for line in (out / "README.md").read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 5 and cells[0].isdigit():
            truth.append((int(cells[0]), cells[1].split()[0], float(cells[2])))
    assert len(truth) >= 12
    modes = tmp_path / "rolling.modes.csv"
    assert main(["cleat", str(out / "cleat.records.npz"), "--sectors", "128", "--out", str(tmp_path / "f.npz"),
                 "--ssi", str(modes), "--tyre", str(out / "true.tyre.toml"), "--quiet"]) == 0
    table = read_mode_table(modes)
    flags = table.extra["label_flag"]
    found = correct = flagged_correct = 0
    for i in range(len(table)):
        f = float(table.freq_hz[i])
        near = [t for t in truth if abs(t[2] - f) < 0.01 * t[2]]
        if not near:
            continue
        n, branch, _ = min(near, key=lambda t: abs(t[2] - f))
        found += 1
        # the model's label is the truth's, whether or not the SSI's own label is
        assert table.extra["model_n"][i] == str(n), (f, table.extra["model_n"][i], n)
        ssi_branch = table.branch[i] or "standing"
        if int(table.n[i]) == n and ssi_branch == branch:
            correct += 1
            flagged_correct += bool(flags[i])
    assert found >= 10, found  # measured: 11 of the 13 generated modes (the weak n = 1 pair is missed)
    assert correct >= 9, correct  # measured: 10 (the 142.8 Hz hybrid, +4 35 % / +3 33 %, reads n = 4 in SSI)
    assert flagged_correct == 0, [(float(table.freq_hz[i]), flags[i]) for i in range(len(table)) if flags[i]]
