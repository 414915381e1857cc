"""A campaign of synthetic tyres on dask.distributed: serial vs a LocalCluster of 1 and 2 workers (issue 16).

Each tyre is a case folder from :func:`ringfit.synth.cases.make_case` (free,
loaded and spinning mode tables; a hidden effect drawn at random); one tyre's
free frequencies are raised by 8 % so the campaign report has an outlier to
find. The work per tyre is what ``ringfit campaign`` runs: its loaded tables make it
``ringfit identify`` with its posterior (STEPS steps), then ``ringfit diagnose`` (a tyre
with a free table only: ``ringfit fit`` → ``ringfit sample``, 16 walkers × STEPS steps).

- **serial**: the same commands one after another in this process
  (``ringfit.batch.execute``, which is what a worker runs).
- **LocalCluster, 1 and 2 workers**: ``ringfit.batch.run_tasks``; each
  cluster runs the campaign twice: a cold pass (the workers compile; the
  persistent compilation cache may already hold the executables) and a warm
  pass (the figures "once workers are warm").

Printed against the issue's targets:

- speed-up of the warm 2-worker pass over the warm serial pass (2 cores:
  ideal 2×);
- per-task overhead beyond the work itself, warm: the mean time a worker
  spends between the end of one task and the start of its next, target
  < 50 ms; the round trip of an empty task; and (workers × wall − Σ task
  time) / tasks, which also counts workers idle at the end of the run;
- peak resident memory per worker process, and the largest rise of one task;
- XLA compilations in tasks after a worker's first of their kind (tyres with
  another mode count compile once more per worker);
- whether every output equals the serial one (bytes; diagnosis JSON and
  posterior draws).

Every pass is printed with its wall time and the CPU time of its tasks (``cpu_s``, the
worker's process time) beside it; the load average at the start and the end. A run in which
any task failed prints no figures: it lists the failures and exits 1.

Run: ``python benchmarks/bench_batch.py [tyres=40] [steps=300] [--keep DIR] [--quick]``
(``--quick``: 2 tyres, 100 steps, the 2-worker cluster only: a smoke run).
"""

from __future__ import annotations

import argparse
import filecmp
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402

import ringfit  # noqa: F401,E402
from ringfit.batch import execute, local_cluster, open_client, run_tasks, summarize
from ringfit.cli.batch import plan_campaign, warm_up

TARGET_OVERHEAD_S = 0.050
OUTLIER_TYRE = 17


def _noop():
    return None


def make_tyres(root: Path, n: int) -> list[Path]:
    from ringfit.io.modes import read_mode_table, write_mode_table
    from ringfit.synth.cases import make_case

    tyres = []
    for i in range(n):
        folder = root / f"tyre{i:02d}"
        make_case(folder, seed=1000 + i)
        if i == OUTLIER_TYRE:
            t = read_mode_table(folder / "free.modes.csv")
            t.freq_hz = t.freq_hz * 1.08
            write_mode_table(t, folder / "free.modes.csv", overwrite=True)
        tyres.append(folder)
    return tyres


def campaign_tasks(tyres, out: Path, steps: int):
    opts = argparse.Namespace(walkers=16, min_steps=steps, max_steps=steps, seed=0, prior="physical",
                              effects=None, force=False)
    out.mkdir(parents=True)
    return plan_campaign(tyres, out, opts)


def serial_pass(tasks):
    with bc.Clock() as c:
        results = [execute(t.name, t.fn, t.args, t.outputs, t.kind) for t in tasks]
    return results, c.wall


def cluster_runs(workers: int, tyres, root: Path, steps: int) -> dict:
    import functools

    t0 = time.perf_counter()
    cluster = local_cluster(workers)
    try:
        with open_client(cluster.scheduler_address,
                         warmup=functools.partial(warm_up, ("fit", "sample", "diagnose"))) as client:
            client.wait_for_workers(workers)
            start = time.perf_counter() - t0
            passes = {}
            for label in ("cold", "warm"):
                tasks, layout = campaign_tasks(tyres, root / f"w{workers}-{label}", steps)
                t1 = time.perf_counter()
                results = run_tasks(client, tasks, progress=False)
                passes[label] = (results, time.perf_counter() - t1, layout)
            from ringfit.batch import Task

            empty = [Task(f"empty{i}", _noop) for i in range(200)]
            t1 = time.perf_counter()
            passes["empty"] = (run_tasks(client, empty, progress=False), 0.0, {})
            empty_s = (time.perf_counter() - t1) / len(empty)
    finally:
        cluster.close()
    return dict(start=start, passes=passes, empty_s=empty_s)


def check_results(failures, label: str, results) -> None:
    """Record every task of a pass that did not succeed."""
    for r in results:
        failures.check(r.ok, f"{label}: {r.name}", f"{r.state}: {r.error}")


def _row(label, results, wall, serial_wall=None):
    s = summarize(results, wall)
    workers: dict[str, float] = {}
    for r in results:
        workers[r.worker] = max(workers.get(r.worker, 0.0), r.peak_rss_mb)
    ok = s["by_state"].get("ok", 0)
    speed = f"{serial_wall / wall:9.2f}×" if serial_wall else f"{'':>10}"
    gap = f"{1e3 * s['gap_s']:10.1f}" if np.isfinite(s["gap_s"]) and s["workers"] and "serial" not in label else f"{'—':>10}"
    return (f"{label:<18}{wall:8.1f}{speed}{s['task_s']:9.1f}{s['cpu_s']:9.1f}{gap}{1e3 * s['overhead_per_task_s']:11.0f}"
            f"{max(workers.values()):12.0f}{s['max_peak_delta_mb']:11.0f}{s['warm_compiles']:10d}"
            f"{ok:>5}/{len(results)}")


#: Fields of a diagnosis JSON that are not results: wall-clock and CPU times, and the baseline tyre file's path
#: (each run's own output folder).
VOLATILE = frozenset({"elapsed_s", "wall_s", "cpu_s", "baseline_tyre"})


def _without_timing(x):
    """A diagnosis JSON without its :data:`VOLATILE` fields (times and paths, not results)."""
    if isinstance(x, dict):
        return {k: _without_timing(v) for k, v in x.items() if k not in VOLATILE}
    if isinstance(x, list):
        return [_without_timing(v) for v in x]
    return x


def identical(layout_a: dict, layout_b: dict) -> tuple[int, int]:
    """(tyres whose fitted TOML, posterior draws and diagnosis JSON equal the other run's, tyres compared).

    Fitted TOML: bytes; posterior: draws and metadata; diagnosis: the JSON less its :data:`VOLATILE` fields.
    """
    import json

    import h5py

    same = 0
    for tyre, a in layout_a.items():
        b = layout_b[tyre]
        try:
            ok = filecmp.cmp(a["fitted"], b["fitted"], shallow=False)
            ok &= (_without_timing(json.loads(Path(a["diagnosis"]).read_text()))
                   == _without_timing(json.loads(Path(b["diagnosis"]).read_text())))
            with h5py.File(a["posterior"]) as ha, h5py.File(b["posterior"]) as hb:
                ok &= bool(np.array_equal(ha["chain"][()], hb["chain"][()]))
                ok &= dict(ha.attrs) == dict(hb.attrs)
        except OSError:
            ok = False
        same += bool(ok)
    return same, len(layout_a)


def main() -> None:
    ap = bc.parser(__doc__.splitlines()[0], quick_help="2 tyres, 100 steps, the 2-worker cluster only (smoke run)")
    ap.add_argument("tyres", nargs="?", type=bc.count("a number of tyres", 1, 1000), default=40)
    ap.add_argument("steps", nargs="?", type=bc.count("a number of sampler steps (ringfit sample needs >= 100)",
                                                      100, 10**6), default=300)
    ap.add_argument("--keep", type=Path, default=None, help="work in this (new) folder and keep it")
    args = ap.parse_args()
    if args.quick:
        args.tyres, args.steps = 2, 100
    if args.keep and args.keep.exists():
        bc.fail(f"--keep {args.keep}: already exists; give a new folder")
    if args.tyres <= OUTLIER_TYRE:
        print(f"(fewer than {OUTLIER_TYRE + 1} tyres: the campaign has no planted outlier)")
    bc.start(f"bench_batch: {args.tyres} tyres, {args.steps} sampler steps" + (" [--quick]" if args.quick else ""))
    if args.keep:
        args.keep.mkdir(parents=True)
        root = args.keep
    else:
        tmp = tempfile.TemporaryDirectory(prefix="bench_batch_")
        root = Path(tmp.name)


    failures = bc.Failures()
    t0 = time.perf_counter()
    tyres = make_tyres(root / "campaign", args.tyres)
    print(f"{args.tyres} synthetic tyres written in {time.perf_counter() - t0:.1f} s; the tasks `ringfit campaign` "
          f"plans per tyre (identify with its posterior, or fit and sample; {args.steps} sampler steps; then "
          "diagnose)")

    serial = {}
    for label in ("cold", "warm"):
        tasks, layout = campaign_tasks(tyres, root / f"serial-{label}", args.steps)
        results, wall = serial_pass(tasks)
        check_results(failures, f"serial, {label}", results)
        serial[label] = (results, wall, layout)
    runs = {w: cluster_runs(w, tyres, root, args.steps) for w in ((2,) if args.quick else (1, 2))}
    for w, run in runs.items():
        for label, (res, _, _) in run["passes"].items():
            check_results(failures, f"{w} worker(s), {label}", res)
    failures.refuse()

    print()
    print(f"{'':<18}{'wall':>8}{'speed-up':>10}{'Σ tasks':>9}{'Σ CPU':>9}{'gap/task':>10}{'idle/task':>11}{'RSS/worker':>12}"
          f"{'task rise':>11}{'compiles':>10}{'ok':>8}")
    print(f"{'':<18}{'[s]':>8}{'':>10}{'[s]':>9}{'[s]':>9}{'[ms]':>10}{'[ms]':>11}{'peak [MiB]':>12}{'[MiB]':>11}"
          f"{'warm':>10}")
    for label in ("cold", "warm"):
        res, wall, _ = serial[label]
        print(_row(f"serial, {label}", res, wall, serial[label][1]))
    for w, run in runs.items():
        for label in ("cold", "warm"):
            res, wall, _ = run["passes"][label]
            print(_row(f"{w} worker{'s' if w > 1 else ' '}, {label}", res, wall, serial[label][1]))
    print()
    work = sum(r.elapsed_s for r in serial["warm"][0])
    work_cpu = sum(r.cpu_s for r in serial["warm"][0])
    kinds = [k for k in ("ssi", "identify", "fit", "sample", "diagnose") if any(r.kind == k for r in serial["warm"][0])]
    per_task = {k: np.mean([r.elapsed_s for r in serial["warm"][0] if r.kind == k]) for k in kinds}
    print(f"work per tyre (serial, warm): {work / args.tyres:.2f} s wall ({work_cpu / args.tyres:.2f} s CPU) = "
          + " + ".join(f"{k} {v:.2f} s" for k, v in per_task.items()))
    for w, run in runs.items():
        res, wall, _ = run["passes"]["warm"]
        s = summarize(res, wall)
        mark = "OK" if s["gap_s"] < TARGET_OVERHEAD_S else "MISSED"
        print(f"{w} worker{'s' if w > 1 else ''}: start + warm-up {run['start']:.1f} s; warm overhead per task "
              f"{1e3 * s['gap_s']:.1f} ms between tasks (target < {1e3 * TARGET_OVERHEAD_S:.0f} ms: {mark}); "
              f"empty-task round trip {1e3 * run['empty_s']:.1f} ms; "
              f"{1e3 * s['overhead_per_task_s']:.0f} ms/task with the idle start and end")
    speed = serial["warm"][1] / runs[2]["passes"]["warm"][1]
    ncpu = bc.usable_cores()
    print(f"speed-up, 2 workers vs serial (warm, wall): {speed:.2f}× on {ncpu} CPUs (other processes share "
          f"these CPUs: see the load averages)")
    if 1 in runs:
        eff = runs[1]["passes"]["warm"][1] / runs[2]["passes"]["warm"][1]
        print(f"2 workers vs 1 worker (warm): {eff:.2f}×; Σ task time {summarize(runs[2]['passes']['warm'][0])['task_s']:.0f} s "
              f"vs {summarize(runs[1]['passes']['warm'][0])['task_s']:.0f} s (a task runs slower when both CPUs are busy)")
    same, total = identical(serial["warm"][2], runs[2]["passes"]["warm"][2])
    print(f"outputs identical to the serial run's (fitted TOML, diagnosis JSON bytes; posterior draws): "
          f"{same}/{total} tyres")

    from ringfit.report.campaign import collect_campaign, write_campaign_report

    res, _, layout = runs[2]["passes"]["warm"]
    campaign = collect_campaign(layout, res)
    report = root / "campaign.html"
    write_campaign_report(campaign, report)
    print(f"campaign: {campaign.summary_line()} (tyre{OUTLIER_TYRE:02d} has its free frequencies raised 8 %); "
          f"verdicts {campaign.verdict_counts()}")
    if args.keep:
        print(f"report: {report}")
    bc.finish()


if __name__ == "__main__":
    main()
