"""How many of issue 14's bad inputs get the promised answer.

Replays every case of ``tests/bad_input_cases.py`` through ``ringfit.cli.main``
(each in a fresh copy of small valid fixtures) and prints the count: exit
status 2, one stderr line naming the file/row/field/option, nothing written
or changed — or, for the few cases marked documented, the behaviour the docs
promise. Cases run one after another in a worker process (imports paid once);
a case that hangs (XLA loops do not see Python signals) is killed after
``--timeout`` seconds, counted as a failure, and the worker is restarted.

    .venv/bin/python benchmarks/bench_bad_input.py [--quick] [--only SUBSTRING] [-v] [--timeout S]

``--quick`` leaves out the cases that run a real fit. The time is printed as wall and CPU (this
process and its workers), with the load average at the start and the end.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import queue
import shutil
import sys
import tempfile
from collections import Counter
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")
TESTS = str(Path(__file__).resolve().parents[1] / "tests")
sys.path.insert(0, TESTS)
sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402


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
        results.put((i, o.ok, str(o.status), o.why))


def main() -> int:
    from bad_input_cases import CASES, build_fixtures

    ap = bc.parser(__doc__.splitlines()[0], quick_help="leave out the cases that run a real fit")
    ap.add_argument("--only", default=None, help="run only the cases whose id contains this text")
    ap.add_argument("--timeout", type=bc.seconds(), default=90.0,
                    help="seconds before a case counts as a hang (default 90)")
    ap.add_argument("-v", "--verbose", action="store_true", help="one line per case")
    args = ap.parse_args()
    todo = [i for i, c in enumerate(CASES) if not (args.quick and c.slow) and (args.only is None or args.only in c.id)]
    if not todo:
        bc.fail(f"--only {args.only!r}: no case id contains it")
    bc.start(f"bench_bad_input: {len(todo)} case(s)" + (" [--quick]" if args.quick else ""))
    ctx = mp.get_context("spawn")
    clock = bc.Clock().__enter__()
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
                _, ok, status, why = res.get(timeout=args.timeout + 30)
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
    clock.__exit__(None, None, None)
    good = sum(r[0] for r in results.values())
    by_item = Counter(CASES[i].item for i in results)
    good_item = Counter(CASES[i].item for i, r in results.items() if r[0])
    print(f"\n{good} of {len(results)} cases got the promised answer ({clock.wall:.1f} s wall, {clock.cpu:.1f} s CPU "
          f"with the workers')")
    for item in sorted(by_item):
        print(f"  issue item {item}: {good_item[item]} of {by_item[item]}")
    bad = [(CASES[i], r) for i, r in results.items() if not r[0]]
    if bad:
        print("not yet:")
        for c, (_, status, why) in bad:
            print(f"  {c.id:<45} {status:<10} {why}")
    bc.finish()
    return 0


if __name__ == "__main__":
    sys.exit(main())
