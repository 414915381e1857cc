"""The ``ringfit`` command line: parse, call the library, print, exit codes.

Each command family lives in its own module here and adds its subcommands in
``register(subparsers)``; heavy imports happen inside the handlers so that
``ringfit --help`` and a cold ``ringfit fit`` stay fast.

Exit codes: 0 success, 1 the job ran but did not succeed (e.g. a fit that did
not converge), 2 bad input (one line on stderr naming file/row/field/option;
argparse's own errors are one line too), 130 interrupted (Ctrl-C), 141 the
reader of stdout went away (``ringfit … | head``; :func:`run`). Warnings raised by the library go to
stderr as one ``WARNING:`` line each. ``ringfit --help`` imports no JAX. A
command's output files appear together when it succeeds, or none does. Every command
runs with JAX's persistent compilation cache on (:mod:`ringfit._cache`).
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import sys
import warnings

#: Modules that contribute subcommands, in help order.
COMMAND_MODULES = (
    "ringfit.cli.free",
    "ringfit.cli.identify",
    "ringfit.cli.rolling",
    "ringfit.cli.gap",
    "ringfit.cli.targets",
    "ringfit.cli.cleat",
    "ringfit.cli.example",
    "ringfit.cli.batch",
    "ringfit.cli.campbell",
    "ringfit.cli.estimate",
)


#: Commands that read back files they wrote (a workflow, a folder built in steps, tasks): their outputs are
#: written one by one. Every other command's outputs are committed together or not at all
#: (:func:`ringfit.io.files.outputs_committed_together`).
WRITES_AS_IT_GOES = frozenset({"demo", "example", "batch", "campaign"})


class CommandFailed(Exception):
    """The command ran but its job did not succeed (exit status 1)."""


class OneLineParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose errors are one line (what, which option, where to look), exit status 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see '{self.prog} --help')\n")


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="ringfit",
        description="Tyre structural dynamics from one embedded accelerometer.",
    )
    parser.add_argument("--version", action="version", version="ringfit 0.1.0")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, parser_class=OneLineParser)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a one-line usage error (status 2)
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2
    from ringfit._cache import enable_compilation_cache
    from ringfit._precision import PrecisionError, require_x64
    from ringfit.errors import InputError
    from ringfit.io.files import outputs_committed_together

    enable_compilation_cache()  # every command: a second run skips XLA compilation (imports no JAX)
    try:
        require_x64(f"ringfit {args.command}")  # never compute in float32 (ringfit._precision)
    except PrecisionError as exc:
        print(f"ringfit {args.command}: error: {exc}", file=sys.stderr)
        return 2
    together = outputs_committed_together() if args.command not in WRITES_AS_IT_GOES else contextlib.nullcontext()
    with _ctrl_c_recorded():
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                try:
                    with together:
                        status = args.run(args)
                finally:
                    _print_warnings(caught)
            from ringfit.io.files import check_not_interrupted

            check_not_interrupted()  # a Ctrl-C swallowed on its way up still ends the command with 130
        except (InputError, PrecisionError) as exc:
            print(f"ringfit {args.command}: error: {exc}", file=sys.stderr)
            return 2
        except CommandFailed as exc:
            print(f"ringfit {args.command}: {exc}", file=sys.stderr)
            return 1
        except KeyboardInterrupt:
            print(f"ringfit {args.command}: interrupted", file=sys.stderr)
            return 130
    return int(status or 0)


_DEPTH = [0]


@contextlib.contextmanager
def _ctrl_c_recorded():
    """SIGINT both raises KeyboardInterrupt (as Python's own handler does) and records itself
    (:func:`ringfit.io.files.mark_interrupted`), so that a KeyboardInterrupt swallowed on its way up — raised
    inside a garbage-collector callback such as JAX's ``_xla_gc_callback``, where Python only prints "Exception
    ignored" — still stops the command before any output is committed, with exit status 130. The record is
    cleared when an outermost command starts and ends (a batch task run in-process keeps its batch's); the
    handler is installed only in the main thread and restored afterwards."""
    import signal
    import threading

    from ringfit.io import files

    outer = _DEPTH[0] == 0
    if outer:
        files.clear_interrupted()
    previous = None
    if outer and threading.current_thread() is threading.main_thread():
        def on_sigint(signum, frame):
            files.mark_interrupted()
            raise KeyboardInterrupt

        try:
            previous = signal.signal(signal.SIGINT, on_sigint)
        except (ValueError, OSError):
            previous = None
    _DEPTH[0] += 1
    try:
        yield
    finally:
        _DEPTH[0] -= 1
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
        if outer:  # the command is over (its status says the interrupt): a caller's own writes go on
            files.clear_interrupted()


def run() -> None:
    """The ``ringfit`` console command (and ``python -m ringfit``): :func:`main`, then the end of the process.

    A JAX process spends about 0.5 s of CPU in the interpreter's teardown after its last output — clearing
    modules and freeing every compiled program — which a one-off command never needs. Where nothing else is
    still running (no child process, no live thread that is not a daemon) the command therefore ends with
    ``os._exit`` once the exit handlers have run (``atexit``: logging's flush, temporary files, libraries'
    own) and stdout and stderr are flushed; otherwise it exits as usual. The exit status is :func:`main`'s;
    a reader of stdout that went away (``ringfit … | head``) ends the command quietly with status 141, as
    SIGPIPE ends a Unix tool (outputs not yet committed when the pipe broke are not written).
    """
    try:
        status = main()
    except BrokenPipeError:
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error at the final flush
        status = 141
    _end(status)


def _end(status: int) -> None:
    import atexit
    import os
    import threading

    mp = sys.modules.get("multiprocessing")
    busy = (mp is not None and mp.active_children()) or any(
        t.is_alive() and not t.daemon for t in threading.enumerate() if t is not threading.main_thread())
    if busy:
        sys.exit(status)
    atexit._run_exitfuncs()  # what a normal exit would run, in the same order
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except BrokenPipeError:  # the reader went away (`ringfit … | head`): as SIGPIPE would end it
            status = status or 141
        except (OSError, ValueError):  # a closed stream: nothing more to say
            pass
    os._exit(status)


def _print_warnings(caught) -> None:
    """Each library warning as one ``WARNING:`` line on stderr (repeats and library-internal noise dropped)."""
    seen = set()
    for w in caught:
        if issubclass(w.category, (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning)):
            continue
        text = " ".join(str(w.message).split())
        if text and text not in seen:
            seen.add(text)
            print(f"WARNING: {text}", file=sys.stderr)


if __name__ == "__main__":  # pragma: no cover
    run()
