"""``ringfit batch`` and ``ringfit campaign``: many inputs as tasks on dask.distributed (docs/formats.md §13).

    ringfit batch {ssi,fit,sample,diagnose,profile,estimate} INPUTS… --out DIR
                  [--scheduler ADDRESS | --workers N] [-- OPTIONS OF THE COMMAND]
    ringfit campaign CAMPAIGN_DIR --out DIR [--scheduler ADDRESS | --workers N]

Each task runs the SAME command a user would type, in-process on a worker:
``ringfit.cli.main([command, input, "--out", output, *options])``. So a batch
gives exactly the serial command's files, and the worker's compiled JAX
functions stay warm from one task to the next. The Dask machinery (cluster,
submission, progress, failures, time and memory per task) is
:mod:`ringfit.batch`; this module only wires the commands to it.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

from ringfit.cli._args import integer

#: Commands ``ringfit batch`` runs, in help order.
BATCH_COMMANDS = ("ssi", "fit", "sample", "diagnose", "profile", "estimate")


@dataclass(frozen=True)
class OutputRule:
    """How a command's per-input output is named: ``DIR/<stem><suffix>`` (+ sidecars).

    - ``inputs``: input suffixes removed to get the stem (first match, case-insensitive);
      a folder input's stem is its name; otherwise the last suffix is removed.
    - ``suffix``: appended to the stem for ``--out``; ``sidecars``: files the
      command writes next to it (same stem).
    - ``defaults``: options added unless the user gave that option (placeholders allowed).
    """

    inputs: tuple[str, ...]
    suffix: str
    sidecars: tuple[str, ...] = ()
    defaults: tuple[tuple[str, ...], ...] = ()


#: The naming rule of every batch command (docs/formats.md §13).
OUTPUT_RULES: dict[str, OutputRule] = {
    "ssi": OutputRule((".records.npz", ".uff", ".unv"), ".modes.csv", (".modes.json",),
                      (("--workers", "1"), ("--quiet",))),
    "fit": OutputRule((".modes.csv",), ".fitted.tyre.toml", (), (("--tyre", "{dir}/tyre.toml"),)),
    # the long commands keep their progress bars: the batch's bar relays each task's latest line
    "sample": OutputRule((".modes.csv",), ".posterior.h5", (), (("--tyre", "{dir}/tyre.toml"),)),
    "diagnose": OutputRule((), ".diagnosis.json", ()),
    "profile": OutputRule((".records.npz",), ".profile.csv", (".profile.json",), (("--quiet",),)),
    "estimate": OutputRule((".profile.csv", ".records.npz"), ".estimate.json", (),
                           (("--tyre", "{dir}/tyre.toml"), ("--quiet",))),
}
PLACEHOLDERS = ("{input}", "{dir}", "{stem}", "{out}")

#: Modules a worker imports once before its first task, per command (missing ones are skipped).
WARM_MODULES = {
    "ssi": ("ringfit.io.records", "ringfit.targets.identify"),
    "fit": ("ringfit.fit.least_squares", "ringfit.fit.identifiability", "ringfit.io.tyre"),
    "sample": ("ringfit.fit.posterior", "ringfit.io.tyre"),
    "identify": ("ringfit.fit.identify", "ringfit.fit.posterior", "ringfit.io.tyre"),
    "diagnose": ("ringfit.gap",),
    "profile": ("ringfit.io.continuous", "ringfit.targets.rolling_profile"),
    "estimate": ("ringfit.fit.estimate", "ringfit.io.profiles", "ringfit.io.tyre"),
}


@dataclass
class PlannedRun:
    """One input of a batch: the command line a worker runs and the files it writes."""

    input: str
    stem: str
    argv: list[str]
    outputs: list[str] = field(default_factory=list)


# ============================================================================ the parsers
def _batch_options(p: argparse.ArgumentParser, *, inputs: bool) -> None:
    if inputs:
        p.add_argument("inputs", nargs="+", help="input files or case folders, one task each")
        p.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder (created if absent)")
    _cluster_options(p)
    p.add_argument("--skip-existing", action="store_true",
                   help="leave out inputs whose outputs are already in DIR (resume an interrupted batch)")
    p.add_argument("--force", action="store_true", help="pass --force to every command (replace outputs)")
    p.add_argument("--dry-run", action="store_true", help="print the command of every input and exit")


def _cluster_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="an existing Dask scheduler, e.g. tcp://10.0.0.5:8786 or, encrypted, tls://10.0.0.5:8786 "
                        "(default: a LocalCluster here)")
    p.add_argument("--security", type=Path, default=None, metavar="FILE.toml",
                   help="TLS certificates (ca_file, cert, key; docs/formats.md §13.4) for a tls:// scheduler, or to "
                        "run the LocalCluster on TLS (default for tls://: Dask's distributed.comm.tls settings)")
    p.add_argument("--dashboard", default=None, metavar="ADDRESS",
                   help="LocalCluster: serve Dask's dashboard here, e.g. 127.0.0.1:8787 (default: none, and no "
                        "HTTP routes at all)")
    p.add_argument("--workers", type=integer("a positive number of workers", lo=1), default=None, metavar="N",
                   help="LocalCluster worker processes, one thread each (default: usable CPUs, at most one per task)")
    p.add_argument("--memory-limit", default="auto", metavar="SIZE",
                   help="LocalCluster memory per worker, e.g. 4GB; a worker above it is restarted and its task "
                        "tried once more (default auto = machine memory / workers)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--verbose", action="store_true", help="print the output of failed tasks and Dask's warnings")


class _InnerParser(argparse.ArgumentParser):
    """The options after the batch command; errors become InputError (exit 2, one line)."""

    def error(self, message):
        from ringfit.errors import InputError

        raise InputError(message)


def _inner_parser(command: str) -> argparse.ArgumentParser:
    p = _InnerParser(prog=f"ringfit batch {command}",
                     description=f"Run `ringfit {command}` on every input as a Dask task.",
                     epilog="Options after `--` go to every command; {input}, {dir}, {stem} and {out} in them "
                            "become the input, its folder, its output stem and DIR/stem.")
    _batch_options(p, inputs=True)
    return p


def register(sub) -> None:
    p = sub.add_parser(
        "batch", help="run one command on many inputs as dask.distributed tasks",
        description="Run `ringfit COMMAND` on every input as one task on a Dask cluster (a LocalCluster of "
                    "worker processes here, or --scheduler). Each output goes to DIR under a name derived from "
                    "its input (docs/formats.md §13); a failing input does not stop the others and is listed at "
                    "the end with its one-line error. Exit 0 if every input succeeded, 1 if some failed, 2 for "
                    "bad batch arguments.",
        epilog="usage after COMMAND: INPUTS... --out DIR [batch options] [-- options of the command]. "
               "Example: ringfit batch fit tyres/*/free.modes.csv --out fits -- --prior physical. "
               "`ringfit batch COMMAND -h` lists the batch options.")
    p.add_argument("batch_command", metavar="COMMAND", choices=BATCH_COMMANDS,
                   help=f"the ringfit command to run on every input: {', '.join(BATCH_COMMANDS)}")
    p.add_argument("rest", nargs=argparse.REMAINDER, metavar="INPUTS... --out DIR [-- OPTIONS]",
                   help="inputs, --out DIR and batch options; after `--`, options for every command")
    _batch_options(p, inputs=False)
    p.set_defaults(run=run_batch)

    c = sub.add_parser(
        "campaign", help="a folder of case folders: targets, fit, posterior, diagnosis per tyre, then a batch report",
        description="For every case folder (one tyre, docs/formats.md §6) in CAMPAIGN_DIR, as Dask tasks: "
                    "targets from free.records.npz by SSI where present (else free.modes.csv as is) -> "
                    "`ringfit fit` -> `ringfit sample` -> `ringfit diagnose`; then a campaign table "
                    "(campaign.csv, one row per tyre) and a self-contained HTML report (campaign.html) built "
                    "from the saved result files (docs/formats.md §13). Exit 0 if every step succeeded, 1 if "
                    "some failed (the table and report are still written), 2 for bad arguments.")
    c.add_argument("campaign", type=Path, help="folder holding one case folder per tyre (each with tyre.toml)")
    c.add_argument("--out", required=True, type=Path, metavar="DIR", help="output folder (created if absent)")
    _cluster_options(c)
    # the same limits as `ringfit sample`'s options: a campaign refuses before any work what its samples would
    c.add_argument("--walkers", type=integer("a whole number of walkers >= 2", lo=2), default=32, help="walkers of `ringfit sample` (default 32)")
    steps = integer("a whole number of steps >= 100", lo=100)
    c.add_argument("--min-steps", type=steps, default=2000, help="`ringfit sample --min-steps` (default 2000)")
    c.add_argument("--max-steps", type=steps, default=20000, help="`ringfit sample --max-steps` (default 20000)")
    c.add_argument("--seed", type=integer("a whole number >= 0", lo=0), default=0, help="`ringfit sample --seed` (default 0)")
    c.add_argument("--prior", default="physical", choices=("physical", "none"),
                   help="prior of `ringfit fit` and `ringfit sample` (default physical)")
    c.add_argument("--effects", default=None, help="`ringfit diagnose --effects` (default: all registered)")
    c.add_argument("--skip-existing", action="store_true",
                   help="keep per-tyre results already in DIR (resume); the table and report are rebuilt")
    c.add_argument("--force", action="store_true", help="replace existing outputs")
    c.set_defaults(run=run_campaign)


# ============================================================================ planning
def output_stems(inputs: list[str], rule: OutputRule) -> list[str]:
    """The output stem of every input (docs/formats.md §13).

    A folder's stem is its name; a file's is its name less the first of
    ``rule.inputs`` it ends with (else less its last suffix). Inputs that
    share a stem get their parent folder's name in front, joined by ``-``
    (``tyre07/free.modes.csv`` → ``tyre07-free``); if that still collides,
    :class:`~ringfit.errors.InputError`.
    """
    from ringfit.errors import InputError

    def stem(path: Path) -> str:
        if path.is_dir():
            return path.resolve().name
        low = path.name.lower()
        for suffix in rule.inputs:
            if low.endswith(suffix) and len(low) > len(suffix):
                return path.name[: -len(suffix)]
        return path.stem

    paths = [Path(x) for x in inputs]
    stems = [stem(p) for p in paths]
    for x, s in zip(inputs, stems):
        if not s or s in (".", "..") or "/" in s or "\\" in s:
            raise InputError("has no name to derive an output name from (the root folder?); expected input "
                             "files or case folders with a name", source=x)
    counts = {s: stems.count(s) for s in stems}
    stems = [f"{p.resolve().parent.name}-{s}" if counts[s] > 1 else s for p, s in zip(paths, stems)]
    seen: dict[str, str] = {}
    for x, s in zip(inputs, stems):
        if s in seen:
            raise InputError(f"{x} and {seen[s]} would write the same output {s!r}; rename one or run them "
                             "in separate batches")
        seen[s] = x
    return stems


def _has_option(extra: list[str], option: str) -> bool:
    return any(a == option or a.startswith(option + "=") for a in extra)


def plan_batch(command: str, inputs: list[str], out_dir, extra: list[str] = (), *, force: bool = False) -> list[PlannedRun]:
    """The command line and outputs of every input of ``ringfit batch COMMAND``.

    **Arguments:** ``command`` (one of :data:`BATCH_COMMANDS`), ``inputs``
    (paths), ``out_dir`` (DIR), ``extra`` (options for every command, with
    placeholders ``{input}``, ``{dir}``, ``{stem}``, ``{out}``), ``force``.

    **Returns:** one :class:`PlannedRun` per input, in order; running each
    ``argv`` with ``ringfit.cli.main`` one after another is the serial
    equivalent of the batch.
    """
    from ringfit.errors import InputError

    rule = OUTPUT_RULES[command]
    extra = list(extra)
    for a in extra:
        if a == "--out" or a.startswith("--out="):
            raise InputError("--out after `--`: batch sets each command's output (use the batch's --out DIR)")
        for token in re.findall(r"\{[A-Za-z_]+\}", a):
            if token not in PLACEHOLDERS:
                raise InputError(f"unknown placeholder {token} in {a!r}; known: {', '.join(PLACEHOLDERS)}")
    if len(set(map(str, inputs))) != len(inputs):
        raise InputError("an input is given twice")
    from ringfit.io.conditions import duplicate_inputs

    for kept, dup, how in duplicate_inputs(inputs):  # a symlink or a copy of another input: its data twice
        raise InputError(f"is {how} as {inputs[kept]}: an input is given twice (its results would be counted twice)",
                         source=inputs[dup])
    for option in rule.defaults:
        if not _has_option(extra, option[0]):
            extra += list(option)
    if force and "--force" not in extra:
        extra.append("--force")
    out_dir = Path(out_dir)
    plans = []
    for x, stem in zip(inputs, output_stems(list(map(str, inputs)), rule)):
        out = out_dir / stem
        values = {"{input}": str(x), "{dir}": str(Path(x).parent), "{stem}": stem, "{out}": str(out)}

        def fill(a: str) -> str:
            for k, v in values.items():
                a = a.replace(k, v)
            return a

        primary = str(out) + rule.suffix
        if Path(primary).parent != out_dir:
            raise InputError(f"would write {primary}, outside --out {out_dir}", source=x)
        arg = str(x) if not str(x).startswith("-") else "./" + str(x)  # -x... would read as an option
        argv = [command, arg, "--out", primary, *map(fill, extra)]
        plans.append(PlannedRun(str(x), stem, argv, [primary] + [str(out) + s for s in rule.sidecars]))
    return plans


def check_command_line(argv: list[str]) -> None:
    """Parse ``argv`` with ringfit's own parser, without running it; InputError with argparse's message."""
    import contextlib
    import io

    from ringfit.cli import build_parser
    from ringfit.errors import InputError

    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            build_parser().parse_args(argv)
    except SystemExit as exc:
        if exc.code:
            raise InputError(f"options for `ringfit {argv[0]}`: {_last_line(err.getvalue())}") from None


# ============================================================================ on the worker
def _last_line(text: str) -> str:
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return lines[-1] if lines else ""


class _Tee(io.StringIO):
    """Keeps what is written (for the last error line) and passes it on at once to ``out``."""

    def __init__(self, out):
        super().__init__()
        self.out = out

    def write(self, text: str) -> int:
        self.out.write(text)
        return super().write(text)

    def flush(self) -> None:
        self.out.flush()


def run_command(argv: list[str], cwd: str | None = None) -> int:
    """Run one ringfit command in this process, as the shell would (a batch task).

    **Arguments:** ``argv`` (without ``ringfit``); ``cwd``: the folder the
    batch was started in: relative paths in ``argv`` are read from there (the
    worker's file system must hold it under the same path). Its stdout and
    stderr go to the caller's streams as they are written (the batch captures
    them and relays its progress lines, :class:`ringfit.batch.TaskStream`).

    **Raises:** :class:`ringfit.batch.TaskFailed` with the command's last stderr
    line and its exit status when that status is not 0.
    """
    import contextlib
    import os

    from ringfit.batch import TaskFailed
    from ringfit.cli import main

    here = os.getcwd()
    if cwd is not None and os.path.abspath(cwd) != here:
        try:
            os.chdir(cwd)  # one task at a time per worker process (ringfit.batch.execute), so this is safe
        except OSError:
            raise TaskFailed(f"the batch's folder {cwd} is not on this worker (tasks send paths: the inputs "
                             "and DIR need a file system every worker sees)", status=2) from None
    err = _Tee(sys.stderr)
    try:
        with contextlib.redirect_stderr(err):
            try:
                status = main(list(argv))
            except SystemExit as exc:  # argparse's own errors
                status = exc.code if isinstance(exc.code, int) else 2
    finally:
        os.chdir(here)
    text = err.getvalue()
    if status:
        raise TaskFailed(_last_line(text) or f"`ringfit {argv[0]}` exited with status {status}", status)
    return 0


def warm_up(commands: tuple[str, ...]) -> None:
    """Worker warm-up: the CLI, the commands' modules and JAX's persistent compilation cache."""
    import importlib

    from ringfit._cache import enable_compilation_cache
    from ringfit.cli import build_parser

    build_parser()
    enable_compilation_cache()
    for command in commands:
        for name in WARM_MODULES.get(command, ()):
            try:
                importlib.import_module(name)
            except ImportError:
                pass


# ============================================================================ the handlers
def _check_cluster_options(opts) -> None:
    """Before any work: distributed importable, --workers only for a LocalCluster, a valid --memory-limit."""
    from ringfit.batch import import_distributed
    from ringfit.errors import InputError

    try:
        import_distributed()
    except ImportError as exc:
        raise InputError(str(exc)) from None
    if opts.scheduler and opts.workers:
        raise InputError("--workers starts a LocalCluster; with --scheduler the cluster's own workers run the "
                         "tasks (start them with `dask worker`)")
    if opts.scheduler:
        from ringfit.batch import check_scheduler_address

        check_scheduler_address(opts.scheduler)
    if opts.scheduler and opts.dashboard:
        raise InputError("--dashboard starts the LocalCluster's dashboard; a --scheduler serves its own "
                         "(`dask scheduler --dashboard-address`)")
    if opts.dashboard is not None:
        import warnings

        from ringfit.batch import check_dashboard_address

        note = check_dashboard_address(opts.dashboard)
        if note:
            warnings.warn(note, stacklevel=2)
    opts.security_obj = None
    from ringfit.batch import check_scheduler_security

    check_scheduler_security(opts.scheduler, opts.security)
    if opts.security is not None:
        from ringfit.batch import read_security

        opts.security_obj = read_security(opts.security)
    opts.memory_limit = _memory_limit(opts.memory_limit)


def _split_rest(rest: list[str]) -> tuple[list[str], list[str]]:
    if "--" in rest:
        i = rest.index("--")
        return rest[:i], rest[i + 1:]
    return rest, []


def _refuse_inputs_like_options(parser: argparse.ArgumentParser, head: list[str]) -> None:
    """An input file whose name starts with ``-`` would be read as an option: say so, and how to name it."""
    from ringfit.errors import InputError

    known = set(parser._option_string_actions)
    for token in head:
        if token.startswith("-") and token.split("=", 1)[0] not in known and Path(token).exists():
            raise InputError(f"an input whose name starts with '-' reads as an option; name it ./{token}",
                             source=token)


def run_batch(args) -> int:
    import os
    import shlex

    from ringfit.errors import InputError

    head, extra = _split_rest(list(args.rest))
    parser = _inner_parser(args.batch_command)
    _refuse_inputs_like_options(parser, head)
    opts = parser.parse_args(head, namespace=argparse.Namespace(**vars(args)))
    _check_cluster_options(opts)
    plans = plan_batch(args.batch_command, opts.inputs, opts.out, extra, force=opts.force)
    check_command_line(plans[0].argv)
    if opts.dry_run:
        for plan in plans:
            print("ringfit " + shlex.join(plan.argv))
        return 0
    if opts.out.exists() and not opts.out.is_dir():
        raise InputError("exists and is not a folder", source=opts.out)
    created = not opts.out.exists()
    try:
        opts.out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"--out: cannot create the folder ({exc.strerror or exc.__class__.__name__})",
                         source=opts.out) from None

    from ringfit.batch import Task

    cwd = os.getcwd()
    tasks = [Task(plan.input, run_command, (plan.argv, cwd), outputs=tuple(plan.outputs), kind=args.batch_command)
             for plan in plans]
    if not opts.quiet:
        print("\n".join(work_summary(tasks)), file=sys.stderr)
    try:
        results, timing = _run(opts, tasks, (args.batch_command,), f"ringfit {args.batch_command}")
    except BaseException:
        if created:  # a scheduler that cannot be reached leaves no empty folder behind
            with contextlib.suppress(OSError):
                opts.out.rmdir()
        raise
    return _report(opts, results, timing)


def _run(opts, tasks, commands, description):
    """Open the client and run the tasks (``opts`` checked by :func:`_check_cluster_options`).

    **Returns:** (results, (start seconds, run seconds)).
    """
    import functools
    import time

    from ringfit.batch import open_client, run_tasks

    workers = opts.workers or None
    if not opts.scheduler:
        from ringfit.batch import default_workers

        workers = min(workers or default_workers(), len(tasks))
    where = opts.scheduler or (f"a LocalCluster of {workers} worker process{'es' if workers > 1 else ''}"
                               + (" on TLS" if opts.security_obj is not None else "")
                               + (f", dashboard {opts.dashboard}" if opts.dashboard else ""))
    print(f"{description}: {len(tasks)} task{'s' if len(tasks) != 1 else ''} on {where}", file=sys.stderr)
    t0 = time.perf_counter()
    with open_client(opts.scheduler, workers, memory_limit=opts.memory_limit,
                     warmup=functools.partial(warm_up, tuple(commands)), quiet=not opts.verbose,
                     security=opts.security_obj, dashboard=opts.dashboard) as client:
        t1 = time.perf_counter()
        results = run_tasks(client, tasks, progress=not opts.quiet, skip_existing=opts.skip_existing,
                            description=description)
        t2 = time.perf_counter()
    return results, (t1 - t0, t2 - t1)


def _memory_limit(text: str):
    """--memory-limit: 'auto', 'none' (no limit) or a size such as 4GB."""
    from ringfit.errors import InputError

    if text in ("auto", "none"):
        return None if text == "none" else text
    try:
        from dask.utils import parse_bytes

        if parse_bytes(text) <= 0:
            raise ValueError
    except (ValueError, TypeError, ImportError):
        raise InputError(f"--memory-limit {text!r}: expected a size like 4GB, 'auto' or 'none'") from None
    return text


def _report(opts, results, timing) -> int:
    """Print the counts, the figures and the table of inputs that did not succeed; the exit status."""
    from ringfit.batch import summarize

    start_s, run_s = timing
    s = summarize(results, run_s)
    states = ", ".join(f"{n} {k}" for k, n in sorted(s["by_state"].items(), key=lambda kv: kv[0] != "ok"))
    print(f"{states} in {run_s:.1f} s (+ {start_s:.1f} s to start the workers)")
    if s["workers"]:
        print(f"  tasks: median {s['median_task_s']:.2f} s, total {s['task_s']:.1f} s on {s['workers']} worker "
              f"process{'es' if s['workers'] > 1 else ''}; peak memory per task {s['max_peak_delta_mb']:.0f} MiB "
              f"above its worker's level (worker peak {s['max_peak_rss_mb']:.0f} MiB); "
              f"XLA compilations in tasks after a worker's first of their kind: {s['warm_compiles']}")
    failed = [r for r in results if not r.ok]
    if failed:
        width = min(60, max(len(r.name) for r in failed))
        print(f"{len(failed)} of {len(results)} did not succeed:")
        print(f"  {'input':<{width}}  {'state':<8} {'exit':>4}  error")
        for r in failed:
            print(f"  {r.name:<{width}}  {r.state:<8} {r.status:>4}  {r.error}")
            if opts.verbose and r.log:
                print("    | " + r.log.rstrip().replace("\n", "\n    | "), file=sys.stderr)
        return 1
    return 0


# ============================================================================ campaign
def campaign_tyres(folder: Path) -> list[Path]:
    """The case folders of a campaign: sub-folders holding ``tyre.toml``, sorted by name."""
    from ringfit.errors import InputError

    if not folder.is_dir():
        raise InputError("is not a folder; expected a folder of case folders (one per tyre)", source=folder)
    tyres = sorted(p for p in folder.iterdir() if p.is_dir() and (p / "tyre.toml").exists())
    if not tyres:
        raise InputError("holds no case folder (a sub-folder with tyre.toml, docs/formats.md §6)", source=folder)
    # a symlink to another tyre's folder is that tyre twice: counted once (the folder itself kept)
    import warnings

    real = {}
    for p in sorted(tyres, key=lambda p: (p.is_symlink(), p.name)):
        r = p.resolve()
        if r in real:
            warnings.warn(f"{p.name} is the same folder as {real[r].name} (a symlink): that tyre is counted once "
                          f"({real[r].name} used)", stacklevel=2)
        else:
            real[r] = p
    return sorted(real.values())


#: Free-tyre records a campaign turns into targets by SSI, first found wins (docs/formats.md §13).
FREE_RECORDS = ("free.records.npz", "free.uff", "free.unv")


@dataclass(frozen=True)
class CampaignTyre:
    """One tyre of a campaign, its case folder read before any work (:func:`read_campaign_tyre`).

    ``records``: the free-tyre records its targets come from by SSI (``None``: its ``free.modes.csv`` as it is);
    ``tables``, ``profiles``: its other mode tables and its rolling profiles, as the case reader gives them."""

    folder: Path
    records: Path | None
    tables: tuple = ()
    profiles: tuple = ()

    @property
    def joint_data(self) -> bool:
        """Whether it holds states ``ringfit identify`` uses beside the free table: a rolling profile, or a standing
        table (no speed, no rotation) whose sidecar says ``state = "loaded"`` (its ``load_n`` is checked by
        identify itself)."""
        from ringfit.io.case import sidecar_number

        def standing(cond):
            return not (sidecar_number(cond, "speed_kmh") or sidecar_number(cond, "rotation_hz") or 0.0)

        return bool(self.profiles) or any(t.state == "loaded" and standing(t.condition) for t in self.tables)


def read_campaign_tyre(folder: Path) -> CampaignTyre:
    """A campaign's tyre folder read by the one case-folder reader (:func:`ringfit.io.case.read_case_folder`, its
    rules and one-line errors naming the file: a sidecar that is not JSON included), before any work.

    A folder whose free modes come from records (:data:`FREE_RECORDS`) has no ``free.modes.csv`` until ``ringfit
    ssi`` writes it, and the reader requires one; its test tables and profiles are read by the readers
    ``read_case_folder`` uses for them (the whole folder is read by the case reader in the identify and diagnose
    steps, after SSI)."""
    records = next((folder / r for r in FREE_RECORDS if (folder / r).exists()), None)
    if records is None:
        from ringfit.io.case import read_case_folder

        case = read_case_folder(folder)
        return CampaignTyre(folder, None, tuple(case.tables), tuple(case.profiles))
    from ringfit.io.conditions import case_inputs
    from ringfit.io.modes import read_mode_table
    from ringfit.io.profiles import read_profile
    from ringfit.io.tyre import read_tyre

    read_tyre(folder / "tyre.toml")
    table_paths, profile_paths = case_inputs(folder)
    return CampaignTyre(folder, records, tuple(map(read_mode_table, table_paths)),
                        tuple(map(read_profile, profile_paths)))


def plan_campaign(tyres: list[CampaignTyre], out_dir: Path, opts) -> tuple[list, dict]:
    """Tasks of a campaign (its tyres read by :func:`read_campaign_tyre`) and, per tyre, its output paths
    (docs/formats.md §13 layout)."""
    import os
    import shutil

    from ringfit.batch import Task
    from ringfit.cli.identify import report_path as identify_report_path

    force = ["--force"] if opts.force else []
    # the long steps (posteriors, identify, diagnose) keep their progress bars: the campaign's bar relays them
    steps = ["--min-steps", str(opts.min_steps), "--max-steps", str(opts.max_steps), "--seed", str(opts.seed)]
    sample_opts = ["--walkers", str(opts.walkers), *steps, "--prior", opts.prior]
    cwd = os.getcwd()

    def step(tyre: str, kind: str, argv: list[str], after: tuple, outputs: list) -> Task:
        return Task(f"{tyre}/{kind}", run_command, (argv, cwd), after=tuple(after),
                    outputs=tuple(map(str, outputs)), kind=kind)

    tasks, layout = [], {}
    for read in tyres:
        tyre, records = read.folder, read.records
        name = tyre.name
        dest = out_dir / name
        dest.mkdir(parents=True, exist_ok=True)
        paths = dict(folder=str(dest), fitted=str(dest / "fitted.tyre.toml"), posterior=str(dest / "posterior.h5"),
                     diagnosis=str(dest / "diagnosis.json"), source=str(tyre), records=None)
        after: tuple[str, ...] = ()
        if records is not None:
            # a view of the case folder whose free.modes.csv is the SSI table: fit and diagnosis use the same targets
            case = dest / "case"
            case.mkdir(exist_ok=True)
            for f in tyre.iterdir():
                if f.is_file() and not f.name.startswith("free.") and not f.name.endswith(".records.npz"):
                    target = case / f.name
                    if opts.force or not target.exists():
                        shutil.copy2(f, target)
            targets = case / "free.modes.csv"
            paths.update(case=str(case), targets=str(targets), records=str(records))
            tasks.append(step(name, "ssi", ["ssi", str(records), "--out", str(targets), "--workers", "1",
                                             "--quiet", *force], (), [targets, targets.with_suffix(".json")]))
            after = (f"{name}/ssi",)
        else:
            case, targets = tyre, tyre / "free.modes.csv"
            paths.update(case=str(case), targets=str(targets))
        if read.joint_data:
            # loaded tables at a known load or profiles: the tyre is identified once from everything measured
            # (``ringfit identify``, its posterior included); every later step reads that tyre file
            tasks.append(step(name, "identify", ["identify", str(case), "--out", paths["fitted"], "--posterior",
                                                 paths["posterior"], *steps, *force], after,
                              [paths["fitted"], paths["posterior"], identify_report_path(Path(paths["fitted"]))]))
            paths["identified"] = True
            first = f"{name}/identify"
        else:
            tasks.append(step(name, "fit", ["fit", str(targets), "--tyre", str(tyre / "tyre.toml"), "--out",
                                            paths["fitted"], "--prior", opts.prior, *force], after,
                              [paths["fitted"]]))
            tasks.append(step(name, "sample", ["sample", str(targets), "--tyre", paths["fitted"], "--out",
                                               paths["posterior"], *sample_opts, *force], (f"{name}/fit",),
                              [paths["posterior"]]))
            first = f"{name}/fit"
        diag_opts = ["--effects", opts.effects] if opts.effects else []
        # one ring per tyre: the diagnosis takes the fitted tyre file as its baseline (not a refit of its own), so the
        # campaign table (read from that file) and the diagnosis agree by construction
        tasks.append(step(name, "diagnose", ["diagnose", str(case), "--out", paths["diagnosis"], "--tyre",
                                             paths["fitted"], *diag_opts, *force], (first,),
                          [paths["diagnosis"]]))
        layout[name] = paths
    return tasks, layout


def work_summary(tasks, opts=None) -> list[str]:
    """What a run will do and which of it takes long, said before any work: the tasks by kind and, for a
    campaign (``opts`` with ``walkers``), the size of each posterior and of each diagnosis's null tests."""
    from collections import Counter

    from ringfit.cli.gap import DEFAULT_NULL_DRAWS

    kinds = Counter(t.kind for t in tasks)
    lines = [f"work: {len(tasks)} task{'s' if len(tasks) != 1 else ''} ("
             + ", ".join(f"{n} {k}" for k, n in kinds.items()) + ")"]
    if kinds.get("sample") and hasattr(opts, "walkers"):
        n = kinds["sample"]
        lines.append(f"  long: {n} posterior{'s' if n != 1 else ''} (sample), each {opts.walkers} walkers × "
                     f"{opts.min_steps}–{opts.max_steps} steps, until the chain is 50 autocorrelation times long")
    if kinds.get("identify") and hasattr(opts, "min_steps"):
        n = kinds["identify"]
        lines.append(f"  long: {n} joint identification{'s' if n != 1 else ''}, each a joint fit and its posterior "
                     f"(2 walkers per free parameter × {opts.min_steps}–{opts.max_steps} steps)")
    if kinds.get("diagnose"):
        n = kinds["diagnose"]
        lines.append(f"  long: {n} diagnos{'is' if n == 1 else 'es'}: every candidate effect refitted, then each round "
                     f"with an accepted candidate tested against {DEFAULT_NULL_DRAWS} draws of each null "
                     "(the whole selection redone per draw; minutes per folder)")
    lines.append("  the bar names each running task, how long it has run and the latest line it printed")
    return lines


def _check_campaign_options(args) -> None:
    """What every tyre's sample and diagnosis would refuse, refused before any work (one line naming the option)."""
    from ringfit.cli.gap import parse_effects
    from ringfit.errors import InputError
    from ringfit.cli.free import DEFAULT_FREE

    if args.max_steps < args.min_steps:
        raise InputError(f"--max-steps {args.max_steps} is below --min-steps {args.min_steps}")
    k = len(DEFAULT_FREE.split(","))
    if args.walkers % 2 or args.walkers < 2 * k:
        raise InputError(f"--walkers {args.walkers}: the stretch move needs an even number of at least {2 * k} "
                         f"(2 × {k} free parameters of the campaign's fits)")
    parse_effects(args.effects)


def run_campaign(args) -> int:
    from ringfit.errors import InputError
    from ringfit.io.files import check_output_path

    _check_cluster_options(args)
    _check_campaign_options(args)
    # every tyre's folder read by the case reader before any work: a folder it refuses is refused here (exit 2)
    tyres = [read_campaign_tyre(t) for t in campaign_tyres(args.campaign)]
    if args.out.exists() and not args.out.is_dir():
        raise InputError("exists and is not a folder", source=args.out)
    if args.out.resolve() == args.campaign.resolve() or args.campaign.resolve() in args.out.resolve().parents:
        raise InputError("is inside the campaign folder; choose an output folder outside it", source=args.out)
    args.out.mkdir(parents=True, exist_ok=True)
    table_path, report_path = args.out / "campaign.csv", args.out / "campaign.html"
    rebuild = args.force or args.skip_existing
    for path in (table_path, report_path):
        check_output_path(path, overwrite=rebuild)
    tasks, layout = plan_campaign(tyres, args.out, args)
    if not args.quiet:
        print(f"ringfit campaign: {len(tyres)} tyre folder{'s' if len(tyres) != 1 else ''} in {args.campaign}",
              file=sys.stderr)
        print("\n".join(work_summary(tasks, args)), file=sys.stderr)
    results, timing = _run(args, tasks, ("ssi", "fit", "sample", "identify", "diagnose"), "ringfit campaign")

    from ringfit.report.campaign import collect_campaign, write_campaign_csv, write_campaign_report

    campaign = collect_campaign(layout, results)
    write_campaign_csv(campaign, table_path, overwrite=rebuild)
    write_campaign_report(campaign, report_path, overwrite=rebuild, title=f"ringfit campaign — {args.campaign.name}")
    status = _report(args, results, timing)
    print(f"wrote {table_path} and {report_path} ({len(tyres)} tyres; {campaign.summary_line()})")
    return status
