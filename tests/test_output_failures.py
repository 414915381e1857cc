"""Outputs that cannot be written (issue 23 item 3): one line, exit 2, nothing left behind.

The replay cases (tests/bad_input_cases.py) simulate a read-only folder and a
full disk inside the process; here the same happens on a real read-only bind
mount and a real, tiny tmpfs where this machine lets the tests mount them
(root with CAP_SYS_ADMIN; skipped otherwise), with the command run as a
separate process so that a crash of a C library (h5py's segfault on a full
disk) shows as its exit status.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import pytest

from ringfit.data import path as data_path
from ringfit.errors import InputError
from ringfit.io.files import atomic_write_text, outputs_committed_together

ROOT = Path(__file__).resolve().parents[1]


def _mount(args) -> bool:
    if shutil.which("mount") is None or os.geteuid() != 0:
        return False
    return subprocess.run(["mount", *args], capture_output=True).returncode == 0


@contextlib.contextmanager
def _mounted(kind: str, tmp_path: Path):
    """A folder that is a read-only bind mount (``"ro"``) or a 64 KiB tmpfs (``"full"``); skip if not possible."""
    target = tmp_path / f"{kind}-{uuid.uuid4().hex[:6]}"
    target.mkdir()
    if kind == "ro":
        src = tmp_path / "ro-src"
        src.mkdir(exist_ok=True)
        ok = _mount(["--bind", "-o", "ro", str(src), str(target)])
    else:
        ok = _mount(["-t", "tmpfs", "-o", "size=64k", "tmpfs", str(target)])
    if not ok:
        pytest.skip(f"cannot mount a {kind} folder here (needs root with mount rights)")
    try:
        yield target
    finally:
        subprocess.run(["umount", "-l", str(target)], capture_output=True)


def _ringfit(*argv, cwd):
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    return subprocess.run([sys.executable, "-m", "ringfit", *map(str, argv)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def _one_error_line(proc, name):
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip() and not ln.startswith("WARNING:")]
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-3000:])
    assert len(lines) == 1 and name in lines[0], proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr


# ----------------------------------------------------------------------------- the transaction itself


def test_outputs_committed_together_or_not_at_all(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    with pytest.raises(RuntimeError), outputs_committed_together():
        atomic_write_text(a, "first")
        assert not a.exists()  # staged: nothing visible before the block ends
        raise RuntimeError("the plot failed")
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no output, no temporary file
    with outputs_committed_together():
        atomic_write_text(a, "first")
        with outputs_committed_together():  # nested: joins the outer block
            atomic_write_text(b, "second")
        atomic_write_text(a, "again")  # a second write of one output replaces the first
        assert not a.exists() and not b.exists()
    assert a.read_text() == "again" and b.read_text() == "second"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]


def test_ssi_plot_failure_leaves_no_mode_table(tmp_path, monkeypatch):
    """The PNG fails after the table was written: the table does not remain (all outputs or none)."""
    import numpy as np

    from bad_input_cases import _impact_records
    from ringfit.cli import main

    np.savez(tmp_path / "rec.records.npz", **_impact_records())
    import matplotlib.figure

    def broken(self, *a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", broken)
    status = main(["ssi", str(tmp_path / "rec.records.npz"), "--out", str(tmp_path / "o.modes.csv"),
                   "--plot", str(tmp_path / "o.png"), "--quiet"])
    assert status == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec.records.npz"]


# ----------------------------------------------------------------------------- real mounts


def test_fit_into_a_read_only_mount_is_one_line(tmp_path):
    with _mounted("ro", tmp_path) as ro:
        proc = _ringfit("fit", data_path("free-ssi.modes.csv"), "--tyre", data_path("table9.tyre.toml"),
                        "--out", ro / "fitted.toml", cwd=tmp_path)
        _one_error_line(proc, str(ro / "fitted.toml"))
        assert "Read-only" in proc.stderr
        assert list(ro.iterdir()) == []


def test_example_into_a_read_only_mount_is_one_line(tmp_path):
    with _mounted("ro", tmp_path) as ro:
        proc = _ringfit("example", "records", "--out", ro / "ex", cwd=tmp_path)
        _one_error_line(proc, "--out")
        assert list(ro.iterdir()) == []


@pytest.mark.slow
def test_sample_on_a_full_disk_is_one_line_not_a_segfault(tmp_path):
    """Was: h5py tracebacks from its object finalisers, then a segfault (exit 139)."""
    with _mounted("full", tmp_path) as full:
        proc = _ringfit("sample", data_path("free-ssi.modes.csv"), "--tyre", data_path("table9.tyre.toml"),
                        "--out", full / "post.h5", "--min-steps", "1000", "--max-steps", "1000", "--quiet",
                        "--force", cwd=tmp_path)
        _one_error_line(proc, "post.h5")
        assert "no space left" in proc.stderr
        assert list(full.iterdir()) == []


@pytest.mark.slow
def test_ssi_plot_on_a_full_disk_leaves_nothing(tmp_path):
    import numpy as np

    from bad_input_cases import _impact_records

    np.savez(tmp_path / "rec.records.npz", **_impact_records())
    with _mounted("full", tmp_path) as full:
        proc = _ringfit("ssi", tmp_path / "rec.records.npz", "--out", full / "o.modes.csv", "--plot", full / "o.png",
                        "--quiet", cwd=tmp_path)
        _one_error_line(proc, "o.png")
        assert list(full.iterdir()) == []


def test_write_failure_names_the_file(tmp_path):
    """A write that fails half-way is an InputError naming the file, and no temporary file stays."""
    from ringfit.io.files import atomic_write

    def failing(tmp):
        tmp.write_text("partial")
        raise OSError(28, "No space left on device")

    with pytest.raises(InputError, match=r"x\.txt: could not be written \(no space left on the device\)"):
        atomic_write(tmp_path / "x.txt", failing)
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- arguments checked before any work


@pytest.mark.parametrize("address", ["tcp://10.0.0.5:8786", "tls://host.example.com:8786", "localhost:8786",
                                     "tcp://[::1]:8786", "inproc://10.0.0.1/1/2", "ws://h:1", "tcp://h"])
def test_scheduler_addresses_dask_dials_pass(address):
    pytest.importorskip("distributed")
    from ringfit.batch import check_scheduler_address

    check_scheduler_address(address)  # no exception: the address reaches distributed.Client


@pytest.mark.parametrize("address, why", [("not a url", "not a host name"), ("http://h:80", "unknown protocol"),
                                          ("tcp://h:99999", "port 99999"), ("tcp://:8786", "not a host name")])
def test_scheduler_addresses_refused_with_one_line(address, why):
    pytest.importorskip("distributed")
    from ringfit.batch import check_scheduler_address

    with pytest.raises(InputError, match="--scheduler") as e:
        check_scheduler_address(address)
    assert why in str(e.value) and "\n" not in str(e.value)


def test_group_velocity_sync_refuses_a_record_too_coarse_for_the_round_trip():
    """100 Hz records (pyuff's binary8byte.uff): the 2 ms lower bound of the round-trip search was sample 0."""
    import numpy as np

    from ringfit.targets.preprocessing import group_velocity, round_trip_time

    x = np.random.default_rng(0).standard_normal(250)
    t = round_trip_time(x, 100.0)  # searched from the first sample after 0, never 0
    assert t >= 1 / 100.0
    with pytest.raises(InputError, match="round-trip time"):
        round_trip_time(x[:5], 100.0)
    with pytest.raises(InputError, match="positive time"):
        group_velocity(0.3, 0.0)


def test_a_missing_font_does_not_bury_the_error_line():
    """CI's stop-39 run: a font cache without the mathtext fonts logged ~20 ``findfont`` warnings on stderr beside
    the one error line. ringfit's plot helpers quiet matplotlib's font fallback (the figure is drawn regardless)."""
    code = ("import ringfit.report.targets_plots\n"
            "from matplotlib import font_manager\n"
            "font_manager.findfont('NoSuchFontFamilyForRingfit')\n")
    proc = subprocess.run([sys.executable, "-c", code], env=dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg"),
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "findfont" not in proc.stderr
