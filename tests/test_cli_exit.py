"""How the ``ringfit`` command ends (issue 24 item 1: the interpreter's teardown skipped, nothing else).

- ``python -m ringfit`` keeps :func:`ringfit.cli.main`'s exit statuses (0, 1, 2) and every output, its
  stdout complete through a pipe; the exit handlers a normal exit runs still run (``atexit``).
- Where a thread that is not a daemon is still running, the process exits as usual (and waits for it).
- A reader of stdout that goes away ends the command quietly with status 141.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import tomllib
from pathlib import Path

import pytest

import ringfit.cli as cli
from ringfit.data import path

ENV = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}


def _ringfit(args, tmp_path, **kw):
    return subprocess.run([sys.executable, "-m", "ringfit", *args], capture_output=True, text=True, env=ENV,
                          cwd=tmp_path, timeout=300, **kw)


@pytest.mark.slow
def test_statuses_and_outputs_are_those_of_main(tmp_path):
    out = tmp_path / "fit.tyre.toml"
    args = ["fit", str(path("free-ssi.modes.csv")), "--tyre", str(path("table9.tyre.toml")), "--out", str(out)]
    done = _ringfit(args, tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.rstrip().endswith(f"wrote {out}")  # the last line of stdout reached the pipe
    assert tomllib.loads(out.read_text())["ring"]["rho_a_kg_per_m"] > 0
    again = _ringfit(args, tmp_path)  # refuses to overwrite: bad input, one line, status 2
    assert again.returncode == 2 and again.stderr.count("\n") == 1 and "exists" in again.stderr
    missing = _ringfit(["fit", str(tmp_path / "none.csv"), "--tyre", str(path("table9.tyre.toml")), "--out",
                        str(tmp_path / "x.tyre.toml")], tmp_path)
    assert missing.returncode == 2 and "none.csv" in missing.stderr


def test_exit_handlers_run_and_the_status_is_kept(tmp_path):
    flag = tmp_path / "handler-ran"
    code = ("import atexit, sys, ringfit.cli as cli\n"
            f"atexit.register(lambda: open({str(flag)!r}, 'w').write('ran'))\n"
            "print('last line', end='')\n"
            "cli._end(3)\n"
            "print('never')\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=120)
    assert done.returncode == 3
    assert done.stdout == "last line"  # flushed before the end; nothing after it ran
    assert flag.read_text() == "ran"


def test_a_running_thread_gets_a_normal_exit(monkeypatch):
    ended = []
    monkeypatch.setattr(os, "_exit", lambda status: ended.append(status))
    release = threading.Event()
    worker = threading.Thread(target=release.wait, daemon=False)
    worker.start()
    try:
        with pytest.raises(SystemExit) as exit_:
            cli._end(5)
        assert exit_.value.code == 5 and not ended
    finally:
        release.set()
        worker.join()


def test_without_other_work_the_process_ends_at_once(monkeypatch):
    ended, handlers = [], []
    monkeypatch.setattr(os, "_exit", lambda status: ended.append(status))
    import atexit

    monkeypatch.setattr(atexit, "_run_exitfuncs", lambda: handlers.append(True))
    cli._end(0)
    assert ended == [0] and handlers == [True]


@pytest.mark.slow
def test_a_closed_pipe_ends_quietly_with_141(tmp_path):
    out = tmp_path / "fit.tyre.toml"
    proc = subprocess.Popen([sys.executable, "-m", "ringfit", "fit", str(path("free-ssi.modes.csv")), "--tyre",
                             str(path("table9.tyre.toml")), "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=ENV, cwd=tmp_path)
    proc.stdout.close()  # the reader is gone before the first line
    stderr = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 141
    assert "Traceback" not in stderr and "Exception ignored" not in stderr
