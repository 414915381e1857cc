"""Ctrl-C always stops a command before its outputs are committed; SIGKILL's leftover temporaries are cleaned (issue 34).

Each case runs in a subprocess: a real SIGINT to a real process, a real SIGKILL.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytestmark = pytest.mark.skipif(os.name != "posix", reason="POSIX signals")

# a command whose work writes its output, then receives a Ctrl-C whose KeyboardInterrupt is swallowed where the
# interpreter swallows it: inside a garbage-collector callback (as JAX's _xla_gc_callback once did), then returns 0
SWALLOWED = textwrap.dedent("""
    import gc, os, signal, sys, time
    import ringfit.cli as cli
    from ringfit.io.files import atomic_write_text

    def work(args):
        if args.command != "example":  # staged, committed at the end (if at all)
            atomic_write_text(args.out, "new\\n")
        fired = []
        def callback(phase, info):
            if phase == "start" and not fired:
                fired.append(1)
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.2)  # the handler runs here; its KeyboardInterrupt is "ignored" by the collector
        gc.callbacks.append(callback)
        gc.collect()
        gc.callbacks.remove(callback)
        print("work went on", flush=True)
        if args.command == "example":  # writes as it goes: a write after the interrupt is refused
            atomic_write_text(args.out / "x", "new\\n")
        return 0

    build = cli.build_parser
    def parser():
        p = build()
        parse = p.parse_args
        def parse_args(argv=None):
            a = parse(argv)
            a.run = work
            return a
        p.parse_args = parse_args
        return p
    cli.build_parser = parser
    sys.exit(cli.main(sys.argv[1:]))
""")


def _run(script: str, *argv, cwd: Path):
    return subprocess.run([sys.executable, "-c", script, *argv], cwd=cwd, capture_output=True, text=True, timeout=120)


def test_swallowed_ctrl_c_still_stops_the_commit(tmp_path):
    out = tmp_path / "out.toml"
    out.write_text("old\n")
    (tmp_path / "ex").mkdir()
    for command in (["fit", "x.modes.csv", "--tyre", "t.toml", "--out", str(out), "--force"],
                    # a command that writes as it goes: the write itself is refused after the interrupt
                    ["example", "case", "--out", str(tmp_path / "ex"), "--force"]):
        res = _run(SWALLOWED, *command, cwd=tmp_path)
        assert "work went on" in res.stdout  # the interrupt really was swallowed
        assert res.returncode == 130, res.stderr
        assert "interrupted" in res.stderr
    assert out.read_text() == "old\n"  # never replaced after the interrupt
    assert not (tmp_path / "ex" / "x").exists()
    assert not [p for p in tmp_path.rglob(".*.tmp")]  # and no temporary left behind


def test_ctrl_c_to_a_running_command_exits_130_without_outputs(tmp_path):
    """A real SIGINT from outside, during a command's work, after it staged its output."""
    script = textwrap.dedent("""
        import sys, time
        import ringfit.cli as cli
        from ringfit.io.files import atomic_write_text
        def work(args):
            atomic_write_text(args.out, "new\\n")
            print("ready", flush=True)
            time.sleep(60)
            return 0
        build = cli.build_parser
        def parser():
            p = build(); parse = p.parse_args
            def parse_args(argv=None):
                a = parse(argv); a.run = work; return a
            p.parse_args = parse_args
            return p
        cli.build_parser = parser
        sys.exit(cli.main(sys.argv[1:]))
    """)
    out = tmp_path / "out.toml"
    proc = subprocess.Popen([sys.executable, "-c", script, "fit", "x.modes.csv", "--tyre", "t.toml", "--out",
                             str(out)], cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "ready"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert "interrupted" in err and "Traceback" not in err
    assert not out.exists() and not list(tmp_path.glob(".*.tmp"))


def test_sigkill_during_the_commit_leaves_a_temporary_the_next_run_removes(tmp_path):
    out = tmp_path / "result.json"
    script = textwrap.dedent(f"""
        import time
        from ringfit.io.files import atomic_write
        def write(tmp):
            tmp.write_text("complete content")
            print("written", flush=True)
            time.sleep(60)  # killed here: between the write and the rename
        atomic_write({str(out)!r}, write)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "written"
    proc.kill()
    proc.wait(timeout=30)
    left = list(tmp_path.glob(".result.json.*.tmp"))
    assert len(left) == 1 and not out.exists()
    # someone else's file that merely looks alike, and a live writer's temporary, are left alone
    other = tmp_path / ".result.json.notours.tmp"
    other.write_text("x")
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        live_tmp = tmp_path / f".result.json.rf{live.pid}.abcdefgh.tmp"
        live_tmp.write_text("being written")
        legacy = tmp_path / ".result.json.k3j4h5g6.tmp"  # the naming before process ids, an hour old
        legacy.write_text("old")
        old = time.time() - 3600
        os.utime(legacy, (old, old))
        from ringfit.io.files import atomic_write_text

        atomic_write_text(out, "new")
        assert out.read_text() == "new"
        assert not left[0].exists() and not legacy.exists()
        assert other.exists() and live_tmp.exists()
    finally:
        live.kill()
        live.wait()
