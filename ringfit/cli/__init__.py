"""The ``ringfit`` command line: parse, call the library, print, exit codes.

Each command family lives in its own module here and adds its subcommands in
``register(subparsers)``; heavy imports happen inside the handlers so that
``ringfit --help`` and a cold ``ringfit fit`` stay fast.

Exit codes: 0 success, 1 the job ran but did not succeed (e.g. a fit that did
not converge), 2 bad input (one line on stderr naming file/row/field).
"""

from __future__ import annotations

import argparse
import importlib
import sys

#: Modules that contribute subcommands, in help order.
COMMAND_MODULES = (
    "ringfit.cli.free",
    "ringfit.cli.rolling",
    "ringfit.cli.gap",
    "ringfit.cli.targets",
    "ringfit.cli.cleat",
    "ringfit.cli.estimate",
)


class CommandFailed(Exception):
    """The command ran but its job did not succeed (exit status 1)."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ringfit",
        description="Tyre structural dynamics from one embedded accelerometer.",
    )
    parser.add_argument("--version", action="version", version="ringfit 0.1.0")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from ringfit.errors import InputError

    try:
        status = args.run(args)
    except InputError as exc:
        print(f"ringfit {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except CommandFailed as exc:
        print(f"ringfit {args.command}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"ringfit {args.command}: interrupted", file=sys.stderr)
        return 130
    return int(status or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
