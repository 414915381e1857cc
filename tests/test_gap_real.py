"""The gap diagnosis on the source study's real measurements (ringfit/data: the thesis's Table 2).

(a) the SSI and the FRF table of the same free tyre as reference and test: nothing to explain;
(b) leave-modes-out on the real free tyre alone: nothing to explain;
(c) a loaded table predicted from the real free fit by the contact model at 4 kN, then made to look
    like a real table (modes missing, an n = 1 row with 20 % damping, scattered damping, no
    freq_std_hz, tags instead of branches, one row without n): ground_contact, with a held-out
    shrink near the ideal one;
and the diagnosis's baseline is ``ringfit fit`` of free.modes.csv (issue 11: one engine).
"""

import json
import math
import shutil

import numpy as np
import pytest

from ringfit.cli import main
from ringfit.data import path as data_path
from ringfit.gap import diagnose
from ringfit.io.modes import ModeTable, read_mode_table, write_mode_table
from ringfit.io.tyre import read_tyre

pytestmark = pytest.mark.slow


def _folder(tmp_path, name, frf=False):
    f = tmp_path / name
    f.mkdir()
    shutil.copy(data_path("table9.tyre.toml"), f / "tyre.toml")
    shutil.copy(data_path("free-ssi.modes.csv"), f / "free.modes.csv")
    shutil.copy(data_path("free-ssi.modes.json"), f / "free.modes.json")
    if frf:
        shutil.copy(data_path("free-frf.modes.csv"), f / "frf.modes.csv")
        shutil.copy(data_path("free-frf.modes.json"), f / "frf.modes.json")
    return f


def test_a_ssi_and_frf_of_the_same_free_tyre_need_no_effect(tmp_path):
    d = diagnose(_folder(tmp_path, "a", frf=True), progress=False)
    assert d.verdict["effects"] == ["none"], d.verdict
    # the damping family has its own verdict and cannot make the structural one
    assert "damping" in d.verdict and d.verdict["damping"]["effects"][0] in ("none", "unexplained")
    assert "identification spread" in d.content["baseline"]["noise_method"]


def test_b_leave_modes_out_on_the_real_free_tyre(tmp_path):
    d = diagnose(_folder(tmp_path, "b"), progress=False)
    assert d.verdict["effects"] == ["none"], d.verdict
    assert d.content["baseline"]["heldout_method"].startswith("leave-modes-out")
    rows = d.content["rows"]
    assert len(rows) == 9 and all({"measured", "baseline", "sigma", "outlier"} <= set(r) for r in rows)


def _real_looking_loaded_table(folder, seed=7):
    """The contact model's loaded modes of the real free fit, degraded as real tables are."""
    from ringfit.fit.least_squares import fit_natural_frequencies
    from ringfit.gap.modal_conditions import contact_patch
    from ringfit.physics.loaded import loaded_natural_frequencies

    tyre = read_tyre(folder / "tyre.toml")
    free = read_mode_table(folder / "free.modes.csv")
    fit = fit_natural_frequencies(free, tyre.geometry, tyre.ring, prior="physical")
    ring = tyre.ring.replace(**{k: fit.values[k] for k in ("rho_a", "ei", "kw", "kv")})
    a, _ = contact_patch(ring, tyre.geometry, 4000.0)
    cos_t, sin_t = (np.asarray(x) for x in loaded_natural_frequencies(ring, tyre.geometry, a))
    rng = np.random.default_rng(seed)
    rows = []
    for n in range(1, 8):
        for tag, f in (("vert" if n == 1 else "extr", cos_t[n - 1]), ("hort" if n == 1 else "0", sin_t[n - 1])):
            if (n, tag) in ((5, "0"), (7, "extr"), (3, "extr")):  # modes the identification missed
                continue
            damping = 20.0 if (n, tag) == (1, "vert") else float(np.exp(rng.normal(np.log(3.0), 0.4)))
            rows.append((n, tag, f * (1 + 0.004 * rng.standard_normal()), damping, f))
    n = np.array([r[0] for r in rows])
    n[[i for i, r in enumerate(rows) if r[:2] == (6, "0")]] = -1  # a row whose n the user did not assign
    table = ModeTable(freq_hz=np.array([r[2] for r in rows]), n=n, tag=np.array([r[1] for r in rows], dtype=object),
                      damping_pct=np.array([r[3] for r in rows]),
                      condition={"state": "loaded", "load_n": 4000.0, "speed_kmh": 0, "pressure_bar": 2.2,
                                 "frame": "fixed"})
    write_mode_table(table, folder / "loaded.modes.csv")
    return table, math.degrees(a), np.array([r[2] - r[4] for r in rows])


def test_c_real_looking_loaded_table_is_ground_contact(tmp_path):
    folder = _folder(tmp_path, "c")
    table, a_deg, noise = _real_looking_loaded_table(folder)
    assert 9.0 < a_deg < 14.0  # the 4 kN patch of this tyre (docs/physics.md §7: 11.7° for Table 9)
    d = diagnose(folder, progress=False)
    v = d.verdict
    assert v["effects"][0] == "ground_contact", v
    c = d.content
    best = next(x for x in c["candidates"] if x["effect"] == "ground_contact" and x["accepted"])
    # ideal shrink from the injected noise: the free rows (real data, which the effect does not touch) keep
    # their held-out residual; the loaded rows can at best come down to the noise added to them
    rows = c["rows"]
    free = [r for r in rows if r["short"].startswith("free")]
    loaded = [r for r in rows if not r["short"].startswith("free")]
    assert len(loaded) == noise.size

    def psi2(z):
        return z * z if abs(z) <= 2 else 4 * abs(z) - 4  # the diagnosis's Huber (c = 2) on test rows

    ss_before = sum(r["z_baseline"] ** 2 for r in free) + sum(psi2(r["z_baseline"]) for r in loaded)
    ss_noise = sum(r["z_baseline"] ** 2 for r in free) + sum((e / r["sigma"]) ** 2 for e, r in zip(noise, loaded))
    ideal = 100 * (1 - ss_noise / ss_before)
    assert abs(best["heldout_shrink_pct"] - ideal) < 10, (best["heldout_shrink_pct"], ideal)
    # both variants are reported; the computed one is a prediction with no free parameter
    variants = {x["variant"] for x in c["candidates"] if x["effect"] == "ground_contact"}
    assert variants == {"computed", "fitted"}
    comp = next(x for x in c["candidates"] if x["effect"] == "ground_contact" and x["variant"] == "computed")
    assert comp["evidence"]["free_parameters_added"] == 0 and comp["params"]["patch_scale"]["value"] == 1.0
    # the verdict names the rows it explains; the row without n was matched by frequency
    assert any("loaded" in r for r in v["explains"])
    assert any("match" in r and "n matched to 6" in r["match"] for r in c["rows"])
    # the damping family is judged apart: the 20 % n = 1 row is a damping matter, not a structural one
    assert "damping" in v
    # every row names the model mode it was compared with: tags extr/0 → the contact branches of their n
    by_row = {r["row"]: r for r in rows}
    assert "contact-symmetric" in by_row["loaded (loaded 4000 N) n=4 extr"]["model_mode"]
    assert "contact-antisymmetric" in by_row["loaded (loaded 4000 N) n=4 0"]["model_mode"]
    assert by_row["loaded (loaded 4000 N) n=4 0"]["short"] == "loaded 4 0"
    # the report: the verdict sentence names the rows, a per-row table per family, no damping row in a
    # frequency figure (separate parts)
    from ringfit.report.gap_report import verdict_sentence, write_gap_report

    sentence = verdict_sentence(c)
    assert "It explains loaded (loaded 4000 N) n=" in sentence
    html = write_gap_report(d, tmp_path / "c.html").read_text()
    assert "Rows — frequency" in html and "Rows — damping" in html and "model mode" in html
    assert "mode frequencies: held-out residual per mode" in html and "modal damping: held-out residual" in html
    freq_rows = next(p for p in c["parts"] if p["family"] == "frequency")["rows"]
    assert not any("damping" in r["row"] for r in freq_rows)


def test_diagnosis_baseline_is_ringfit_fit(tmp_path):
    """Issue 11: the same table gives the same ring through `ringfit fit` and the diagnosis's baseline."""
    folder = _folder(tmp_path, "fit")
    d = diagnose(folder, effects="cavity_mode", progress=False)
    ref = d.content["baseline"]["reference_fit"]
    sigma_rel = ref["sigma_rel"]
    out = tmp_path / "fitted.toml"
    assert main(["fit", str(folder / "free.modes.csv"), "--tyre", str(folder / "tyre.toml"), "--out", str(out),
                 "--default-std", repr(sigma_rel)]) == 0
    fitted = read_tyre(out).ring_values
    for k in ("rho_a", "ei", "kw", "kv"):
        assert fitted[k] == pytest.approx(ref["values"][k], rel=1e-8)
        assert d.content["baseline"]["parameters"][k] == pytest.approx(ref["values"][k], rel=1e-5)
    assert json.loads(d.to_json())["verdict"]["effects"] == ["none"]


def test_rows_own_identification_sigma_is_used(tmp_path):
    """freq_std_hz and damping_std_pct of a table (what `ringfit ssi` writes) reach the diagnosis's σ:
    a row with a wide damping σ is weighted by it, a row with a wide frequency σ too."""
    from ringfit.gap.effects import get
    from ringfit.gap.modal import build_modal_problems

    folder = _folder(tmp_path, "sig")
    table, _, _ = _real_looking_loaded_table(folder)
    tyre = read_tyre(folder / "tyre.toml")
    free = read_mode_table(folder / "free.modes.csv")
    std = np.full(len(table), "", dtype=object)
    std[3] = "10"  # ± 10 percentage points on a ~3 % damping: δζ/ζ ≈ 3, far above a table's scatter
    fstd = np.full(len(table), np.nan)
    fstd[4] = 20.0  # ± 20 Hz
    loaded = ModeTable(freq_hz=table.freq_hz, n=table.n, tag=table.tag, damping_pct=table.damping_pct,
                       freq_std_hz=fstd, condition=table.condition, extra={"damping_std_pct": std})
    freq, damp = build_modal_problems([free, loaded], tyre, (get("ground_contact"),))
    m_free = int((free.kind == "structural").sum())
    assert damp.sigma[m_free + 3] == pytest.approx(10 / table.damping_pct[3], rel=1e-9)
    others = np.delete(damp.sigma[m_free:], 3)
    assert np.all(others < 0.5 * damp.sigma[m_free + 3])
    assert freq.sigma[m_free + 4] >= 20.0 and np.all(np.delete(freq.sigma[m_free:], 4) < 10.0)
