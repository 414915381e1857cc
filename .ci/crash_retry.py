"""Run pytest with the arguments given; a test whose worker process *crashed* is run once more, alone.

Why: XLA can segfault while it deserialises a large program from JAX's persistent compilation cache
(`backend.deserialize_executable`), not reproducibly: seen twice in `tests/test_state_new_tread.py`
with two workers on two busy cores, never when the same test is run alone on the same cache. A crash
kills the worker and xdist reports the test as failed with "worker 'gwN' crashed while running …";
it says nothing about ringfit. So a test that crashed is run again in a fresh process (`-n 0`), once,
and it must pass there. Every other failure fails the run as it is: nothing else is retried, and a
crash on the retry fails too.

Usage (from the repository root): ``python .ci/crash_retry.py -m slow``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

CRASH = "crashed while running"


class _Record:
    """pytest plugin (controller side): the failed test ids, split into crashed and other."""

    def __init__(self, path: str):
        self.path, self.crashed, self.other = path, [], []

    def pytest_runtest_logreport(self, report):
        if report.failed:
            (self.crashed if CRASH in str(report.longrepr) else self.other).append(report.nodeid)

    def pytest_sessionfinish(self, session):
        if not hasattr(session.config, "workerinput"):  # the controller only
            with open(self.path, "w") as f:
                json.dump({"crashed": self.crashed, "other": self.other}, f)


def _run(args: list[str], record: str) -> int:
    code = ("import sys, pytest; sys.path.insert(0, %r); from crash_retry import _Record; "
            "sys.exit(pytest.main(sys.argv[1:], plugins=[_Record(%r)]))") % (os.path.dirname(__file__), record)
    return subprocess.call([sys.executable, "-c", code, *args])


def main(argv: list[str]) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        record = os.path.join(tmp, "failed.json")
        rc = _run(argv, record)
        if rc != 1 or not os.path.exists(record):  # passed, or interrupted / internal or usage error
            return rc
        with open(record) as f:
            failed = json.load(f)
        if failed["other"] or not failed["crashed"]:
            return rc
        crashed = sorted(set(failed["crashed"]))
        print(f"\ncrash_retry: {len(crashed)} test(s) crashed their worker (no test failed otherwise); "
              f"running them again alone, once: {' '.join(crashed)}", flush=True)
        again = _run([*crashed, "-n", "0", "-m", "slow or not slow"], record)
        print(f"crash_retry: the crashed test(s) {'passed' if again == 0 else 'FAILED'} when run again alone",
              flush=True)
        return again


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
