"""``ringfit profile`` and ``ringfit cleat``: continuous drum recordings → profiles, angle–time fields, modes.

    ringfit profile RECORD --out NAME.profile.csv [--points 2048]
    ringfit cleat RECORD --sectors 512 --out FIELD.npz [--animate A.gif] [--ssi MODES.csv [--tyre FITTED.toml]]

RECORD is a continuous ``*.records.npz`` (docs/records-continuous.md) or a rig file — NI TDMS, MATLAB .mat,
CSV — with a channel map where it lacks channel metadata (docs/formats.md §17).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ringfit.cli._args import force_flag, integer, number, quiet_flag


def register(sub) -> None:
    p = sub.add_parser("profile", help="rolling profile (docs/formats.md §3) from a continuous recording",
                       description="Average a continuous recording by sensor angle over revolutions and write "
                                   "a *.profile.csv (+ .json sidecar); the revolution-to-revolution spread goes "
                                   "into extra columns.")
    p.add_argument("record", help="continuous *.records.npz, or a .tdms/.mat/.csv rig file (docs/formats.md §17)")
    p.add_argument("--channels", "--channel-map", dest="channel_map", default=None, metavar="MAP.toml",
                   help="TDMS/.mat/CSV only: channel map naming the acceleration, encoder and trigger (hall) "
                        "channels with their axes and units (docs/formats.md §17.4)")
    p.add_argument("--out", required=True, help="output NAME.profile.csv")
    p.add_argument("--points", type=integer("a whole number of angles in 16..1048576", lo=16, hi=1 << 20),
                   default=2048, help="angle points per revolution (default 2048)")
    p.add_argument("--quiet-after", type=number("a finite number of seconds >= 0", lo=0.0, hi=1e4), default=None,
                   metavar="S", help="with a hall channel: leave out samples less than S seconds after each cleat arrival")
    force_flag(p)
    quiet_flag(p)
    p.set_defaults(run=run_profile)

    c = sub.add_parser("cleat", help="angle–time field of a cleat test, its modes and animation",
                       description="Rebuild the cleat response on the plane of sensor angle × time since the "
                                   "cleat's arrival (hall pulses), the no-cleat reading subtracted at the same angle.")
    c.add_argument("record", help="continuous *.records.npz with encoder and hall, or a .tdms/.mat/.csv rig file "
                                  "(docs/formats.md §17)")
    c.add_argument("--channels", "--channel-map", dest="channel_map", default=None, metavar="MAP.toml",
                   help="TDMS/.mat/CSV only: channel map naming the acceleration, encoder and trigger (hall) "
                        "channels (docs/formats.md §17.4), as in profile, ssi and estimate")
    c.add_argument("--out", required=True, help="output FIELD.npz")
    c.add_argument("--sectors", type=integer("a whole number of sectors in 4..65536", lo=4, hi=1 << 16), default=512,
                   help="sectors around the tyre (default 512)")
    c.add_argument("--time-step", type=number("a time step in seconds > 0", lo=0.0, hi=1e3, lo_open=True),
                   default=None, metavar="S", help="time bin [s] (default 1/fs)")
    c.add_argument("--duration", type=number("a duration in seconds > 0", lo=0.0, hi=1e4, lo_open=True), default=None,
                   metavar="S", help="time after each arrival to rebuild [s] (default: the drum period)")
    c.add_argument("--baseline", default=None, metavar="PROFILE.csv",
                   help="no-cleat profile to subtract (default: from this record's samples long after each hit)")
    c.add_argument("--no-baseline", action="store_true", help="subtract nothing")
    c.add_argument("--animate", default=None, metavar="A.gif", help="write a polar animation (GIF)")
    c.add_argument("--snapshots", default=None, metavar="S.png", help="write a multi-panel figure of instants")
    c.add_argument("--coverage-plot", default=None, metavar="C.png", help="write the coverage figure (fig. 23)")
    c.add_argument("--ssi", default=None, metavar="MODES.csv", help="identify the rolling-tyre modes, write a mode table")
    c.add_argument("--ssi-channels", type=integer("a whole number of channels in 2..4096", lo=2, hi=4096),
                   default=None, metavar="N", help="sectors used as SSI channels (default 128)")
    c.add_argument("--f-max", type=number("a frequency in Hz > 0", lo=0.0, hi=1e6, lo_open=True), default=400.0,
                   help="top of the SSI band [Hz] (default 400)")
    c.add_argument("--skip", type=number("a finite number of seconds >= 0", lo=0.0, hi=1e3), default=None, metavar="S",
                   help="drop τ < S (cleat contact) before SSI (default: time for 30° of rotation)")
    c.add_argument("--tyre", type=Path, default=None,
                   help="tyre TOML (docs/formats.md §1): label the SSI modes with (n, direction) of the rolling, loaded "
                        "tyre's model at the record's speed, load and drum, and flag labels no branch supports")
    force_flag(c)
    quiet_flag(c)
    c.set_defaults(run=run_cleat)


def run_profile(args: argparse.Namespace) -> int:
    from ringfit.io.continuous import read_continuous
    from ringfit.io.files import check_output_paths
    from ringfit.io.profiles import sidecar_path, write_profile
    from ringfit.targets.rolling_profile import rolling_profile

    inputs = [args.record] + ([args.channel_map] if args.channel_map else [])
    check_output_paths([args.out, sidecar_path(args.out)], overwrite=args.force, inputs=inputs)
    with read_continuous(args.record, channels=args.channel_map) as rec:
        arrivals = None
        if args.quiet_after is not None and rec.has_hall:
            from ringfit.targets.cleat import detect_cleat_arrivals

            arrivals = detect_cleat_arrivals(rec, progress=not args.quiet).sample
        prof = rolling_profile(rec, points=args.points, arrivals_samples=arrivals, quiet_after_s=args.quiet_after,
                               progress=not args.quiet)
    write_profile(prof.to_profile(), args.out, overwrite=args.force, inputs=[args.record])
    print(f"{args.out}: {len(prof.angle_deg)} angles, {prof.full_revolutions} revolutions, "
          f"rotation {prof.rotation_hz:.4f} Hz; median spread "
          + ", ".join(f"{a} {np_median(prof.spread[i]):.3g} m/s²" for i, a in enumerate(prof.axes)))
    return 0


def np_median(x) -> float:
    import numpy as np

    return float(np.nanmedian(x))


#: SSI channels of ``cleat --ssi`` when --ssi-channels is not given.
SSI_CHANNELS = 128


def _ssi_channels(args) -> None:
    """``--channels N`` (a whole number) is the old spelling of ``--ssi-channels N``: accepted with a warning;
    ``--channels MAP.toml`` is the channel map, as in every other command."""
    import warnings

    text = args.channel_map
    if text is not None and str(text).strip().isdigit():
        from ringfit.errors import InputError

        n = int(str(text).strip())
        if args.ssi_channels is not None:
            raise InputError(f"--channels {n} and --ssi-channels {args.ssi_channels}: --channels names the channel "
                             "map; give the SSI channel count once, as --ssi-channels")
        if not 2 <= n <= 4096:
            raise InputError(f"--channels {n}: expected a whole number of SSI channels in 2..4096 (now "
                             "--ssi-channels)")
        warnings.warn(f"--channels {n} as the SSI channel count is deprecated: --ssi-channels {n} (--channels "
                      "MAP.toml is the channel map, as in the other commands)", stacklevel=2)
        args.channel_map, args.ssi_channels = None, n
    if args.ssi_channels is None:
        args.ssi_channels = SSI_CHANNELS


def run_cleat(args: argparse.Namespace) -> int:
    _ssi_channels(args)
    from ringfit.io.continuous import read_continuous
    from ringfit.io.files import check_output_paths
    from ringfit.io.modes import sidecar_path
    from ringfit.targets.cleat import angle_time_field, coverage_points

    outputs = [args.out, args.animate, args.snapshots, args.coverage_plot, args.ssi,
               sidecar_path(args.ssi) if args.ssi else None]
    if args.tyre is not None and not args.ssi:
        from ringfit.errors import InputError

        raise InputError("--tyre labels the SSI modes: give --ssi MODES.csv too")
    inputs = [args.record] + ([args.baseline] if args.baseline else []) + ([args.tyre] if args.tyre else []) + (
        [args.channel_map] if args.channel_map else [])
    check_output_paths(outputs, overwrite=args.force, inputs=inputs)
    baseline = "auto"
    if args.no_baseline:
        baseline = None
    elif args.baseline:
        from ringfit.io.profiles import read_profile

        baseline = read_profile(args.baseline)
    with read_continuous(args.record, channels=args.channel_map) as rec:
        field = angle_time_field(rec, sectors=args.sectors, time_step_s=args.time_step, duration_s=args.duration,
                                 baseline=baseline, progress=not args.quiet)
        cov = field.coverage()
        print(f"{len(field.arrivals)} cleat arrivals, {cov['passes']} passes used; sensor advances "
              f"{cov['angle_step_deg']:.2f} deg per pass; {100 * cov['filled_fraction']:.1f} % of "
              f"{cov['bins']} bins filled (median {cov['median_count']:g} samples per bin); "
              f"passes for full coverage: {cov['passes_for_full_coverage'] or 'not reached'}")
        if args.coverage_plot:
            from ringfit.report.cleat_plots import plot_coverage

            dur = field.tau_s[-1]
            pts = {k: coverage_points(rec, field.arrivals, k, dur) for k in (10, 50) if k <= len(field.arrivals)}
            plot_coverage(pts, args.coverage_plot)
    extra = {}
    if args.ssi:
        from ringfit.io.modes import write_mode_table
        from ringfit.targets.rolling_modes import identify_rolling_modes

        modes = identify_rolling_modes(field, channels=args.ssi_channels, f_max=args.f_max, skip_s=args.skip,
                                       progress=not args.quiet)
        table, flags = _label_modes(modes.table, field, args, channels=len(modes.channel_deg))
        write_mode_table(table, args.ssi, overwrite=args.force)
        extra = {"mode_freq_hz": modes.table.freq_hz, "mode_shapes": modes.shapes,
                 "mode_channel_deg": modes.channel_deg}
        print(f"{args.ssi}: {len(table)} modes" + (f", {sum(map(bool, flags))} flagged" if any(flags) else ""))
        for i in range(len(table)):
            model = ""
            if "model_n" in table.extra and table.extra["model_n"][i]:
                model = f"  model: n={table.extra['model_n'][i]} {table.extra['model_direction'][i]}"
            print(f"  {table.freq_hz[i]:8.2f} Hz  n={table.n[i]:<2d} {table.branch[i] or table.tag[i]:<9s} "
                  f"ζ={table.damping_pct[i]:.2f} %{model}" + (f"  FLAG: {flags[i]}" if flags[i] else ""))
    field.save(args.out, overwrite=args.force, extra=extra)
    print(f"{args.out}: field {field.mean.shape[1]} sectors × {field.mean.shape[2]} time bins "
          f"of {1e3 * field.time_step_s:.4g} ms; baseline: {field.baseline}")
    if args.snapshots or args.animate:
        from ringfit.report.cleat_plots import SCALE_WINDOW_S, animate_field, field_scale, plot_polar_snapshots

        window = min(field.tau_s[-1], SCALE_WINDOW_S)
        scale = field_scale(field, "radial", window)  # one scale for snapshots and animation
        if args.snapshots:
            t_end = min(field.tau_s[-1], 0.06)
            plot_polar_snapshots(field, [t_end * f for f in (0.0, 0.05, 0.12, 0.25, 0.5, 1.0)], args.snapshots,
                                 scale=scale)
            print(f"{args.snapshots}: polar snapshots ({scale:.3g} m/s² per unit radius)")
        if args.animate:
            animate_field(field, args.animate, tau_max_s=window, scale=scale)
            print(f"{args.animate}: animation ({scale:.3g} m/s² per unit radius)")
    return 0


def _label_modes(table, field, args, *, channels: int):
    """Model labels and plausibility flags for the identified modes (issue 13 item 6)."""
    from ringfit.gap.campbell import label_identified_modes

    if args.tyre is None:
        return label_identified_modes(table, channels=channels)
    from ringfit.io.tyre import read_tyre

    tyre = read_tyre(args.tyre)
    cond = field.condition
    drum = cond.get("drum_diameter_m")
    return label_identified_modes(table, tyre.ring, tyre.geometry, channels=channels,
                                  load_n=cond.get("load_n"), drum_diameter_m=drum if drum else None)
