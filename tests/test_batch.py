"""`ringfit batch` / `ringfit campaign` on a LocalCluster of 2 worker processes (issue 16).

One cluster serves the whole module (its start takes seconds); the CLI reaches
it with --scheduler, as a user reaches a remote one. Expected files come from
the serial command run in this process on the same inputs; campaign numbers
are recomputed here from the raw draws in the posterior file.
"""

import os
import re
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("distributed")

import cloudpickle  # noqa: E402  (comes with distributed)

from ringfit.batch import Task, TaskFailed, execute, local_cluster, open_client, run_tasks  # noqa: E402
from ringfit.cli import main  # noqa: E402
from ringfit.cli.batch import output_stems, plan_batch, OUTPUT_RULES  # noqa: E402
from ringfit.data import path as data_path  # noqa: E402
from ringfit.errors import InputError  # noqa: E402

MODES = data_path("free-ssi.modes.csv")
TYRE = data_path("table9.tyre.toml")
SAMPLE_OPTS = ["--walkers", "8", "--min-steps", "150", "--max-steps", "150"]

# the test functions below travel to the workers by value (this module is not importable there)
cloudpickle.register_pickle_by_value(sys.modules[__name__])


@pytest.fixture(scope="module")
def cluster():
    cl = local_cluster(2, memory_limit="3GB")
    yield cl
    cl.close()


@pytest.fixture(scope="module")
def tables(tmp_path_factory):
    """Three good free-tyre tables (the bundled SSI table, frequencies scaled) and a broken one."""
    folder = tmp_path_factory.mktemp("tables")
    text = Path(MODES).read_text().splitlines()
    header = text[0].split(",")
    col = header.index("freq_hz")
    good = []
    for i, scale in enumerate((1.0, 1.01, 0.99)):
        rows = [header]
        for line in text[1:]:
            cells = line.split(",")
            cells[col] = repr(float(cells[col]) * scale)
            rows.append(cells)
        p = folder / f"tyre{i}.modes.csv"
        p.write_text("\n".join(",".join(r) for r in rows) + "\n")
        good.append(p)
    broken = folder / "broken.modes.csv"
    broken.write_text("n,freq_hz\n1,104.2\n2,nan\n3,140.1\n")
    return good, broken


def _serial_error(argv, capsys):
    """The one-line error the serial command prints (last stderr line)."""
    capsys.readouterr()
    status = main(argv)
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    return status, err[-1]


# ============================================================================ naming, planning, bad arguments
def test_output_names_follow_the_documented_rule(tmp_path):
    fit = OUTPUT_RULES["fit"]
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    assert output_stems([str(tmp_path / "x" / "run1.modes.csv"), str(tmp_path / "y.MODES.CSV")], fit) == ["run1", "y"]
    assert output_stems([str(tmp_path / "a")], OUTPUT_RULES["diagnose"]) == ["a"]
    # the same stem in two folders: the parent folder's name goes in front
    assert output_stems([str(tmp_path / "a" / "free.modes.csv"), str(tmp_path / "b" / "free.modes.csv"),
                         str(tmp_path / "c.modes.csv")], fit) == ["a-free", "b-free", "c"]
    with pytest.raises(InputError, match="same output"):
        output_stems([str(tmp_path / "a" / "free.modes.csv"), str(tmp_path / "q" / "a" / "free.modes.csv")], fit)
    plans = plan_batch("fit", [str(tmp_path / "a" / "free.modes.csv")], tmp_path / "out",
                       ["--plot", "{out}.png", "--prior", "none"], force=True)
    assert plans[0].argv == ["fit", str(tmp_path / "a" / "free.modes.csv"), "--out",
                             str(tmp_path / "out" / "free.fitted.tyre.toml"), "--plot",
                             str(tmp_path / "out" / "free") + ".png", "--prior", "none", "--tyre",
                             str(tmp_path / "a" / "tyre.toml"), "--force"]
    est = plan_batch("estimate", ["r/run1.profile.csv", "r/drive.records.npz"], "o", ["--tyre", "fitted.toml"])
    assert est[0].argv == ["estimate", "r/run1.profile.csv", "--out", "o/run1.estimate.json", "--tyre",
                           "fitted.toml", "--quiet"]
    assert est[1].outputs == ["o/drive.estimate.json"]
    ssi = plan_batch("ssi", ["r/t1.records.npz"], "o", ["--workers", "3"])[0]
    assert ssi.argv.count("--workers") == 1 and ssi.outputs == ["o/t1.modes.csv", "o/t1.modes.json"]
    with pytest.raises(InputError, match="--out"):
        plan_batch("fit", ["a.modes.csv"], "o", ["--out", "x"])
    with pytest.raises(InputError, match="placeholder"):
        plan_batch("fit", ["a.modes.csv"], "o", ["--tyre", "{folder}/t.toml"])


def test_bad_batch_arguments_exit_2_before_any_work(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["batch", "fit", str(MODES)]) == 2  # no --out
    assert main(["batch", "fit", str(MODES), "--out", str(out), "--", "--walkers", "3"]) == 2  # not a fit option
    err = capsys.readouterr().err
    assert "--walkers" in err and len(err.strip().splitlines()) == 2
    assert main(["batch", "fit", str(MODES), str(MODES), "--out", str(out)]) == 2
    assert main(["batch", "fit", str(MODES), "--out", str(out), "--workers", "2", "--scheduler", "tcp://x:1"]) == 2
    assert main(["batch", "fit", str(MODES), "--out", str(out), "--memory-limit", "lots"]) == 2
    assert not out.exists()
    assert main(["campaign", str(tmp_path), "--out", str(out)]) == 2  # no case folder in it
    assert main(["batch", "fit", str(MODES), "--out", str(out), "--dry-run", "--", "--tyre", str(TYRE)]) == 0
    assert capsys.readouterr().out.startswith(f"ringfit fit {MODES} --out {out / 'free-ssi.fitted.tyre.toml'}")


def test_campaign_reads_every_tyre_folder_with_the_case_reader_before_any_work(tmp_path, capsys):
    """A tyre folder the case reader refuses stops the campaign before any work: exit 2, one line naming the file
    (a sidecar that is not JSON is not skipped; a folder without free.modes.csv or free records is refused)."""
    from ringfit.synth.cases import make_case

    camp, out = tmp_path / "camp", tmp_path / "out"
    make_case(camp / "tyreA", effect="none", seed=3)
    make_case(camp / "tyreB", effect="none", seed=4)
    (camp / "tyreB" / "loaded.modes.json").write_text('{"state": "loaded", "load_n": 4000,')  # cut short
    capsys.readouterr()
    assert main(["campaign", str(camp), "--out", str(out), "--workers", "1", "--quiet"]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and str(camp / "tyreB" / "loaded.modes.json") in err[0], err
    assert not out.exists()
    (camp / "tyreB" / "loaded.modes.json").unlink()
    (camp / "tyreB" / "loaded.modes.csv").unlink()
    (camp / "tyreB" / "free.modes.csv").unlink()
    assert main(["campaign", str(camp), "--out", str(out), "--workers", "1", "--quiet"]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and "free.modes.csv" in err[0] and "tyreB" in err[0], err
    assert not out.exists()


def test_campaign_joint_data_from_the_read_tables(tmp_path):
    """Joint data (identify instead of fit and sample): a profile, or a standing loaded table, as read."""
    from ringfit.cli.batch import read_campaign_tyre
    from ringfit.synth.cases import make_case

    make_case(tmp_path / "t", effect="none", seed=3)
    assert read_campaign_tyre(tmp_path / "t").joint_data  # its standing loaded table
    (tmp_path / "t" / "loaded.modes.json").write_text(
        '{"state": "loaded", "load_n": 4000, "speed_kmh": 40, "pressure_bar": 2.2, "frame": "fixed"}')
    assert not read_campaign_tyre(tmp_path / "t").joint_data  # a rolling one is not


# ============================================================================ one task, in this process
def _jitted_twice():
    import jax
    import jax.numpy as jnp

    f = jax.jit(lambda x: jnp.cumsum(x) ** 2)
    f(jnp.ones(7)).block_until_ready()
    return f


def _allocate(mb):
    a = np.ones(int(mb * 2**20 / 8))
    return float(a.sum())


def test_execute_measures_memory_and_compiles_and_reports_failures():
    big = execute("big", _allocate, (300,))
    assert big.ok and big.value == 300 * 2**20 / 8
    assert 295 <= big.peak_delta_mb <= 330, big.peak_delta_mb  # the 300 MiB array, measured by the kernel
    small = execute("small", _allocate, (1,))
    assert small.peak_delta_mb < 30  # the high-water mark was reset between tasks
    first = execute("jit", _jitted_twice)
    assert first.compiles >= 1
    f = first.value
    again = execute("call", lambda: f(np.ones(7)).block_until_ready())
    assert again.ok and again.compiles == 0
    bad = execute("bad", _raise, (TaskFailed("input.csv: row 3: nan", status=2),))
    assert (bad.state, bad.status, bad.error) == ("failed", 2, "input.csv: row 3: nan")
    crash = execute("crash", _raise, (ZeroDivisionError("x\ny"),))
    assert (crash.state, crash.status, crash.error) == ("failed", 1, "ZeroDivisionError: x y")
    assert "Traceback" in crash.log


def _raise(exc):
    print("some output")
    raise exc


# ============================================================================ the cluster
@pytest.mark.slow  # end to end, > 7 s: CI runs it with -m slow (issue 24 item 3)
def test_batch_fit_matches_serial_and_survives_a_broken_input(cluster, tables, tmp_path, capsys, monkeypatch):
    good, broken = tables
    monkeypatch.chdir(tmp_path)  # relative paths: the workers read them from the batch's folder
    inputs = [os.path.relpath(p) for p in (good[0], broken, good[1], good[2])]
    broken = inputs[1]
    out = Path("batch")
    status = main(["batch", "fit", *inputs, "--out", str(out), "--scheduler", cluster.scheduler_address,
                   "--quiet", "--", "--tyre", str(TYRE)])
    printed = capsys.readouterr().out
    assert status == 1
    # the serial command, input by input, in this process
    serial = Path("serial")
    serial.mkdir()
    plans = plan_batch("fit", inputs, serial, ["--tyre", str(TYRE)])
    for plan in plans:
        if plan.input != str(broken):
            assert main(plan.argv) == 0
    for plan in plans:
        name = Path(plan.outputs[0]).name
        if plan.input == str(broken):
            assert not (out / name).exists()
        else:
            assert (out / name).read_bytes() == (serial / name).read_bytes()
    status, error = _serial_error(plans[1].argv, capsys)
    assert status == 2
    line = next(x for x in printed.splitlines() if str(broken) in x)
    assert "failed" in line and error in line
    assert "3 ok, 1 failed" in printed


@pytest.mark.slow  # end to end, > 7 s: CI runs it with -m slow (issue 24 item 3)
def test_warm_workers_do_not_recompile_and_sample_matches_serial(cluster, tables, tmp_path):
    """Same-shape inputs: after a worker's first task of a kind, no XLA compilation; files as the serial ones."""
    import h5py

    good, _ = tables
    plans = plan_batch("sample", [str(p) for p in good[:2]], tmp_path / "b", ["--tyre", str(TYRE), *SAMPLE_OPTS])
    (tmp_path / "b").mkdir()
    with open_client(cluster.scheduler_address) as client:
        tasks = [Task(p.input, _run, (p.argv,), outputs=tuple(p.outputs), kind="sample") for p in plans]
        tasks += [Task(p.input + "#2", _run, (p.argv[:3] + [p.outputs[0] + ".2.h5"] + p.argv[4:],), kind="sample")
                  for p in plans]
        results = run_tasks(client, tasks, progress=False)
    assert all(r.ok for r in results), [r.error for r in results]
    assert len({r.worker for r in results}) == 2
    for r in results:
        if r.kind_index > 0:
            assert r.compiles == 0, (r.name, r.worker, r.kind_index, r.compiles)
    serial = plan_batch("sample", [str(good[1])], tmp_path, ["--tyre", str(TYRE), *SAMPLE_OPTS])[0]
    assert main(serial.argv) == 0
    with h5py.File(serial.outputs[0]) as a, h5py.File(plans[1].outputs[0]) as b:
        assert dict(a.attrs) == dict(b.attrs)
        for key in ("chain", "log_prob", "acceptance", "tau"):
            np.testing.assert_array_equal(a[key][()], b[key][()])


def _run(argv):
    from ringfit.cli.batch import run_command

    return run_command(argv)


def _make_campaign(root: Path):
    from ringfit.io.records import write_records
    from ringfit.params import table9
    from ringfit.synth.cases import make_case
    from ringfit.synth.records import impact_records, ring_modes

    make_case(root / "tyreA", effect="none", seed=3)
    # tyreA: free modes and rolling tables only (no joint data): fitted and sampled; tyreB keeps its standing loaded
    # table at load_n: identified once (ringfit identify) from its free and loaded modes
    for f in ("loaded.modes.csv", "loaded.modes.json"):
        (root / "tyreA" / f).unlink()
    make_case(root / "tyreB", effect="none", seed=4)
    # tyreB's free table comes from impact records by SSI instead
    (root / "tyreB" / "free.modes.csv").unlink()
    (root / "tyreB" / "free.modes.json").unlink()
    geometry, ring = table9()
    rec = impact_records(ring_modes(ring, geometry, seed=1), np.arange(24) * 15.0, duration_s=0.5, seed=3)
    write_records(rec, root / "tyreB" / "free.records.npz")
    make_case(root / "tyreC", effect="none", seed=5)
    # tyreC: every measurement at 2.2 bar, its tyre file at 2.5: the case reader takes the folder (with a warning),
    # identify refuses it (one pressure, not the tyre file's): a failed step in a campaign that runs
    toml = root / "tyreC" / "tyre.toml"
    toml.write_text(toml.read_text().replace("pressure_bar = 2.2", "pressure_bar = 2.5"))
    (root / "notes").mkdir()  # not a case folder: ignored


@pytest.mark.slow  # end to end, > 7 s: CI runs it with -m slow (issue 24 item 3)
def test_campaign_table_and_report_from_the_saved_files(cluster, tmp_path, capsys):
    from ringfit.fit.posterior import load_posterior
    from ringfit.io.tyre import read_tyre
    from ringfit.gap.diagnosis import read_diagnosis

    _make_campaign(tmp_path / "camp")
    out = tmp_path / "out"
    status = main(["campaign", str(tmp_path / "camp"), "--out", str(out), "--scheduler", cluster.scheduler_address,
                   "--walkers", "8", "--min-steps", "150", "--max-steps", "150", "--quiet"])
    printed = capsys.readouterr().out
    assert status == 1  # identify refuses tyreC's pressures
    assert "tyreC/identify" in printed and "pressure_bar" in printed
    import csv

    rows = {r["tyre"]: r for r in csv.DictReader((out / "campaign.csv").open())}
    assert sorted(rows) == ["tyreA", "tyreB", "tyreC"]
    assert rows["tyreC"]["status"] == "failed" and rows["tyreC"]["failed_step"] == "identify"
    assert "pressure_bar" in rows["tyreC"]["error"] and rows["tyreC"]["ei_n_m2_median"] == ""
    assert rows["tyreB"]["targets"] == "ssi:free.records.npz" and rows["tyreA"]["targets"] == "free.modes.csv"
    assert (out / "tyreB" / "case" / "free.modes.csv").exists()  # the SSI table, beside tyreB's test tables
    assert (out / "tyreB" / "case" / "loaded.modes.csv").exists()
    for tyre in ("tyreA", "tyreB"):
        row = rows[tyre]
        assert row["status"] == "ok"
        with __import__("h5py").File(out / tyre / "posterior.h5") as h5:  # the draws, read independently
            chain = h5["chain"][()]
            meta = __import__("json").loads(h5.attrs["meta"])
            shift = h5["shift_u"][()] if "shift_u" in h5 else None
        names = meta["names"]
        assert set(meta["kinds"]) == {"log"}  # the chain holds log-parameters (docs/formats.md §11)
        # tyreA: the free-mode fit's four parameters; tyreB: the identification's six (k_tread from the loaded table)
        assert len(names) == (4 if tyre == "tyreA" else 6)
        assert (out / tyre / "fitted.identify.json").exists() == (tyre == "tyreB")
        u = chain[meta["burn"]::meta["thin"]].reshape(-1, len(names))
        if shift is not None:  # docs/formats.md §11: each kept draw moves by ε δu, ε from the generator [seed, 7919]
            u = u + np.random.default_rng([int(meta.get("seed", 0)), 7919]).standard_normal(u.shape[0])[:, None] * shift
        draws = np.exp(u)
        for j, name in enumerate(names):
            key = {"rho_a": "rho_a_kg_per_m", "ei": "ei_n_m2", "kw": "kw_n_per_m2", "kv": "kv_n_per_m2",
                   "k_tread": "k_tread_n_per_m2", "damping_ratio": "damping_ratio"}[name]
            lo, med, hi = np.percentile(draws[:, j], [2.5, 50, 97.5])
            np.testing.assert_allclose([float(row[f"{key}_lo"]), float(row[f"{key}_median"]),
                                        float(row[f"{key}_hi"])], [lo, med, hi], rtol=1e-9)
            assert float(row[key]) == pytest.approx(read_tyre(out / tyre / "fitted.tyre.toml").ring_values[name],
                                                    rel=1e-9)
        if tyre == "tyreA":
            assert row["modes"] == str(len(load_posterior(out / tyre / "posterior.h5").meta["data"]["n"]))
        diagnosis = read_diagnosis(out / tyre / "diagnosis.json")
        verdict = diagnosis["verdict"]
        assert row["verdict"] == "+".join(verdict["effects"])
        # one ring per tyre: the diagnosis's baseline is the fitted tyre file the table reads, not a refit
        fitted = read_tyre(out / tyre / "fitted.tyre.toml").ring_values
        reference = diagnosis["parts"][0]["baseline"]["reference_fit"]
        assert reference["status"] == "evaluated"
        for name, value in reference["values"].items():
            assert value == pytest.approx(fitted[name], rel=1e-12)
    assert rows["tyreA"]["distance"] == ""  # two tyres: too few for the outlier test
    page = (out / "campaign.html").read_text()
    assert "tyreA" in page and "tyreC" in page and "data:image/png;base64," in page
    assert "src=\"http" not in page and "<script src" not in page  # self-contained
    # a second run resumes: nothing is recomputed, the table and report are rebuilt
    mtime = (out / "tyreA" / "posterior.h5").stat().st_mtime_ns
    assert main(["campaign", str(tmp_path / "camp"), "--out", str(out), "--scheduler",
                 cluster.scheduler_address, "--skip-existing", "--quiet"]) == 1
    assert (out / "tyreA" / "posterior.h5").stat().st_mtime_ns == mtime


# ============================================================================ lost workers (kept last: it restarts them)
def _kill_once(marker):
    runs = Path(marker + ".runs")
    runs.write_text(runs.read_text() + "x" if runs.exists() else "x")
    if not os.path.exists(marker):
        Path(marker).touch()
        os.kill(os.getpid(), 9)
    return "second try"


def _kill_always():
    os.kill(os.getpid(), 9)


def test_lost_worker_is_retried_once_then_reported(cluster, tmp_path):
    marker = str(tmp_path / "killed")
    with open_client(cluster.scheduler_address) as client:
        once, fine = run_tasks(client, [Task("once", _kill_once, (marker,)), Task("fine", _allocate, (1,))],
                               progress=False)
        client.wait_for_workers(2, timeout=240)  # a restarted worker re-imports JAX: slow on a busy machine
        # (one crash at a time: Dask counts every death of the worker that holds a task, whoever caused it)
        always, after = run_tasks(client, [Task("always", _kill_always),
                                           Task("after", _allocate, (1,), after=("always",))], progress=False)
        client.wait_for_workers(2, timeout=240)  # a restarted worker re-imports JAX: slow on a busy machine
    assert once.ok and once.value == "second try" and Path(marker + ".runs").read_text() == "xx"
    assert fine.ok
    assert always.state == "lost" and "died twice" in always.error
    assert after.state == "skipped" and "always" in after.error


# ============================================================================ outlier statistics
def test_outlier_test_is_calibrated_and_finds_a_planted_outlier():
    from ringfit.report.campaign import batch_distances

    rng = np.random.default_rng(0)
    k, N = 4, 12
    L = np.tril(rng.normal(size=(k, k))) + 2 * np.eye(k)
    pvals, any_flag = [], 0
    for _ in range(400):
        x = rng.normal(size=(N, k)) @ L.T + 5.0
        d = batch_distances(x)
        pvals.append(d["p_value"])
        any_flag += d["outlier"].any()
    p = np.concatenate(pvals)
    # leave-one-out p-values of one population are uniform (Hotelling T² → F), so ~10 % fall below 0.1
    assert 0.085 < np.mean(p < 0.1) < 0.115 and 0.035 < np.mean(p < 0.05) < 0.065
    assert any_flag / 400 < 0.08  # Bonferroni: at most 5 % of clean batches have any flag
    x = rng.normal(size=(25, k)) @ L.T
    x[7] += 8.0 * L[:, 0]  # eight standard deviations along one direction of the spread
    d = batch_distances(x)
    assert np.flatnonzero(d["outlier"]).tolist() == [7] and d["distance"][7] > d["threshold"]
    few = batch_distances(rng.normal(size=(k + 2, k)))
    assert not few["tested"] and np.isnan(few["distance"]).all()


def _prints_progress(seconds):
    """A task that draws a progress bar on stderr for a few seconds (as a diagnosis does)."""
    import sys
    import time

    print("starting")
    for i in range(4):
        sys.stderr.write(f"\rnull draws: {50 * (i + 1)}/200")
        sys.stderr.flush()
        time.sleep(seconds / 4)
    return 0


@pytest.mark.slow  # a cluster and a task of 6 s
def test_a_running_task_relays_its_progress_to_the_batch_bar(cluster, capsys):
    """Issue 34: a long task is not a frozen bar: its latest line and its run time reach the client's bar."""
    with open_client(cluster.scheduler_address) as client:
        results = run_tasks(client, [Task("t1/diagnose", _prints_progress, (6.0,))], progress=True)
    assert results[0].ok and results[0].log == "starting\n"  # bar redraws stay out of the task's log
    err = capsys.readouterr().err
    assert re.search(r"t1/diagnose 0m0\ds \[null draws: (50|100|150|200)/200\]", err), err[-500:]
