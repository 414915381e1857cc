"""Many independent jobs as tasks on dask.distributed: the machinery behind ``ringfit batch`` and ``ringfit campaign``
(docs/formats.md §13; how the workers run, §13.5).

It takes plain callables and knows nothing of the command line. :func:`open_client` gives a client on a
:func:`local_cluster` of single-threaded worker processes, or on an existing scheduler, with the worker set-up
(:class:`WorkerSetup`) on every worker; a :class:`Task` is one job (a picklable callable, its small arguments, the
tasks it needs first, the files it writes); :func:`run_tasks` submits them with a progress bar that relays each
running task's latest line, and returns one :class:`TaskResult` per task, in order, whatever happened to it;
:func:`summarize` counts states, CPU, memory and warm compilations.

Example (four tasks on a two-process LocalCluster; run under ``if __name__ == "__main__":``)::

    import math
    from ringfit.batch import Task, open_client, run_tasks, summarize
    with open_client(workers=2) as client:
        results = run_tasks(client, [Task(f"sqrt{i}", math.sqrt, (float(i),)) for i in range(4)])
    [r.state for r in results]        # ['ok', 'ok', 'ok', 'ok']; r.value holds each result
    summarize(results)["by_state"]     # {'ok': 4}
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from ringfit._threads import limit_threads

#: XLA flag given to every LocalCluster worker process (on top of Dask's own
#: ``OMP/MKL/OPENBLAS_NUM_THREADS=1``): XLA's CPU runtime on one thread.
WORKER_XLA_FLAG = "--xla_cpu_multi_thread_eigen=false"
#: Scheduler settings of a LocalCluster (give your own scheduler the same, see the README): a task whose
#: worker dies is tried once more, then reported ``lost``.
SCHEDULER_CONFIG = {"distributed.scheduler.allowed-failures": 1}
INSTALL_HINT = "ringfit batch needs dask.distributed: pip install 'ringfit[batch]' (or pip install distributed)"

try:  # the worker plugin must subclass Dask's; without distributed the rest of this module still works
    from distributed import WorkerPlugin as _WorkerPlugin
except ImportError:  # pragma: no cover - exercised only without the extra
    _WorkerPlugin = object


class TaskFailed(Exception):
    """Raised by a task's callable: the job ran and failed; ``status`` is its exit status (1 or 2)."""

    def __init__(self, message: str, status: int = 1):
        super().__init__(" ".join(str(message).split()))
        self.status = int(status)


def import_distributed():
    """``distributed``, or :class:`ImportError` with the install hint."""
    try:
        import distributed
    except ImportError:
        raise ImportError(INSTALL_HINT) from None
    return distributed


@dataclass(frozen=True)
class Task:
    """One job.

    - ``name``: unique within a run (the Dask key and the row of the report).
    - ``fn``, ``args``: ``fn(*args)`` runs on a worker; both must pickle (a
      module-level function, paths and options, not data).
    - ``after``: names of tasks that must succeed first; if one does not,
      this task is ``skipped``.
    - ``outputs``: the files it writes (for ``skip_existing`` and the report).
    - ``kind``: what sort of job (e.g. the command name); :func:`summarize`
      counts the compilations of tasks that were not the first of their kind
      on their worker.
    """

    name: str
    fn: Callable
    args: tuple = ()
    after: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    kind: str = ""


@dataclass
class TaskResult:
    """What became of one :class:`Task`.

    - ``state``: ``ok``; ``failed`` (the callable raised or returned a failure);
      ``lost`` (its worker died twice while running it); ``skipped`` (a task
      in ``after`` did not succeed); ``kept`` (``skip_existing`` and every
      output already there).
    - ``status``: exit status, 0 ok, 1 failed, 2 bad input.
    - ``error``: one line, empty when ok; ``log``: the task's stdout and stderr.
    - ``value``: what the callable returned.
    - ``elapsed_s`` [s]: wall time of the callable on the worker; ``cpu_s`` [s]: the worker
      process's CPU time meanwhile (``time.process_time``; on a shared machine the figure to compare);
      ``started_at`` [s]: when it started (``time.time()`` of the worker).
    - ``rss_start_mb``, ``peak_rss_mb``, ``peak_delta_mb`` [MiB]: resident
      memory of the worker process when the task started, its peak during the
      task, and the difference.
    - ``compiles``: XLA compilations during the task (in-memory cache misses,
      including loads from the persistent cache); ``compile_s`` [s] their time.
    - ``worker``: ``host:pid`` of the process that ran it; ``task_index``: how
      many tasks that process had run before this one; ``kind_index``: how many
      of the same ``kind``.
    """

    name: str
    state: str = "ok"
    status: int = 0
    error: str = ""
    value: Any = None
    log: str = ""
    elapsed_s: float = 0.0
    cpu_s: float = 0.0
    started_at: float = float("nan")
    rss_start_mb: float = float("nan")
    peak_rss_mb: float = float("nan")
    peak_delta_mb: float = float("nan")
    compiles: int = 0
    compile_s: float = 0.0
    worker: str = ""
    task_index: int = 0
    kind_index: int = 0
    kind: str = ""
    outputs: tuple[str, ...] = field(default_factory=tuple)

    @property
    def ok(self) -> bool:
        return self.state in ("ok", "kept")


# ============================================================================ on the worker
#: Dask event topic of the progress lines tasks relay to the client.
PROGRESS_TOPIC = "ringfit-task-progress"
#: Least seconds between two progress lines relayed from one task; the client's bar is redrawn as often.
PROGRESS_EVERY_S = 2.0
#: Longest progress line relayed (characters).
PROGRESS_WIDTH = 90

_TASK_LOCK = threading.Lock()
_TASKS_RUN = 0
_KINDS_RUN: dict[str, int] = {}


class _JaxCompiles:
    """Counts XLA compilations in this process (JAX's monitoring events)."""

    installed = False
    count = 0
    seconds = 0.0

    @classmethod
    def install(cls) -> None:
        if cls.installed:
            return
        import jax.monitoring

        def listener(event: str, duration: float, **_kw) -> None:
            if event == "/jax/core/compile/backend_compile_duration":
                cls.count += 1
                cls.seconds += duration

        jax.monitoring.register_event_duration_secs_listener(listener)
        cls.installed = True


def _status_mb(field_name: str) -> float | None:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field_name + ":"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


class _PeakMemory:
    """Peak resident memory during a ``with`` block [MiB].

    Linux: reset the kernel's high-water mark (``/proc/self/clear_refs``) at
    entry and read ``VmHWM`` at exit (exact). Elsewhere: sample the RSS with
    psutil every 5 ms in a thread.
    """

    def __enter__(self):
        self.start = self._rss()
        self.exact = False
        try:
            with open("/proc/self/clear_refs", "w") as fh:
                fh.write("5")
            self.exact = _status_mb("VmHWM") is not None
        except OSError:
            self.exact = False
        self.sampled = self.start
        if not self.exact:
            self._stop = threading.Event()
            self._thread = threading.Thread(target=self._sample, daemon=True)
            self._thread.start()
        return self

    @staticmethod
    def _rss() -> float:
        rss = _status_mb("VmRSS")
        if rss is not None:
            return rss
        try:
            import psutil

            return psutil.Process().memory_info().rss / 2**20
        except Exception:  # noqa: BLE001
            return float("nan")

    def _sample(self):
        while not self._stop.wait(0.005):
            self.sampled = max(self.sampled, self._rss())

    def __exit__(self, *exc):
        if self.exact:
            self.peak = max(_status_mb("VmHWM") or float("nan"), self.start)
        else:
            self._stop.set()
            self._thread.join()
            self.peak = max(self.sampled, self._rss())
        return False


_BAR_GLYPHS = re.compile(r"\|[^|]*\|")


def progress_line(text: str) -> str:
    """A progress line as relayed: one line, a tqdm bar's drawn part left out (``modes: rotation: 44% 4/9
    [00:02<00:02, 2.42candidate/s]``), at most :data:`PROGRESS_WIDTH` characters."""
    line = " ".join(_BAR_GLYPHS.sub(" ", text).split())
    return line if len(line) <= PROGRESS_WIDTH else line[: PROGRESS_WIDTH - 1] + "…"


class TaskStream(io.TextIOBase):
    """A task's stdout and stderr: written to ``log``, except progress-bar redraws (text after a carriage
    return); the latest line of either is passed to ``relay`` (at most every ``every_s`` seconds)."""

    def __init__(self, log, relay: Callable[[str], Any] | None = None, every_s: float = PROGRESS_EVERY_S):
        super().__init__()
        self.log, self.relay, self.every_s = log, relay, every_s
        self._last = -float("inf")
        self._pending: str | None = None
        self._timer: threading.Timer | None = None
        self._lock = threading.Lock()

    def writable(self) -> bool:
        """Always writable (a text stream a task's prints and progress bars go to)."""
        return True

    def isatty(self) -> bool:
        """Not a terminal: progress bars draw plain lines, which this stream relays."""
        return False

    def write(self, text: str) -> int:
        """Log ``text`` and relay its latest complete line (a bar's redraw after ``\\r`` is relayed only)."""
        if "\r" in text:  # a bar redrawing its line: relayed, not logged (what came before the first \r is)
            head, _, _ = text.partition("\r")
            if head.strip():
                self.log.write(head)
            self._relay(text.rsplit("\r", 1)[-1])
        else:
            self.log.write(text)
            lines = [line for line in text.splitlines() if line.strip()]
            if lines:
                self._relay(lines[-1])
        return len(text)

    def _relay(self, line: str) -> None:
        line = progress_line(line)
        if self.relay is None or not line:
            return
        with self._lock:
            self._pending = line
            wait = self._last + self.every_s - time.monotonic()
            if wait > 0:  # too soon: the newest line goes out when the interval is over (none is left stale)
                if self._timer is None:
                    self._timer = threading.Timer(wait, self._send)
                    self._timer.daemon = True
                    self._timer.start()
                return
        self._send()

    def _send(self) -> None:
        with self._lock:
            line, self._pending, self._timer = self._pending, None, None
            self._last = time.monotonic()
        if line is None or self.relay is None:
            return
        try:
            self.relay(line)
        except Exception:  # noqa: BLE001 - progress is best effort: it never fails a task
            self.relay = None

    def close(self) -> None:
        """Stop a pending relay (the task is over)."""
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()
            self._timer, self._pending = None, None
        super().close()


def _worker_relay(name: str) -> Callable[[str], None] | None:
    """Where a task on a Dask worker sends its progress lines (a worker event); ``None`` outside a worker."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        return None
    return lambda line: worker.log_event(PROGRESS_TOPIC, {"task": name, "line": line})


def _one_line(text: str, limit: int = 400) -> str:
    line = " ".join(str(text).split())
    return line if len(line) <= limit else line[: limit - 1] + "…"


def execute(name: str, fn: Callable, args: tuple = (), outputs: tuple = (), kind: str = "") -> TaskResult:
    """Run one task in this process and measure it (what a worker calls; public for serial runs).

    **Arguments:** ``name``, ``fn``, ``args``, ``outputs``, ``kind`` as in :class:`Task`.

    **Returns:** a :class:`TaskResult`; never raises for a failure of ``fn``.
    """
    global _TASKS_RUN
    with _TASK_LOCK:  # one task at a time per process: stdout capture and memory figures are per process
        limit_threads()
        _JaxCompiles.install()
        c0, s0 = _JaxCompiles.count, _JaxCompiles.seconds
        log = io.StringIO()
        stream = TaskStream(log, _worker_relay(name))
        result = TaskResult(name, outputs=tuple(outputs), worker=f"{socket.gethostname()}:{os.getpid()}",
                            task_index=_TASKS_RUN, kind=kind, kind_index=_KINDS_RUN.get(kind, 0))
        result.started_at = time.time()
        t0, p0 = time.perf_counter(), time.process_time()
        with _PeakMemory() as mem, contextlib.redirect_stdout(stream), contextlib.redirect_stderr(stream):
            try:
                result.value = fn(*args)
            except TaskFailed as exc:
                result.state, result.status, result.error = "failed", exc.status or 1, _one_line(exc)
            except SystemExit as exc:
                code = exc.code if isinstance(exc.code, int) else 1
                if code:
                    result.state, result.status, result.error = "failed", code, f"exit status {code}"
            except Exception as exc:  # noqa: BLE001 - a task's failure is reported, never raised
                traceback.print_exc(file=log)
                result.state, result.status = "failed", 1
                result.error = _one_line(f"{type(exc).__name__}: {exc}")
        stream.close()
        result.elapsed_s = time.perf_counter() - t0
        result.cpu_s = time.process_time() - p0
        result.rss_start_mb, result.peak_rss_mb = mem.start, mem.peak
        result.peak_delta_mb = mem.peak - mem.start
        result.compiles = _JaxCompiles.count - c0
        result.compile_s = _JaxCompiles.seconds - s0
        result.log = log.getvalue()
        _TASKS_RUN += 1
        _KINDS_RUN[kind] = _KINDS_RUN.get(kind, 0) + 1
        return result


class WorkerSetup(_WorkerPlugin):
    """Dask worker plugin: thread limits, the compile counter, then an optional warm-up callable.

    Runs on every worker when registered and on every worker that joins or
    restarts later. ``warmup`` (picklable, no arguments) typically imports the
    modules the tasks need; its failure is logged by Dask, not fatal.
    """

    name = "ringfit-worker-setup"

    def __init__(self, warmup: Callable[[], Any] | None = None):
        self.warmup = warmup

    def setup(self, worker=None):
        """Run on each worker as it starts: one thread for BLAS and XLA, compile counting, warm-up."""
        limit_threads()
        _JaxCompiles.install()
        if self.warmup is not None:
            with _TASK_LOCK:
                self.warmup()


# ============================================================================ on the client
def default_workers() -> int:
    """Worker processes for a LocalCluster by default: the CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def worker_env() -> dict[str, str]:
    """Environment of LocalCluster workers: this process's ``XLA_FLAGS`` plus :data:`WORKER_XLA_FLAG`."""
    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_multi_thread_eigen" not in flags:
        flags = f"{flags} {WORKER_XLA_FLAG}".strip()
    return {"XLA_FLAGS": flags}


#: Dask settings that empty the HTTP servers of the scheduler and its workers: distributed always
#: opens one per process (``/health``, ``/metrics``, ``/info``, …, besides the dashboard); with no
#: routes it answers nothing but 404.
NO_HTTP_CONFIG = {"distributed.scheduler.http.routes": [], "distributed.worker.http.routes": []}
#: Keys of a ``--security FILE.toml`` (docs/formats.md §13.4) -> ``distributed.security.Security`` arguments.
SECURITY_KEYS = {"ca_file": "tls_ca_file", "cert": "tls_client_cert", "key": "tls_client_key",
                 "scheduler_cert": "tls_scheduler_cert", "scheduler_key": "tls_scheduler_key",
                 "worker_cert": "tls_worker_cert", "worker_key": "tls_worker_key",
                 "ciphers": "tls_ciphers", "min_version": "tls_min_version"}


def read_security(path: str | os.PathLike):
    """A ``distributed.security.Security`` from a TOML file of certificate paths (docs/formats.md §13.4).

    Keys: ``ca_file`` (required), ``cert`` and ``key`` (this process's, the
    client's; required), ``scheduler_cert``/``scheduler_key`` and
    ``worker_cert``/``worker_key`` (for a LocalCluster this process starts;
    default ``cert``/``key``), ``ciphers``, ``min_version`` (1.2 or 1.3).
    Relative paths are relative to the TOML file. Encryption is required on
    every connection (``require_encryption``).

    **Raises** :class:`~ringfit.errors.InputError` naming the file and key for
    an unknown or missing key or a certificate file that does not exist.
    """
    import tomllib
    from pathlib import Path

    from ringfit.errors import InputError

    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("file not found (--security names a TOML file of TLS certificate paths)", source=path) from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputError(f"not a readable TOML file ({exc})", source=path) from None
    unknown = [k for k in data if k not in SECURITY_KEYS]
    if unknown:
        raise InputError(f"unknown key {unknown[0]!r}; expected {', '.join(SECURITY_KEYS)}", source=path)
    for key in ("ca_file", "cert", "key"):
        if key not in data:
            raise InputError(f"missing key {key!r} (a PEM file path)", source=path)
    kwargs = {}
    for key, value in data.items():
        if key == "min_version":
            if value not in (1.2, 1.3):
                raise InputError(f"min_version = {value!r}; expected 1.2 or 1.3", source=path)
            import ssl

            kwargs["tls_min_version"] = ssl.TLSVersion.TLSv1_2 if value == 1.2 else ssl.TLSVersion.TLSv1_3
            continue
        if not isinstance(value, str) or not value:
            raise InputError(f"{key} = {value!r}; expected a file path", source=path)
        if key == "ciphers":
            kwargs["tls_ciphers"] = value
            continue
        file = (path.parent / value).expanduser()
        if not file.is_file():
            raise InputError(f"{key} = {value!r}: no such file ({file})", source=path)
        kwargs[SECURITY_KEYS[key]] = str(file)
    for role in ("scheduler", "worker"):
        kwargs.setdefault(f"tls_{role}_cert", kwargs["tls_client_cert"])
        kwargs.setdefault(f"tls_{role}_key", kwargs["tls_client_key"])
    distributed = import_distributed()
    return distributed.Security(require_encryption=True, **kwargs)


def local_cluster(workers: int | None = None, *, memory_limit: str | float | None = "auto", quiet: bool = True,
                  dashboard: str | None = None, security=None):
    """A ``distributed.LocalCluster`` of ``workers`` processes, one thread each.

    **Arguments:**

    - ``workers``: worker processes (default :func:`default_workers`).
    - ``memory_limit``: per worker, in Dask's forms (``"4GB"``, bytes, ``"auto"``
      = this machine's memory / workers, ``None`` = no limit); a worker above
      95 % of it is restarted by its nanny and its task rescheduled.
    - ``quiet``: no Dask log lines (lost workers show in the results); else WARNING and above.
    - ``dashboard``: address of the scheduler's dashboard (``":8787"``,
      ``"127.0.0.1:8787"``); ``None`` (default): no dashboard, and the HTTP
      servers that distributed opens anyway serve nothing (:data:`NO_HTTP_CONFIG`).
    - ``security``: a ``distributed.Security`` (e.g. :func:`read_security`):
      the cluster listens on ``tls://`` and every connection is encrypted.

    Tasks whose worker dies twice are reported ``lost`` (:data:`SCHEDULER_CONFIG`).
    Close it with ``cluster.close()``.
    """
    import logging

    import dask

    distributed = import_distributed()
    workers = int(workers or default_workers())
    config = dict(SCHEDULER_CONFIG)
    if dashboard is None:
        config.update(NO_HTTP_CONFIG)  # the nannies hand this config to their worker processes
    tls = {} if security is None else {"security": security, "protocol": "tls://"}
    with dask.config.set(config):
        return distributed.LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, memory_limit=memory_limit,
            dashboard_address=dashboard, env=worker_env(),
            silence_logs=logging.CRITICAL if quiet else logging.WARNING, **tls,
        )


_HOST = re.compile(r"^(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9]([A-Za-z0-9.\-_]*[A-Za-z0-9])?)$")


def _is_ip(host) -> bool:
    import ipaddress

    try:
        ipaddress.ip_address(str(host).strip("[]"))
    except ValueError:
        return False
    return True


def check_dashboard_address(address: str) -> str | None:
    """``--dashboard``: ``[HOST]:PORT`` (or a bare PORT) Dask can serve its dashboard on; InputError naming the
    option otherwise (before any cluster starts). **Returns** a warning when it is reachable from other machines:
    a wildcard host (empty, ``0.0.0.0``, ``::``) opens every interface; any other non-loopback host, that one."""
    import ipaddress

    from ringfit.errors import InputError

    def bad(why):
        return InputError(f"--dashboard {address!r}: {why}; expected HOST:PORT such as 127.0.0.1:8787")

    text = str(address).strip()
    if not text or any(c.isspace() for c in text):
        raise bad("not an address")
    host, sep, port = text.rpartition(":")
    if not sep:
        host, port = "", text
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise bad(f"port {port!r} is not a number in 1..65535")
    if host and not (_HOST.match(host) or _is_ip(host)):
        raise bad(f"{host!r} is not a host name or IP address")
    bare = host.strip("[]")
    if bare in ("", "0.0.0.0", "::", "*"):
        return (f"--dashboard {address}: the dashboard opens on every network interface, so anyone who can reach "
                f"this machine on port {port} sees the tasks, their arguments and paths; use 127.0.0.1:{port} to "
                "keep it on this machine")
    if bare == "localhost":
        return None
    try:
        loopback = ipaddress.ip_address(bare).is_loopback
    except ValueError:
        loopback = False  # a host name: reachable where that name resolves
    if not loopback:
        return (f"--dashboard {address}: the dashboard opens on {host}, reachable from other machines on port "
                f"{port}; use 127.0.0.1:{port} to keep it on this machine")
    return None


def check_scheduler_address(address: str) -> None:
    """``address`` is a scheduler address Dask can dial (``tcp://HOST:PORT``, ``tls://…``, ``inproc://…``; the
    scheme defaults to tcp): :class:`~ringfit.errors.InputError` naming ``--scheduler`` otherwise, before any
    connection is tried."""
    import_distributed()  # without the extra: the install hint, not a bare ModuleNotFoundError
    from distributed.comm import parse_address
    from distributed.comm.addressing import parse_host_port
    from distributed.comm.registry import backends

    from ringfit.errors import InputError

    def bad(why):
        return InputError(f"--scheduler {address!r}: {why}; expected an address such as tcp://10.0.0.5:8786")

    try:
        scheme, loc = parse_address(address)
    except (ValueError, TypeError) as exc:
        raise bad(_one_line(exc)) from None
    if scheme not in backends:
        raise bad(f"unknown protocol {scheme!r} (known: {', '.join(sorted(backends))})")
    if scheme in ("tcp", "tls"):
        try:
            host, port = parse_host_port(loc, 8786)
        except (ValueError, TypeError) as exc:
            raise bad(_one_line(exc)) from None
        if not (_HOST.match(host or "") or _is_ip(host)):
            raise bad(f"{host!r} is not a host name or IP address")
        if not 0 < int(port) < 65536:
            raise bad(f"port {port} outside 1..65535")


@contextlib.contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None, *, memory_limit="auto",
                warmup: Callable[[], Any] | None = None, timeout: float = 30.0, quiet: bool = True,
                security=None, dashboard: str | None = None):
    """A ``distributed.Client`` on ``scheduler`` (an address) or on a new LocalCluster.

    **Arguments:** ``scheduler``: e.g. ``tcp://10.0.0.5:8786`` or
    ``tls://10.0.0.5:8786``, or ``None`` for a :func:`local_cluster` of
    ``workers`` processes with ``memory_limit`` and ``dashboard``;
    ``security``: a ``distributed.Security`` (:func:`read_security`) for a
    ``tls://`` scheduler, or to start the LocalCluster on TLS (without it a
    ``tls://`` scheduler uses Dask's own ``distributed.comm.tls`` settings);
    ``warmup``: a picklable callable every worker runs once (:class:`WorkerSetup`);
    ``timeout`` [s]: to reach the scheduler; ``quiet``: as in :func:`local_cluster`.

    **Yields:** the client; on exit the client (and a cluster it started) is closed.
    """
    from ringfit.errors import InputError

    distributed = import_distributed()
    cluster = None
    if scheduler:
        check_scheduler_address(scheduler)
        check_scheduler_security(scheduler, security)
        try:
            client = distributed.Client(scheduler, timeout=timeout,
                                        **({} if security is None else {"security": security}))
        except (OSError, ValueError, TypeError) as exc:  # unreachable, refused handshake, wrong certificate
            raise InputError(f"cannot reach the scheduler ({_one_line(exc)})", source=scheduler) from None
    else:
        cluster = local_cluster(workers, memory_limit=memory_limit, quiet=quiet, dashboard=dashboard,
                                security=security)
        client = distributed.Client(cluster, **({} if security is None else {"security": security}))
    try:
        client.register_plugin(WorkerSetup(warmup), name=WorkerSetup.name)
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def check_scheduler_security(scheduler: str | None, security) -> None:
    """A ``tls://`` scheduler has certificates (``security`` or Dask's config); ``security`` goes with ``tls://``.

    **Raises** :class:`~ringfit.errors.InputError` (one line naming the address).
    """
    from ringfit.errors import InputError

    if not scheduler:
        return
    if scheduler.startswith("tls://") and security is None and not _dask_tls_configured():
        raise InputError("a tls:// scheduler needs certificates: give --security FILE.toml (docs/formats.md "
                         "§13.4) or set distributed.comm.tls in the Dask configuration", source=scheduler)
    if security is not None and not scheduler.startswith("tls://"):
        raise InputError("--security is for a tls:// scheduler (or a LocalCluster on TLS); this address is "
                         "not encrypted", source=scheduler)


def _dask_tls_configured() -> bool:
    """Whether Dask's own configuration names a CA file for TLS (``distributed.comm.tls.ca-file``)."""
    import dask

    return bool(dask.config.get("distributed.comm.tls.ca-file", None))


def _all_exist(paths) -> bool:
    return bool(paths) and all(os.path.exists(p) for p in paths)


def _lost_message(exc: BaseException) -> str:
    name = type(exc).__name__
    if name == "KilledWorker":
        return ("its worker died twice while running it (KilledWorker): a crash, or memory above the worker's "
                "limit")
    if name == "CancelledError":
        return "cancelled (scheduler or client went away)"
    return _one_line(f"{name}: {exc}")


def run_tasks(client, tasks: Sequence[Task], *, retries: int = 1, progress: bool = True,
              skip_existing: bool = False, description: str = "tasks",
              max_in_flight: int | None = None) -> list[TaskResult]:
    """Submit ``tasks`` to ``client`` and wait for all of them.

    **Arguments:**

    - ``client``: a ``distributed.Client`` (:func:`open_client`).
    - ``tasks``: :class:`Task` list; ``after`` names must come earlier in it.
    - ``retries``: Dask retries of a task whose *wrapper* raised (a task's own
      failure is a result, not retried; a dead worker is handled by the scheduler).
    - ``progress``: a tqdm bar over tasks on stderr, naming each running task, how long it has run and the
      latest line it printed (relayed from its worker, :class:`TaskStream`), redrawn every
      :data:`PROGRESS_EVERY_S` seconds.
    - ``skip_existing``: a task whose ``outputs`` all exist is not run (``kept``).
    - ``max_in_flight``: tasks submitted at once (default: the cluster's
      worker threads, asked again as workers come and go).

    The client feeds the scheduler: a task is submitted once the tasks it
    needs have succeeded and a worker thread is free for it, so every worker
    holds only the task it runs (a worker that dies takes no queued bystander
    with it, whatever the scheduler's settings) and the scheduler sees only
    independent tasks. Ready tasks deeper in a chain go first, so whole chains
    (a tyre's fit → posterior) finish early.

    **Returns:** one :class:`TaskResult` per task, in the order of ``tasks``.
    Failures never raise; the caller reads ``state``.
    """
    from tqdm.auto import tqdm

    distributed = import_distributed()
    by_name: dict[str, Task] = {}
    depth: dict[str, int] = {}
    order: dict[str, int] = {}
    for i, task in enumerate(tasks):
        if task.name in by_name:
            raise ValueError(f"task name {task.name!r} is not unique")
        missing = [a for a in task.after if a not in by_name]
        if missing:
            raise ValueError(f"task {task.name!r} needs {missing}, which come later or do not exist")
        by_name[task.name], order[task.name] = task, i
        depth[task.name] = 1 + max((depth[a] for a in task.after), default=0)
    pending = dict(by_name)
    done: dict[str, TaskResult] = {}
    keys: dict[str, str] = {}
    queue = distributed.as_completed()
    bar = tqdm(total=len(tasks), desc=description, unit="task", file=sys.stderr, disable=not progress)
    started: dict[str, float] = {}  # running task -> when it was submitted (time.monotonic())
    latest: dict[str, str] = {}  # task -> the latest progress line it relayed

    def on_progress(event) -> None:
        msg = event[1] if isinstance(event, tuple) else event
        if isinstance(msg, dict) and msg.get("task") in started:
            latest[msg["task"]] = str(msg.get("line", ""))

    def redraw() -> None:
        bar.set_postfix_str(running_status(started, latest, sum(not r.ok for r in done.values())))

    def finish(name: str, result: TaskResult) -> None:
        done[name] = result
        started.pop(name, None)
        latest.pop(name, None)
        bar.update(1)
        redraw()

    def slots() -> int:
        if max_in_flight is not None:
            return max(1, int(max_in_flight))
        return max(1, sum(client.nthreads().values()))

    def launch() -> None:
        """Settle on the client what needs no worker; submit ready tasks while threads are free."""
        changed = True
        while changed:
            changed = False
            for name, task in list(pending.items()):
                if not all(a in done for a in task.after):
                    continue
                bad = [done[a] for a in task.after if not done[a].ok]
                if bad:
                    finish(name, TaskResult(name, state="skipped", status=1, outputs=tuple(task.outputs),
                                            error=f"needs {bad[0].name}, which {bad[0].state}"))
                elif skip_existing and _all_exist(task.outputs):
                    finish(name, TaskResult(name, state="kept", outputs=tuple(task.outputs)))
                else:
                    continue
                del pending[name]
                changed = True
        ready = sorted((n for n, t in pending.items() if all(a in done for a in t.after)),
                       key=lambda n: (-depth[n], order[n]))
        free = slots() - len(keys)
        for name in ready[: max(free, 0)]:
            task = pending.pop(name)
            fut = client.submit(execute, name, task.fn, tuple(task.args), tuple(task.outputs), task.kind,
                                key=f"ringfit-task-{_token()}", pure=False, retries=retries)
            keys[fut.key] = name
            started[name] = time.monotonic()
            queue.add(fut)

    stop = threading.Event()

    def redraw_every() -> None:
        while not stop.wait(PROGRESS_EVERY_S):
            redraw()

    if progress:
        with contextlib.suppress(Exception):  # an old scheduler without events: the bar still counts tasks
            client.subscribe_topic(PROGRESS_TOPIC, on_progress)
        threading.Thread(target=redraw_every, name="ringfit-progress", daemon=True).start()
    try:
        launch()
        for fut in queue:
            name = keys.pop(fut.key)
            try:  # a result lost with its worker before it was gathered is recomputed: result() waits for it
                result = fut.result()
            except Exception as exc:  # noqa: BLE001 - KilledWorker, cancelled, a wrapper that kept failing
                result = TaskResult(name, state="lost", status=1, error=_lost_message(exc),
                                    outputs=tuple(by_name[name].outputs))
            fut.release()
            finish(name, result)
            launch()
    finally:
        stop.set()
        if progress:
            with contextlib.suppress(Exception):
                client.unsubscribe_topic(PROGRESS_TOPIC)
        bar.close()
    if pending:  # pragma: no cover - every task is settled or submitted once its needs are done
        raise RuntimeError(f"tasks never ran: {sorted(pending)}")
    return [done[t.name] for t in tasks]


def _clock(seconds: float) -> str:
    seconds = int(seconds)
    return f"{seconds // 3600}h{seconds // 60 % 60:02d}m" if seconds >= 3600 else f"{seconds // 60}m{seconds % 60:02d}s"


def running_status(started: dict, latest: dict, failed: int = 0, now: float | None = None, show: int = 2) -> str:
    """The bar's postfix: the ``show`` longest-running tasks with their run time and latest progress line
    (``tyre1/diagnose 12m03s [modes: rotation 4/9]; tyre2/identify 3m10s; +1 running``), then failures."""
    now = time.monotonic() if now is None else now
    order = sorted(started, key=lambda n: started[n])
    parts = [f"{n} {_clock(now - started[n])}" + (f" [{latest[n]}]" if latest.get(n) else "") for n in order[:show]]
    if len(order) > show:
        parts.append(f"+{len(order) - show} running")
    if failed:
        parts.append(f"{failed} failed")
    return "; ".join(parts)


def _token() -> str:
    import uuid

    return uuid.uuid4().hex


def summarize(results: Sequence[TaskResult], wall_s: float | None = None) -> dict:
    """Figures over a run: counts by state, task time, memory, compilations on warm tasks, overhead.

    **Returns:** dict with ``tasks``, ``by_state`` (state → count), ``task_s``
    (sum of task wall times) [s], ``cpu_s`` (sum of their CPU times) [s], ``median_task_s`` [s], ``max_peak_delta_mb`` and
    ``max_peak_rss_mb`` [MiB] over tasks, ``workers`` (distinct processes),
    ``warm_compiles`` (compilations in tasks that were not the first of their
    kind on their worker; a new input shape compiles again), ``gap_s`` [s]:
    the mean time a worker spent between the end of one task and the start
    of its next (the per-task overhead beyond the work itself) and, with
    ``wall_s``, ``overhead_per_task_s`` = (workers × wall − Σ task time) /
    tasks [s], which also counts idle workers at the start and the end.
    """
    import numpy as np

    ran = [r for r in results if r.worker]
    by_state: dict[str, int] = {}
    for r in results:
        by_state[r.state] = by_state.get(r.state, 0) + 1
    task_s = float(sum(r.elapsed_s for r in ran))
    per_worker: dict[str, list[TaskResult]] = {}
    for r in ran:
        per_worker.setdefault(r.worker, []).append(r)
    gaps = []
    for rs in per_worker.values():
        rs = sorted(rs, key=lambda r: r.started_at)
        gaps += [b.started_at - (a.started_at + a.elapsed_s) for a, b in zip(rs, rs[1:])]
    out = dict(tasks=len(results), by_state=by_state, task_s=task_s, cpu_s=float(sum(r.cpu_s for r in ran)),
               median_task_s=float(np.median([r.elapsed_s for r in ran])) if ran else float("nan"),
               max_peak_delta_mb=max((r.peak_delta_mb for r in ran), default=float("nan")),
               max_peak_rss_mb=max((r.peak_rss_mb for r in ran), default=float("nan")),
               workers=len(per_worker), warm_compiles=int(sum(r.compiles for r in ran if r.kind_index > 0)),
               gap_s=float(np.mean(gaps)) if gaps else float("nan"))
    if wall_s is not None and ran:
        out["wall_s"] = float(wall_s)
        out["overhead_per_task_s"] = (len(per_worker) * float(wall_s) - task_s) / len(ran)
    return out
