"""Argument types shared by the commands: every number an option takes is checked when it is parsed.

Each returns a converter for ``argparse``'s ``type=``; a bad value ends in
argparse's one-line error naming the option (``ringfit ssi: error: argument
--skip: expected a finite number of seconds >= 0; got 'nan'``), exit status 2.
"""

from __future__ import annotations

import argparse
import math


def number(what: str = "a number", *, lo: float | None = None, hi: float | None = None,
           lo_open: bool = False, hi_open: bool = False):
    """A finite float in [lo, hi] (``lo_open``/``hi_open`` exclude the ends)."""

    def convert(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        ok = math.isfinite(value)
        if ok and lo is not None:
            ok = value > lo if lo_open else value >= lo
        if ok and hi is not None:
            ok = value < hi if hi_open else value <= hi
        if not ok:
            raise argparse.ArgumentTypeError(f"expected {what}; got {text!r}")
        return value

    return convert


def integer(what: str = "a whole number", *, lo: int | None = None, hi: int | None = None):
    """A whole number in [lo, hi]."""

    def convert(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or (lo is not None and value < lo) or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"expected {what}; got {text!r}")
        return value

    return convert


def drum_diameter():
    """A drum diameter [m] in :data:`ringfit.io.modes.DRUM_DIAMETER_RANGE_M` (``--drum``; the range is imported
    when the option is given, so that ``--help`` stays free of NumPy)."""

    def convert(text: str) -> float:
        from ringfit.io.modes import DRUM_DIAMETER_RANGE_M

        lo, hi = DRUM_DIAMETER_RANGE_M
        return number(f"a drum diameter in metres in [{lo:g}, {hi:g}] (omit --drum for a flat road)",
                      lo=lo, hi=hi)(text)

    return convert


def quiet_flag(p: argparse.ArgumentParser) -> None:
    """The one switch that silences progress bars: ``--quiet`` (``--no-progress`` kept as a hidden alias)."""
    p.add_argument("--quiet", action="store_true", help="no progress bar on stderr")
    p.add_argument("--no-progress", dest="quiet", action="store_true", help=argparse.SUPPRESS)


def force_flag(p: argparse.ArgumentParser) -> None:
    """``--force``: replace existing outputs (inputs are never replaced)."""
    p.add_argument("--force", action="store_true", help="replace existing outputs (never an input)")


def sampler_flags(p: argparse.ArgumentParser) -> None:
    """``--sampler {compiled,emcee}`` and ``--chains N`` of the commands that sample a posterior."""
    p.add_argument("--sampler", choices=("compiled", "emcee"), default="compiled",
                   help="'compiled': the stretch move as one compiled program per block of steps (default); "
                        "'emcee': the same move driven by emcee, one step at a time (the reference)")
    p.add_argument("--chains", type=integer("a whole number of chains >= 1", lo=1), default=1,
                   help="independent ensembles sampled side by side by the compiled sampler (default 1)")
