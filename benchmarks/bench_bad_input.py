"""How many of the bad inputs of issues 14 and 23 get the promised answer.

Replays every case of ``tests/bad_input_cases.py`` through ``ringfit.cli.main``
(each in a fresh copy of small valid fixtures) and prints the count: exit
status 2, one stderr line naming the file/row/field/option, nothing written
or changed — or, for the few cases marked documented, the behaviour the docs
promise. Cases run one after another in a worker process (imports paid once);
a case that hangs (XLA loops do not see Python signals) is killed after
``--timeout`` seconds, counted as a failure, and the worker is restarted.

    .venv/bin/python benchmarks/bench_bad_input.py [--quick] [--only SUBSTRING] [-v] [--timeout S]

``--quick`` leaves out the cases that run a real fit. The count is printed per
issue and item (issue 23 item 3: the crashes, hangs and silent answers a new
user found), with the wall time, the CPU time of this process and its workers,
and the load average at the start and the end.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import queue
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")
TESTS = str(Path(__file__).resolve().parents[1] / "tests")
sys.path.insert(0, TESTS)


def _worker(tasks, results, fixtures, workdir):
    sys.path.insert(0, TESTS)
    from bad_input_cases import CASES, replay

    while True:
        i = tasks.get()
        if i is None:
            return
        d = Path(workdir) / f"c{i:03d}"
        shutil.copytree(fixtures, d, symlinks=True)
        os.chdir(d)
        o = replay(CASES[i], d)
        os.chdir(workdir)
        shutil.rmtree(d, ignore_errors=True)
        results.put((i, o.ok, str(o.status), o.why, time.process_time()))


def main() -> int:
    from bad_input_cases import CASES, build_fixtures

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="leave out the cases that run a real fit")
    ap.add_argument("--only", default=None, help="run only the cases whose id contains this text")
    ap.add_argument("--timeout", type=float, default=90.0, help="seconds before a case counts as a hang (default 90)")
    ap.add_argument("-v", "--verbose", action="store_true", help="one line per case")
    args = ap.parse_args()
    todo = [i for i, c in enumerate(CASES) if not (args.quick and c.slow) and (args.only is None or args.only in c.id)]
    ctx = mp.get_context("spawn")
    load0 = os.getloadavg()
    t0, c0 = time.perf_counter(), time.process_time()
    worker_cpu = {}  # the CPU time each worker process had used at its last answer
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        fixtures = build_fixtures(Path(tmp) / "_fixtures")
        worker = None
        for i in todo:
            if worker is None or not worker[0].is_alive():
                tasks, res = ctx.Queue(), ctx.Queue()
                proc = ctx.Process(target=_worker, args=(tasks, res, str(fixtures), tmp), daemon=True)
                proc.start()
                worker = (proc, tasks, res)
            proc, tasks, res = worker
            tasks.put(i)
            # the first case of a fresh worker also pays the imports
            try:
                _, ok, status, why, worker_cpu[proc.pid] = res.get(timeout=args.timeout + 30)
            except queue.Empty:
                proc.kill()
                proc.join()
                worker = None
                ok, status, why = False, "timeout", f"still running after {args.timeout:g} s (killed)"
            results[i] = (ok, status, why)
            if args.verbose:
                print(f"{'ok ' if ok else 'BAD'} {CASES[i].id:<45} {status:<9} {why}", flush=True)
        if worker is not None:
            worker[1].put(None)
            worker[0].join(timeout=10)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0 + sum(worker_cpu.values())
    good = sum(r[0] for r in results.values())
    by_item = Counter((CASES[i].issue, CASES[i].item) for i in results)
    good_item = Counter((CASES[i].issue, CASES[i].item) for i, r in results.items() if r[0])
    print(f"\n{good} of {len(results)} cases got the promised answer ({wall:.1f} s wall, {cpu:.1f} s CPU; "
          f"load average {load0[0]:.2f} at the start, {os.getloadavg()[0]:.2f} at the end, {os.cpu_count()} cores)")
    for issue, item in sorted(by_item):
        print(f"  issue {issue} item {item}: {good_item[issue, item]} of {by_item[issue, item]}")
    bad = [(CASES[i], r) for i, r in results.items() if not r[0]]
    if bad:
        print("not yet:")
        for c, (_, status, why) in bad:
            print(f"  {c.id:<45} {status:<10} {why}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
