"""What every benchmark here shares, so that its figures can be read on a shared machine.

- :func:`parser`: an ``ArgumentParser`` whose bad arguments end in one line and exit status 2,
  with the checked number types of the ``ringfit`` commands (:func:`count`, :func:`seconds`, …)
  and ``--quick`` (a short smoke run whose figures are not the targets').
- :func:`start` / :func:`finish`: the header (machine, load average at the start) and the
  footer (load average at the end, the script's own CPU time beside its wall time). A load
  average above the number of cores means the figures are inflated by other work.
- :class:`Clock` and :func:`timed`: wall time (``time.perf_counter``) beside CPU time
  (``time.process_time`` of this process, plus the children's ``RUSAGE_CHILDREN`` for work
  done in processes the script waited for).
- :func:`run_process`: one whole process, timed from outside (wall; CPU = its user + system time).
- :func:`interleaved`: several contenders run in turn, A B C A B C …, so that a machine whose
  speed drifts slows all alike; ratios are taken round by round (:func:`ratio_span`).
- :class:`Failures`: every failed task is recorded; :meth:`Failures.refuse` prints what
  failed and exits 1 *instead of* the figures (a timing of work that did not happen is no
  figure).
- :func:`span`: ``min / median / max`` of repeated runs (quote the median).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field


#: The bare-library yardstick of a cold `ringfit fit`: the same Levenberg–Marquardt fit of eq. 18 in a
#: script of its own (JAX + optimistix, nothing of ringfit); argument: the mode table.
BARE_FIT_SCRIPT = r"""
import os, sys, csv
os.environ["JAX_ENABLE_X64"] = "1"
import numpy as np, jax, jax.numpy as jnp, lineax as lx, optimistix as optx
rows = list(csv.DictReader(open(sys.argv[1])))
n = jnp.asarray([float(r["n"]) for r in rows if r["n"]][:9]); f = jnp.asarray([float(r["freq_hz"]) for r in rows if r["n"]][:9])
R, P = 0.296, 2.2e5 * 0.152 / 0.296
def resid(y, args):
    rho, ei, kw, kv = jnp.exp(y); n2 = n**2
    k = ei / R**4 * n2 * (n2 - 1) ** 2 + P * n2 * (n2 - 1) + kw * n2 + kv
    return (jnp.sqrt(k / (rho * (1 + n2))) / (2 * jnp.pi) - f) / (0.01 * f)
@jax.jit
def bare(y0):
    solver = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-10, linear_solver=lx.SVD())
    return optx.least_squares(resid, solver, y0, max_steps=256, throw=False).value
print(np.exp(np.asarray(bare(np.log(np.array([2.715, 0.9426, 1.294e6, 1.161e6]))))))
"""


# --------------------------------------------------------------------------- arguments
class _OneLineParser(argparse.ArgumentParser):
    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see '{self.prog} --help')\n")


def parser(description: str, quick_help: str = "a short smoke run (its figures are not the targets')"):
    """An argument parser: one-line errors with exit status 2, and ``--quick``."""
    p = _OneLineParser(prog=os.path.basename(sys.argv[0]) or "benchmark", description=description)
    p.add_argument("--quick", action="store_true", help=quick_help)
    return p


def count(what: str = "a whole number >= 1", lo: int = 1, hi: int = 10**7):
    """``type=`` for a whole number in [lo, hi]."""

    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"expected {what} (from {lo} to {hi}); got {text!r}")
        return value

    return convert


def number(what: str = "a number", lo: float = -math.inf, hi: float = math.inf, lo_open: bool = False):
    """``type=`` for a finite float in [lo, hi] (``lo_open``: > lo)."""

    def convert(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        ok = math.isfinite(value) and (value > lo if lo_open else value >= lo) and value <= hi
        if not ok:
            raise argparse.ArgumentTypeError(f"expected {what}; got {text!r}")
        return value

    return convert


def seconds(what: str = "a number of seconds > 0"):
    """``type=`` for a positive, finite number of seconds."""
    return number(what, lo=0.0, lo_open=True)


def choices_list(allowed, what: str = "names"):
    """``type=`` for a comma-separated list of names from ``allowed``."""

    def convert(text: str) -> list[str]:
        names = [t.strip() for t in text.split(",") if t.strip()]
        bad = [t for t in names if t not in allowed]
        if bad:
            raise argparse.ArgumentTypeError(f"unknown {what} {bad}; expected some of {', '.join(allowed)}")
        return names

    return convert


def fail(message: str) -> None:
    """A bad argument found after parsing: one line, exit status 2."""
    print(f"{os.path.basename(sys.argv[0])}: error: {' '.join(message.split())}", file=sys.stderr)
    sys.exit(2)


# --------------------------------------------------------------------------- the machine
def loadavg() -> str:
    """``load average 1.02 0.88 0.61 (1, 5, 15 min) on 2 cores``."""
    try:
        one, five, fifteen = os.getloadavg()
        text = f"{one:.2f} {five:.2f} {fifteen:.2f} (1, 5, 15 min)"
    except OSError:
        text = "unknown"
    return f"load average {text} on {usable_cores()} cores"


def usable_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


_STARTED: dict = {}


def start(title: str) -> None:
    """Print the benchmark's header: title, machine, load average at the start."""
    _STARTED.update(wall=time.perf_counter(), cpu=_cpu_now())
    print(f"{title}")
    print(f"  {platform.python_implementation()} {platform.python_version()} on {platform.machine()}, "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    print(f"  start: {loadavg()}")
    sys.stdout.flush()


def finish() -> None:
    """Print the footer: load average at the end, the whole script's CPU time beside its wall time."""
    wall = time.perf_counter() - _STARTED.get("wall", time.perf_counter())
    cpu = _cpu_now() - _STARTED.get("cpu", _cpu_now())
    print(f"  end: {loadavg()}; this script: {wall:.1f} s wall, {cpu:.1f} s CPU (children included)")
    try:
        busy = os.getloadavg()[0] > usable_cores()
    except OSError:
        busy = False
    if busy:
        print("  NOTE: the load average exceeded the cores: other work shared the machine; wall times are "
              "inflated, compare CPU times and the ratios of interleaved runs")
    sys.stdout.flush()


# --------------------------------------------------------------------------- timing
def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _cpu_now() -> float:
    return time.process_time() + _children_cpu()


@dataclass
class Sample:
    """One timed run: ``wall`` and ``cpu`` seconds (``ok``: the work succeeded)."""

    wall: float
    cpu: float
    ok: bool = True
    detail: str = ""


class Clock:
    """``with Clock() as c: …`` then ``c.wall``, ``c.cpu`` (this process + waited-for children)."""

    def __enter__(self):
        self._w, self._c = time.perf_counter(), _cpu_now()
        return self

    def __exit__(self, *exc):
        self.wall = time.perf_counter() - self._w
        self.cpu = _cpu_now() - self._c
        return False

    @property
    def sample(self) -> Sample:
        return Sample(self.wall, self.cpu)


def _block(x):
    if "jax" in sys.modules:
        return sys.modules["jax"].block_until_ready(x)
    return x


def best(fn, *args, repeat: int = 200, warm: bool = True) -> Sample:
    """Warm micro-benchmark: the least wall and the least CPU time of ``repeat`` calls of ``fn(*args)``
    (JAX results waited for); the minimum is the figure least moved by other work on the machine."""
    if warm:
        _block(fn(*args))
    wall, cpu = math.inf, math.inf
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        _block(fn(*args))
        c, w = time.process_time() - c0, time.perf_counter() - w0
        wall, cpu = min(wall, w), min(cpu, c)
    return Sample(wall, cpu)


def ms(s: Sample, digits: int = 3) -> str:
    """``1.234 ms (CPU 1.200 ms)``."""
    return f"{1e3 * s.wall:.{digits}f} ms (CPU {1e3 * s.cpu:.{digits}f} ms)"


def timed(fn, *args, **kwargs):
    """``(result, Sample)`` of ``fn(*args, **kwargs)``."""
    with Clock() as c:
        out = fn(*args, **kwargs)
    return out, c.sample


@dataclass
class ProcessRun(Sample):
    returncode: int = 0
    stdout: str = ""
    stderr: str = ""


def run_process(argv, env=None, cwd=None, timeout: float | None = None, pin: str | None = None) -> ProcessRun:
    """Run ``argv`` to its end; wall from outside, CPU = its (and its waited-for children's) user + system.

    ``pin``: CPU list for ``taskset -c`` (e.g. ``"0"``) where taskset exists; ``ok`` is exit status 0.
    """
    import shutil

    if pin is not None and shutil.which("taskset"):
        argv = ["taskset", "-c", pin, *argv]
    c0, w0 = _children_cpu(), time.perf_counter()
    try:
        p = subprocess.run(argv, env=env, cwd=cwd, capture_output=True, text=True, timeout=timeout)
        rc, out, err = p.returncode, p.stdout, p.stderr
    except subprocess.TimeoutExpired as exc:
        rc, out, err = -9, str(exc.stdout or ""), f"timed out after {timeout} s"
    wall, cpu = time.perf_counter() - w0, _children_cpu() - c0
    last = (err.strip().splitlines() or [""])[-1]
    return ProcessRun(wall, cpu, rc == 0, "" if rc == 0 else f"exit {rc}: {last}", rc, out, err)


def interleaved(contenders: dict, rounds: int, failures: "Failures | None" = None) -> dict[str, list[Sample]]:
    """Run each contender ``rounds`` times, in turn (A B C A B C …).

    ``contenders``: name -> callable returning a :class:`Sample` (or a ``(result, Sample)``); a
    sample with ``ok`` false is recorded in ``failures``. **Returns:** name -> samples, in order.
    """
    out = {name: [] for name in contenders}
    for i in range(rounds):
        for name, fn in contenders.items():
            s = fn()
            if isinstance(s, tuple):
                s = s[1]
            out[name].append(s)
            if failures is not None and not s.ok:
                failures.add(f"{name} (round {i + 1})", s.detail)
    return out


# --------------------------------------------------------------------------- figures
def span(values, scale: float = 1.0, fmt: str = "{:.2f}") -> str:
    """``min / median / max`` of ``values × scale`` (one value: just it)."""
    v = sorted(float(x) * scale for x in values)
    if not v:
        return "–"
    if len(v) == 1:
        return fmt.format(v[0])
    return " / ".join(fmt.format(x) for x in (v[0], statistics.median(v), v[-1]))


def walls(samples) -> list[float]:
    return [s.wall for s in samples]


def cpus(samples) -> list[float]:
    return [s.cpu for s in samples]


def ratio_span(a, b, attr: str = "cpu", fmt: str = "{:.2f}") -> str:
    """``min / median / max`` of the round-by-round ratios a[i]/b[i] of interleaved samples."""
    return span([getattr(x, attr) / getattr(y, attr) for x, y in zip(a, b) if getattr(y, attr) > 0], fmt=fmt)


def row(label: str, samples, target: str = "", width: int = 44) -> str:
    """One table row: wall and CPU as min / median / max, and the target."""
    return f"  {label:<{width}} wall {span(walls(samples)):>20} s   CPU {span(cpus(samples)):>20} s   {target}"


@dataclass
class Failures:
    """Failed tasks of a benchmark run; :meth:`refuse` ends the run without figures if there are any."""

    items: list = field(default_factory=list)

    def add(self, what: str, why: str = "") -> None:
        self.items.append((what, " ".join(str(why).split())))

    def check(self, ok: bool, what: str, why: str = "") -> bool:
        if not ok:
            self.add(what, why)
        return ok

    def __bool__(self) -> bool:
        return bool(self.items)

    def refuse(self) -> None:
        """If anything failed: list it on stderr, print no figures, exit status 1."""
        if not self.items:
            return
        print(f"REFUSED: {len(self.items)} task(s) failed; no figures are printed for a run whose work did not "
              f"all happen:", file=sys.stderr)
        for what, why in self.items[:20]:
            print(f"  {what}: {why or 'failed'}", file=sys.stderr)
        if len(self.items) > 20:
            print(f"  … and {len(self.items) - 20} more", file=sys.stderr)
        print(f"  end: {loadavg()}", file=sys.stderr)
        sys.exit(1)
