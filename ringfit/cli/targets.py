"""``ringfit ssi | frf`` — mode tables from impact records or measured FRFs (docs/formats.md §4 → §2)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ringfit.cli._args import force_flag, integer, number, quiet_flag


def _axes() -> tuple[str, ...]:
    from ringfit.io.record_types import AXES  # noqa: PLC0415 (the CLI's import stays light)

    return AXES


def _orders(text: str) -> range:
    try:
        parts = [int(x) for x in text.split(":")]
        if len(parts) == 2:
            parts.append(2)
        start, stop, step = parts
        if not (1 <= start <= stop <= 2000 and step >= 1):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}; expected START:STOP[:STEP] with 1 <= START <= STOP <= 2000, "
                                         "e.g. 2:160:2") from None
    return range(start, stop + 1, step)


def _band(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(x) for x in text.split(":"))
        if not (0 <= lo < hi < float("inf")):
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}; expected LOW:HIGH in Hz with 0 <= LOW < HIGH, e.g. 20:400") from None
    return lo, hi


def _node_map(kind: str):
    """``NODE=VALUE,...`` -> dict; VALUE a number (angles) or an axis name (axes)."""

    def convert(text: str) -> dict:
        import math

        out = {}
        try:
            for part in text.split(","):
                if not part.strip():
                    continue
                key, value = (x.strip() for x in part.split("="))
                key = int(key)
                if kind == "angles":
                    value = float(value)
                    if not math.isfinite(value):
                        raise ValueError
                elif value not in _axes():
                    raise ValueError
                out[key] = value
        except ValueError:
            example = "1=0,2=15,3=30 (node=degrees)" if kind == "angles" else "0=radial or 1=tangential,3=radial"
            raise argparse.ArgumentTypeError(f"{text!r}; expected e.g. {example}") from None
        if not out:
            raise argparse.ArgumentTypeError(f"{text!r} is empty")
        return out

    return convert


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("records", type=Path,
                   help="records *.records.npz or UFF58 (.uff/.unv) time records (docs/formats.md §4), or a rig file: "
                        "NI TDMS (.tdms), MATLAB .mat (v5, v7.3) or CSV with a header (§17)")
    p.add_argument("--out", required=True, type=Path, help="output mode table *.modes.csv (+ .modes.json sidecar)")
    p.add_argument("--band", type=_band, default=(20.0, 400.0), metavar="LOW:HIGH",
                   help="frequency range of interest in Hz, below the records' Nyquist frequency; its top sets the "
                        "decimation (default 20:400)")
    p.add_argument("--delay", type=number("a finite delay in seconds, |delay| <= 1", lo=-1.0, hi=1.0), default=0.0,
                   help="delay of the acceleration behind the force channel [s] (default 0)")
    p.add_argument("--threshold", type=number("a fraction of the peak force in (0, 1]", lo=0.0, hi=1.0, lo_open=True),
                   default=0.1, help="impact = first |force| >= THRESHOLD x peak (default 0.1)")
    p.add_argument("--angles", type=_node_map("angles"), default=None, metavar="NODE=DEG,...",
                   help="UFF only: sensor angle [deg] of each response node, for files without node coordinates")
    p.add_argument("--axes", type=_node_map("axes"), default=None, metavar="DIR=AXIS,...",
                   help="UFF only: axis of each response direction code, e.g. 0=radial for scalar channels "
                        "(default 1=tangential,2=lateral,3=radial)")
    p.add_argument("--channels", "--channel-map", dest="channel_map", type=Path, default=None, metavar="MAP.toml",
                   help="TDMS/.mat/CSV only: channel map giving each channel's angle, axis, unit, sensitivity and "
                        "the force channels, where the file does not (docs/formats.md §17.4)")
    p.add_argument("--plot", type=Path, default=None, help="also write a PNG figure")
    p.add_argument("--cavity", type=number("a cavity frequency in Hz, 0 < f <= 1e4", lo=0.0, hi=1e4, lo_open=True),
                   default=None, metavar="HZ",
                   help="the tyre's air-cavity frequency [Hz]: a row that is not ring-like is `acoustic` only "
                        "within 8 %% of it and with an n = 1 pattern, else `unclassified` (default: eq. 22 of "
                        "docs/physics.md with the source study's cavity length, 218.75 Hz)")
    force_flag(p)


def register(sub) -> None:
    p = sub.add_parser("ssi", help="covariance-driven SSI of impact records -> mode table",
                       description="Remove channel offsets, align the records on the hammer impact (or by group "
                                   "velocity without force), decimate, drop the first 0.0127 s, leave out dead or "
                                   "junk channels (said so), run SSI-cov over the model orders, label the "
                                   "stabilization diagram (frequency 1 %%, damping 5 %%, pair-aware shape check), "
                                   "cluster stable poles into modes (one per double pole), assign n from the shapes, "
                                   "estimate each mode's σ by a jackknife over groups of sensor angles and write "
                                   "the mode table.")
    _common(p)
    p.add_argument("--orders", type=_orders, default=range(2, 161, 2), metavar="START:STOP[:STEP]",
                   help="model orders (state dimensions), default 2:160:2")
    p.add_argument("--block-rows", type=integer("a whole number of block rows >= 2", lo=2, hi=10_000), default=30,
                   metavar="N", help="block rows p of the Hankel matrix (default 30)")
    p.add_argument("--skip", type=number("a finite number of seconds >= 0", lo=0.0, hi=1e3), default=0.0127,
                   help="seconds dropped after the impact (default 0.0127)")
    p.add_argument("--radius", type=number("a tyre radius in metres, 0 < R <= 5", lo=0.0, hi=5.0, lo_open=True),
                   default=None, help="tyre radius [m], for records without force")
    p.add_argument("--workers", type=integer("a whole number >= 1", lo=1, hi=4096), default=None, metavar="N",
                   help="threads for the SVD, the order sweep and the jackknife (default: the CPUs this process may "
                        "use, at most 8)")
    p.add_argument("--no-jackknife", dest="jackknife", action="store_false",
                   help="freq_std_hz and damping_std_pct from the spread over the model orders only, which "
                        "understates them (default: a jackknife over groups of sensor angles plus half that spread, "
                        "docs/formats.md §2)")
    quiet_flag(p)
    p.set_defaults(run=run_ssi)

    p = sub.add_parser("frf", help="H1 / coherence peak picking of impact records or measured FRFs -> mode table",
                       description="H1 and coherence over repeated impacts per sensor angle (channel offsets removed, "
                                   "records with dead or junk channels and poor impacts rejected), or FRFs measured "
                                   "by other software (UFF58 function type 4); peak picking per circumferential "
                                   "harmonic, half-power damping, quadrature shapes, n from the shapes; writes the "
                                   "mode table.")
    _common(p)
    p.add_argument("--indicator", choices=("harmonic", "sum"), default="harmonic",
                   help="peak-picking curve: per circumferential harmonic (default) or the summed FRF power (source)")
    p.add_argument("--min-coherence", type=number("a coherence in [0, 1]", lo=0.0, hi=1.0), default=0.9,
                   help="impact rejection target (default 0.9)")
    quiet_flag(p)  # frf draws no bar, but every command takes --quiet (a script passes it to all)
    p.set_defaults(run=run_frf)


def _check_outputs(args) -> None:
    from ringfit.io.files import check_output_paths
    from ringfit.io.modes import sidecar_path

    inputs = [args.records] + ([args.channel_map] if args.channel_map else [])
    check_output_paths([args.out, sidecar_path(args.out), args.plot], overwrite=args.force, inputs=inputs)


def _read(args, *, frf_ok: bool):
    from ringfit.io.records import read_measurement, read_records

    read = read_measurement if frf_ok else read_records
    return read(args.records, angles=args.angles, axes=args.axes, channels=args.channel_map)


def _finish(args, result, plot) -> int:
    from ringfit.io.modes import write_mode_table

    write_mode_table(result.table, args.out, overwrite=args.force)
    if args.plot is not None:
        from ringfit.io.files import atomic_write

        fig = plot(result)
        atomic_write(args.plot, lambda tmp: fig.savefig(tmp, format="png", dpi=120))
    import numpy as np

    from ringfit.report.numbers import fmt_pm, fmt_value

    t = result.table
    print(f"{len(t)} modes -> {args.out}" + ("" if t.condition.get("credible", True) else "  (NOT CREDIBLE: noise)"))
    for i in range(len(t)):
        n = "-" if t.n[i] < 0 else str(t.n[i])
        sd = float(t.freq_std_hz[i])  # the frequency to the digits its σ warrants (report/numbers.py)
        f = fmt_pm(t.freq_hz[i], sd, "Hz") if np.isfinite(sd) and sd > 0 else f"{fmt_value(t.freq_hz[i])} Hz"
        print(f"  n={n:>2}  {t.kind[i]:<10}  {f:>20}  ζ = {t.damping_pct[i]:.2f} %")
        if t.kind[i] == "unclassified" and str(t.extra.get("reason", [""] * len(t))[i]):
            print(f"         ({t.extra['reason'][i]})")
    for note in t.condition.get("limits", []):
        print(f"note: {note}")
    return 0


def _check_records(args, records) -> None:
    """What the options ask of the records: a band below their Nyquist, a skip shorter than them."""
    from ringfit.errors import InputError
    from ringfit.io.records import MeasuredFRF
    from ringfit.targets.identify import MIN_DECAY_SAMPLES

    if isinstance(records, MeasuredFRF):
        f = records.freq_hz
        if args.band[0] < f[0] or args.band[1] > f[-1]:
            raise InputError(f"--band {args.band[0]:g}:{args.band[1]:g} reaches beyond the measured lines "
                             f"{f[0]:g}–{f[-1]:g} Hz of {records.source}")
        return
    if records.n_samples < MIN_DECAY_SAMPLES:
        raise InputError(f"records of {records.n_samples} samples; expected at least {MIN_DECAY_SAMPLES}",
                         source=records.source)
    if args.band[1] >= records.fs_hz / 2:
        raise InputError(f"--band {args.band[0]:g}:{args.band[1]:g}: the top is not below the records' Nyquist "
                         f"frequency {records.fs_hz / 2:g} Hz ({records.source})")
    length = records.n_samples / records.fs_hz
    if getattr(args, "skip", 0.0) >= length:
        raise InputError(f"--skip {args.skip:g} s is not shorter than the records ({length:.4g} s)")


def _cavity_hz(args) -> float:
    """``--cavity``, else eq. 22 with the source study's cavity length (docs/physics.md §3.6)."""
    if args.cavity is not None:
        return float(args.cavity)
    from ringfit.physics.natural import cavity_frequency

    return float(cavity_frequency(1))


def run_ssi(args) -> int:
    import sys

    from ringfit.targets.identify import ssi_modes

    _check_outputs(args)
    records = _read(args, frf_ok=False)
    _check_records(args, records)
    result = ssi_modes(records, orders=args.orders, block_rows=args.block_rows, f_range=args.band,
                       skip_s=args.skip, threshold=args.threshold, delay_s=args.delay, radius_m=args.radius,
                       jackknife=args.jackknife, progress=not args.quiet and sys.stderr is not None,
                       workers=args.workers, cavity_hz=_cavity_hz(args))

    def plot(res):
        from ringfit.report.targets_plots import plot_ssi_summary

        return plot_ssi_summary(res, f_range=args.band)

    return _finish(args, result, plot)


def run_frf(args) -> int:
    from ringfit.targets.frf import frf_modes

    _check_outputs(args)
    records = _read(args, frf_ok=True)
    _check_records(args, records)
    result = frf_modes(records, f_range=args.band, delay_s=args.delay, threshold=args.threshold,
                       min_coherence=args.min_coherence, indicator=args.indicator, cavity_hz=_cavity_hz(args))

    def plot(res):
        from ringfit.report.targets_plots import plot_frf

        return plot_frf(res, f_range=args.band)

    return _finish(args, result, plot)
