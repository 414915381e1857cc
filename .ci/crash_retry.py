"""Run pytest with the arguments given; if a worker process *crashes*, the run stops and resumes once.

Why: XLA can segfault while it deserialises a large program from JAX's persistent compilation cache
(`backend.deserialize_executable`), not reproducibly: seen twice in `tests/test_state_new_tread.py`
with two workers on two busy cores, never when the same test is run alone on the same cache. A crash
kills the worker; xdist reports that test as failed ("worker 'gwN' crashed while running …"), which
says nothing about ringfit, and its replacement worker may then never be given work: one such run here
waited for ever after its last test, which in CI would be the 90-minute cap.

So the run is made with ``--max-worker-restart=0`` (a crash stops it promptly), the tests it reported
are recorded, and if the only failures were crashes, the crashed tests and every test not yet run are
run again, once. A crash in that second run, or any other failure in either, fails as it is: nothing
else is retried.

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
    """pytest plugin (controller side): the tests finished, and the failed ones split into crashed and other."""

    def __init__(self, path: str):
        self.path, self.done, self.crashed, self.other = path, set(), [], []
        self._save()

    def _save(self):
        with open(self.path, "w") as f:
            json.dump({"done": sorted(self.done), "crashed": self.crashed, "other": self.other}, f)

    def pytest_runtest_logreport(self, report):
        if report.failed:
            (self.crashed if CRASH in str(report.longrepr) else self.other).append(report.nodeid)
        if report.failed or report.when == "teardown":
            self.done.add(report.nodeid)
        self._save()  # as it goes: a run that stops early still says what it did


def _pytest(args: list[str], record: str | None = None) -> int:
    code = ("import sys, pytest; sys.path.insert(0, %r); from crash_retry import _Record; "
            "sys.exit(pytest.main(sys.argv[1:], plugins=[_Record(%r)] if %r else []))"
            ) % (os.path.dirname(os.path.abspath(__file__)), record, bool(record))
    return subprocess.call([sys.executable, "-c", code, *args])


def _collected(args: list[str]) -> list[str]:
    out = subprocess.run([sys.executable, "-m", "pytest", *args, "--collect-only", "-q", "-n", "0"],
                         capture_output=True, text=True)
    return [line.rstrip("\n") for line in out.stdout.splitlines() if "::" in line and not line[:1].isspace()]


def main(argv: list[str]) -> int:
    with tempfile.TemporaryDirectory() as tmp:
        record = os.path.join(tmp, "first.json")
        rc = _pytest([*argv, "--max-worker-restart=0"], record)
        if rc == 0 or not os.path.exists(record):
            return rc
        with open(record) as f:
            first = json.load(f)
        if first["other"] or not first["crashed"]:
            return rc
        left = sorted((set(_collected(argv)) - set(first["done"])) | set(first["crashed"]))
        print(f"\ncrash_retry: a worker crashed running {', '.join(first['crashed'])} (no test failed otherwise); "
              f"running it and the {len(left) - len(set(first['crashed']))} test(s) not yet run again, once",
              flush=True)
        again = _pytest([*argv, "--max-worker-restart=0", *left], os.path.join(tmp, "second.json"))
        print(f"crash_retry: the second run {'passed' if again == 0 else 'FAILED'}", flush=True)
        return again


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
