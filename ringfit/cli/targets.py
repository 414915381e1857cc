"""``ringfit ssi | frf`` — mode tables from impact records (DATA.md §4 → §2)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _orders(text: str) -> range:
    try:
        parts = [int(x) for x in text.split(":")]
        if len(parts) == 2:
            parts.append(2)
        start, stop, step = parts
        if not (1 <= start <= stop and step >= 1):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}; expected START:STOP[:STEP], e.g. 2:160:2") from None
    return range(start, stop + 1, step)


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1; got {text!r}")
    return value


def _band(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(x) for x in text.split(":"))
        if not 0 <= lo < hi:
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}; expected LOW:HIGH in Hz, e.g. 20:400") from None
    return lo, hi


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("records", type=Path, help="records *.records.npz or UFF type 58 (.uff/.unv), DATA.md §4")
    p.add_argument("--out", required=True, type=Path, help="output mode table *.modes.csv (+ .modes.json sidecar)")
    p.add_argument("--band", type=_band, default=(20.0, 400.0), metavar="LOW:HIGH",
                   help="frequency range of interest in Hz; its top sets the decimation (default 20:400)")
    p.add_argument("--delay", type=float, default=0.0, help="delay of the acceleration behind the force channel [s]")
    p.add_argument("--threshold", type=float, default=0.1, help="impact = first |force| >= THRESHOLD x peak (default 0.1)")
    p.add_argument("--plot", type=Path, default=None, help="also write a PNG figure")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")


def register(sub) -> None:
    p = sub.add_parser("ssi", help="covariance-driven SSI of impact records -> mode table",
                       description="Align the records on the hammer impact (or by group velocity without force), "
                                   "decimate, drop the first 0.0127 s, run SSI-cov over the model orders, label the "
                                   "stabilization diagram (frequency 1 %%, damping 5 %%, pair-aware shape check), "
                                   "cluster stable poles into modes (one per double pole), assign n from the shapes "
                                   "and write the mode table.")
    _common(p)
    p.add_argument("--orders", type=_orders, default=range(2, 161, 2), metavar="START:STOP[:STEP]",
                   help="model orders (state dimensions), default 2:160:2")
    p.add_argument("--block-rows", type=int, default=30, metavar="N", help="block rows p of the Hankel matrix (default 30)")
    p.add_argument("--skip", type=float, default=0.0127, help="seconds dropped after the impact (default 0.0127)")
    p.add_argument("--radius", type=float, default=None, help="tyre radius [m], for records without force")
    p.add_argument("--workers", type=_positive_int, default=None, metavar="N",
                   help="threads for the SVD and the order sweep (default: the CPUs this process may use, at most 8)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=run_ssi)

    p = sub.add_parser("frf", help="H1 / coherence peak picking of impact records -> mode table",
                       description="H1 and coherence over repeated impacts per sensor angle (poor impacts rejected), "
                                   "peak picking per circumferential harmonic, half-power damping, quadrature shapes, "
                                   "n from the shapes; writes the mode table.")
    _common(p)
    p.add_argument("--indicator", choices=("harmonic", "sum"), default="harmonic",
                   help="peak-picking curve: per circumferential harmonic (default) or the summed FRF power (source)")
    p.add_argument("--min-coherence", type=float, default=0.9, help="impact rejection target (default 0.9)")
    p.set_defaults(run=run_frf)


def _check_outputs(args) -> None:
    from ringfit.io.files import check_output_path
    from ringfit.io.modes import sidecar_path

    check_output_path(args.out, overwrite=args.force, inputs=[args.records])
    check_output_path(sidecar_path(args.out), overwrite=args.force, inputs=[args.records])
    if args.plot is not None:
        check_output_path(args.plot, overwrite=args.force, inputs=[args.records])


def _finish(args, result, plot) -> int:
    from ringfit.io.modes import write_mode_table

    write_mode_table(result.table, args.out, overwrite=args.force)
    if args.plot is not None:
        from ringfit.io.files import atomic_write

        fig = plot(result)
        atomic_write(args.plot, lambda tmp: fig.savefig(tmp, format="png", dpi=120))
    t = result.table
    print(f"{len(t)} modes -> {args.out}")
    for i in range(len(t)):
        n = "-" if t.n[i] < 0 else str(t.n[i])
        print(f"  n={n:>2}  {t.kind[i]:<10}  {t.freq_hz[i]:8.2f} Hz ± {t.freq_std_hz[i]:.2f}  ζ = {t.damping_pct[i]:.2f} %")
    return 0


def run_ssi(args) -> int:
    from ringfit.io.records import read_records
    from ringfit.targets.identify import ssi_modes

    _check_outputs(args)
    records = read_records(args.records)
    result = ssi_modes(records, orders=args.orders, block_rows=args.block_rows, f_range=args.band,
                       skip_s=args.skip, threshold=args.threshold, delay_s=args.delay, radius_m=args.radius,
                       progress=not args.no_progress and sys.stderr is not None, workers=args.workers)

    def plot(res):
        from ringfit.report.targets_plots import plot_stabilization

        return plot_stabilization(res, f_range=args.band)

    return _finish(args, result, plot)


def run_frf(args) -> int:
    from ringfit.io.records import read_records
    from ringfit.targets.frf import frf_modes

    _check_outputs(args)
    records = read_records(args.records)
    result = frf_modes(records, f_range=args.band, delay_s=args.delay, threshold=args.threshold,
                       min_coherence=args.min_coherence, indicator=args.indicator)

    def plot(res):
        from ringfit.report.targets_plots import plot_frf

        return plot_frf(res, f_range=args.band)

    return _finish(args, result, plot)
