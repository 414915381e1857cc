"""Cold start: how long a fresh process takes to its first answer (issue 24, item 1).

Run: python benchmarks/bench_cold.py [--rounds 3] [--pin 0] [--quick] [--no-demo] [--no-batch] [--no-split]

Every figure is a whole process started fresh, timed from outside: wall, and CPU = the process's
user + system time (children included), as min / median / max over ``--rounds`` interleaved
rounds (each round runs every contender once, in turn). Each run of an "empty cache" contender
gets a fresh, empty ``RINGFIT_CACHE_DIR``; the "warm cache" contender shares one filled before
the rounds. Pinned to one core (``taskset -c 0``) where taskset exists. Targets (issue 24,
on one core of a quiet machine):

- ``ringfit diagnose`` of ``ringfit example case``: < 4 s with a warm compilation cache,
  < 8 s with an empty one;
- ``ringfit fit`` of the bundled SSI table: < 2 s with an empty cache;
- ``ringfit demo`` (fit + posterior + report) after install (empty cache): < 15 s;
- a batch worker (LocalCluster of one worker, the ``fit`` warm-up) ready for its first task:
  < 3 s from the start of the client's process to the first result;

beside the bare-library yardsticks in the same rounds: ``python -c "import jax"`` and a script
that imports JAX + optimistix and solves the same eq. 18 fit cold. Then (``--no-split`` skips it)
where one cold diagnosis spends its CPU time, in-process: imports, tracing, lowering to MLIR,
XLA compilation (or loading from the cache) and the rest (the work and dispatch).

``--quick``: one round, no demo, no batch worker (a smoke run: its figures are not the targets').
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "ringfit" / "data"
MODES, TYRE = DATA / "free-ssi.modes.csv", DATA / "table9.tyre.toml"

TARGETS = {"diagnose_warm": 4.0, "diagnose_empty": 8.0, "fit_empty": 2.0, "demo": 15.0, "worker": 3.0}

#: A batch worker, from the client's start: LocalCluster of one worker with the `fit` warm-up, one trivial task.
WORKER_SCRIPT = r"""
import functools, json, time
t0 = time.perf_counter()
from ringfit.batch import open_client
from ringfit.cli.batch import warm_up
if __name__ == "__main__":  # worker processes are spawned: they must not run this again
    with open_client(workers=1, warmup=functools.partial(warm_up, ("fit",))) as client:
        client.submit(sum, [1, 2]).result()
        ready = time.perf_counter() - t0
    print(json.dumps({"ready_s": ready}))
"""

#: The split of one diagnosis in-process: imports, tracing, lowering, compilation, the rest (CPU seconds).
SPLIT_SCRIPT = r"""
import json, sys, time
c0, w0 = time.process_time(), time.perf_counter()
import ringfit, jax
from jax._src import dispatch
acc = {"tracing": 0.0, "lowering": 0.0, "compilation": 0.0}
kind = {dispatch.JAXPR_TRACE_EVENT: "tracing", dispatch.JAXPR_TO_MLIR_MODULE_EVENT: "lowering",
        dispatch.BACKEND_COMPILE_EVENT: "compilation"}
depth = [0]
Base = dispatch.LogElapsedTimeContextManager
class Timed(Base):  # outermost events only (a jit traced inside another's trace counts once)
    __slots__ = ["c"]
    def __enter__(self):
        self.c = time.process_time(); depth[0] += 1
        return super().__enter__()
    def __exit__(self, *exc):
        depth[0] -= 1
        if depth[0] == 0 and self.event in kind:
            acc[kind[self.event]] += time.process_time() - self.c
        return super().__exit__(*exc)
dispatch.log_elapsed_time = Timed
ringfit.enable_compilation_cache()
from ringfit.gap import diagnose
import ringfit.gap.modal, ringfit.gap.ranking, ringfit.gap.case, ringfit.fit.engine
c1 = time.process_time()
d = diagnose(sys.argv[1], progress=False)
c2, w2 = time.process_time(), time.perf_counter()
out = {"imports": c1 - c0, **acc, "total": c2 - c0, "wall": w2 - w0, "verdict": d.verdict["effects"]}
out["rest"] = out["total"] - out["imports"] - sum(acc.values())
print(json.dumps(out))
"""


def main(argv=None) -> int:
    p = bc.parser("Cold-start figures of ringfit commands against bare JAX yardsticks (issue 24).",
                  quick_help="one round, no demo, no batch worker (a smoke run; not the targets' figures)")
    p.add_argument("--rounds", type=bc.count("a number of rounds", 1, 50), default=3,
                   help="interleaved rounds; each figure is min / median / max over them (default 3)")
    p.add_argument("--pin", default="0", help="CPU list for taskset -c (default 0; '' = no pinning)")
    p.add_argument("--no-demo", action="store_true", help="leave out `ringfit demo`")
    p.add_argument("--no-batch", action="store_true", help="leave out the batch worker")
    p.add_argument("--no-split", action="store_true", help="leave out the in-process split of a cold diagnosis")
    args = p.parse_args(argv)
    if args.pin and not all(part.strip().isdigit() for part in args.pin.replace("-", ",").split(",")):
        bc.fail(f"--pin {args.pin!r}: expected a CPU list such as 0 or 0,1")
    if args.pin and not shutil.which("taskset"):
        print("  (taskset not found: runs are not pinned)")
    rounds = 1 if args.quick else args.rounds
    demo = not (args.quick or args.no_demo)
    batch = not (args.quick or args.no_batch)
    if batch:
        try:
            import distributed  # noqa: F401
        except ImportError:
            bc.fail("the batch worker needs dask.distributed (pip install -e '.[batch]'), or give --no-batch")

    bc.start(f"bench_cold: cold processes, {rounds} interleaved round(s), pinned to CPU {args.pin or 'none'}"
             + (" [--quick: not the targets' figures]" if args.quick else ""))
    failures = bc.Failures()
    py = sys.executable
    pin = args.pin or None
    with tempfile.TemporaryDirectory(prefix="bench-cold-") as tmp:
        tmp = Path(tmp)
        # as a user's process runs: no JAX settings of ours, and Python's bytecode cache on (an installed
        # package has its .pyc files; without them each cold process recompiles ringfit's source, ~0.2–0.4 s)
        base_env = {k: v for k, v in os.environ.items()
                    if not k.startswith("JAX_") and k != "PYTHONDONTWRITEBYTECODE"}
        base_env["PYTHONPATH"] = os.pathsep.join([str(ROOT), base_env.get("PYTHONPATH", "")]).rstrip(os.pathsep)

        def env(cache: Path) -> dict:
            return {**base_env, "RINGFIT_CACHE_DIR": str(cache)}

        fresh = iter(range(10**6))

        def empty_cache() -> Path:
            return tmp / f"cache-{next(fresh)}"

        ringfit = [py, "-m", "ringfit"]
        made = bc.run_process(ringfit + ["example", "case", "--out", str(tmp / "example")], env(empty_cache()))
        case = tmp / "example" / "case"
        if not failures.check(made.ok, "ringfit example case", made.detail):
            failures.refuse()
        warm = tmp / "warm-cache"
        filled = bc.run_process(ringfit + ["diagnose", str(case), "--out", str(tmp / "fill.diagnosis.json"),
                                           "--quiet"], env(warm))
        failures.check(filled.ok, "filling the warm cache (ringfit diagnose)", filled.detail)
        failures.refuse()

        out = iter(range(10**6))

        def diagnose(cache):
            def run():
                path = tmp / f"d{next(out)}.diagnosis.json"
                r = bc.run_process(ringfit + ["diagnose", str(case), "--out", str(path), "--quiet"],
                                   env(cache() if callable(cache) else cache), pin=pin)
                if r.ok and "ground_contact" not in json.loads(path.read_text())["verdict"]["effects"]:
                    r.ok, r.detail = False, "the verdict is not ground_contact"
                return r
            return run

        def fit():
            return bc.run_process(ringfit + ["fit", str(MODES), "--tyre", str(TYRE), "--out",
                                             str(tmp / f"f{next(out)}.tyre.toml")], env(empty_cache()), pin=pin)

        def demo_run():
            return bc.run_process(ringfit + ["demo", "--out", str(tmp / f"demo{next(out)}"), "--quiet"],
                                  env(empty_cache()), pin=pin)

        def worker():
            r = bc.run_process([py, "-c", WORKER_SCRIPT], env(empty_cache()), pin=pin, timeout=300)
            if r.ok:
                r.wall_ready = json.loads(r.stdout.strip().splitlines()[-1])["ready_s"]
            return r

        contenders = {
            "python -c 'import jax'": lambda: bc.run_process([py, "-c", "import jax"], base_env, pin=pin),
            "bare JAX + optimistix fit, cold": lambda: bc.run_process([py, "-c", bc.BARE_FIT_SCRIPT, str(MODES)],
                                                                     base_env, pin=pin),
            "ringfit fit, empty cache": fit,
            "ringfit diagnose, warm cache": diagnose(warm),
            "ringfit diagnose, empty cache": diagnose(empty_cache),
        }
        if demo:
            contenders["ringfit demo, empty cache"] = demo_run
        if batch:
            contenders["batch worker ready (1 worker, fit warm-up)"] = worker
        samples = bc.interleaved(contenders, rounds, failures)

        split = {}
        if not args.no_split:
            for name, cache in (("empty cache", empty_cache()), ("warm cache", warm)):
                r = bc.run_process([py, "-c", SPLIT_SCRIPT, str(case)], env(cache), pin=pin)
                if failures.check(r.ok, f"split of a cold diagnosis ({name})", r.detail):
                    split[name] = json.loads(r.stdout.strip().splitlines()[-1])
    failures.refuse()

    print("\n  cold process (fresh interpreter each run)" + " " * 5 + "min / median / max")
    target_of = {"ringfit fit, empty cache": "fit_empty", "ringfit diagnose, warm cache": "diagnose_warm",
                 "ringfit diagnose, empty cache": "diagnose_empty", "ringfit demo, empty cache": "demo"}
    for name, s in samples.items():
        key = target_of.get(name)
        note = (f"(target < {TARGETS[key]:g} s)" if key else
                "(to the cluster's close)" if name.startswith("batch") else "(yardstick)")
        print(bc.row(name, s, note))
    if batch:
        ready = [getattr(s, "wall_ready", float("nan")) for s in samples["batch worker ready (1 worker, fit warm-up)"]]
        print(f"  {'  of which: start to first result':<44} wall {bc.span(ready):>20} s   "
              f"(target < {TARGETS['worker']:g} s; the rest is closing the cluster)")
    jax_s, bare_s = samples["python -c 'import jax'"], samples["bare JAX + optimistix fit, cold"]
    print("\n  ratios, round by round (CPU time):")
    for name in ("ringfit fit, empty cache", "ringfit diagnose, warm cache", "ringfit diagnose, empty cache"):
        print(f"    {name:<40} {bc.ratio_span(samples[name], bare_s):>18} × the bare fit, "
              f"{bc.ratio_span(samples[name], jax_s):>18} × import jax")
    if split:
        print("\n  one cold `ringfit diagnose` in-process, CPU seconds (imports / tracing / lowering / compilation "
              "or cache load / rest = work and dispatch):")
        for name, d in split.items():
            parts = " / ".join(f"{d[k]:.2f}" for k in ("imports", "tracing", "lowering", "compilation", "rest"))
            print(f"    {name:<12} {parts}   total {d['total']:.2f} s CPU, {d['wall']:.2f} s wall")
    bc.finish()
    return 0


if __name__ == "__main__":
    sys.exit(main())
