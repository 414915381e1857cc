"""``ringfit roll | fit-rolling`` — simulate a rolling profile; fit the tread stiffness to measured profiles."""

from __future__ import annotations

from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("roll", help="simulate the steady rolling tyre and write the sensor profile",
                       description="Solve the steady rolling ring with tread-spring contact (flat road or drum, "
                                   "load imposed) and write what the co-rotating sensor reads (DATA.md §3, baseline "
                                   "sensor: radial/tangential, revolution mean removed). The sidecar carries "
                                   "rotation_hz = Ω/2π with Ω = V/R_e, R_e = R_out − δ/3 unless --rotation-hz is given.")
    p.add_argument("--tyre", required=True, type=Path, help="tyre TOML (DATA.md §1) with fitted [ring] values")
    p.add_argument("--speed", required=True, type=float, help="speed [km/h]")
    p.add_argument("--load", type=float, default=4000.0, help="vertical load Fz [N] (default 4000)")
    p.add_argument("--drum", type=float, default=None, metavar="DIAMETER_M", help="drum diameter [m]; omit for a flat road")
    p.add_argument("--rotation-hz", type=float, default=None, help="wheel rotation rate [Hz] (overrides V/R_e)")
    p.add_argument("--points", type=int, default=1024, help="angles in the written profile (default 1024)")
    p.add_argument("--grid", type=int, default=512, help="model grid M (default 512, PHYSICS.md §4.5)")
    p.add_argument("--out", required=True, type=Path, help="output SIM.profile.csv (sidecar .json next to it)")
    p.add_argument("--plot", type=Path, default=None, help="optional PNG: deformed ring, pressure, channels")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.set_defaults(run=run_roll)

    p = sub.add_parser("fit-rolling", help="fit the tread stiffness to rolling profiles",
                       description="Least-squares fit (optimistix Levenberg–Marquardt, log-parameters) of the "
                                   "tread stiffness — optionally damping and the angle offset — to one or more "
                                   "profiles at different speeds, keeping the ring's other parameters from the tyre "
                                   "file. Writes the tyre file with the fitted values. Exit 1 if it does not converge.")
    p.add_argument("profiles", nargs="+", type=Path, help="*.profile.csv files (each with its .json sidecar)")
    p.add_argument("--tyre", required=True, type=Path, help="tyre TOML from the natural-frequency fit")
    p.add_argument("--out", required=True, type=Path, help="output tyre TOML with the fitted [ring] values")
    p.add_argument("--free", default="k_tread",
                   help="comma-separated parameters: k_tread, damping_ratio, angle_offset, ... (default k_tread)")
    p.add_argument("--grid", type=int, default=512, help="model grid M (default 512)")
    p.add_argument("--plot", type=Path, default=None, help="optional PNG: measured vs model per channel and speed")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.set_defaults(run=run_fit_rolling)


def _check_grid(grid: int):
    from ringfit.errors import InputError

    if grid < 64 or grid % 2:
        raise InputError(f"--grid {grid}: expected an even number >= 64")


def run_roll(args) -> int:
    from ringfit._cache import enable_compilation_cache

    enable_compilation_cache()  # a second run skips XLA compilation
    from ringfit.errors import InputError
    from ringfit.io.files import check_output_path
    from ringfit.io.profiles import sidecar_path

    _check_grid(args.grid)
    if not args.speed >= 0:
        raise InputError(f"--speed {args.speed}: expected a speed >= 0 km/h")
    if not args.load > 0:
        raise InputError(f"--load {args.load}: expected a positive load in N")
    if args.drum is not None and not args.drum > 0:
        raise InputError(f"--drum {args.drum}: expected a positive diameter in metres")
    if args.points < 16:
        raise InputError(f"--points {args.points}: expected at least 16")
    check_output_path(args.out, overwrite=args.force, inputs=[args.tyre])
    check_output_path(sidecar_path(args.out), overwrite=args.force, inputs=[args.tyre])
    if args.plot is not None:
        check_output_path(args.plot, overwrite=args.force, inputs=[args.tyre, args.out])

    import numpy as np

    from ringfit.io.profiles import Profile, band_limited_resample, grid_angles_deg, write_profile
    from ringfit.io.tyre import read_tyre
    from ringfit.physics.contact import ContactSolver, contact_length, patch_edges
    from ringfit.physics.profile import simulate_profile

    tyre = read_tyre(args.tyre)
    solver = ContactSolver(n_grid=args.grid)
    grid, sol = simulate_profile(tyre.ring, tyre.geometry, speed_kmh=args.speed, load_n=args.load,
                                 rotation_hz=args.rotation_hz, drum_diameter_m=args.drum, solver=solver,
                                 with_solution=True)
    if not bool(sol.ok):
        raise InputError("the contact solve did not converge inside its ±35° window (load too large for this tyre?)")
    omega = 2 * np.pi * grid.condition["rotation_hz"]
    values = band_limited_resample(grid.channels, args.points)
    condition = dict(grid.condition, sample_rate_hz=grid.condition["rotation_hz"] * args.points)
    write_profile(Profile(grid_angles_deg(args.points), values[0], values[1], condition=condition), args.out,
                  overwrite=args.force, inputs=[args.tyre])
    lead, trail = (np.degrees(float(x)) for x in patch_edges(sol))
    r_e = args.speed / 3.6 / omega if omega > 0 else float("nan")
    omega_src = "--rotation-hz" if args.rotation_hz is not None else f"V/R_e, R_e = R_out − δ/3 = {r_e:.4f} m"
    print(f"{args.speed:g} km/h, Fz = {args.load:g} N on {'a %.4g m drum' % args.drum if args.drum else 'a flat road'}: "
          f"Ω = {omega:.3f} rad/s ({omega_src})")
    print(f"deflection {1e3 * float(sol.deflection):.2f} mm, patch {lead:+.2f}° … {trail:+.2f}° "
          f"({1e3 * float(contact_length(sol)):.1f} mm), p_max {float(sol.pressure.max()):.4g} N/m, "
          f"Fx {float(sol.fx):+.1f} N (rearward +)")
    print(f"wrote {args.out} and {sidecar_path(args.out).name}")
    if args.plot is not None:
        from ringfit.report.rolling_plots import rolling_solution_figure

        rolling_solution_figure(sol, tyre.geometry, grid.channels, speed_kmh=args.speed).savefig(args.plot)
        print(f"wrote {args.plot}")
    return 0


def run_fit_rolling(args) -> int:
    from ringfit._cache import enable_compilation_cache

    enable_compilation_cache()  # a second run skips XLA compilation
    from ringfit.cli import CommandFailed
    from ringfit.errors import InputError
    from ringfit.io.files import check_output_path

    _check_grid(args.grid)
    free = tuple(x.strip() for x in args.free.split(",") if x.strip())
    inputs = [args.tyre, *args.profiles]
    check_output_path(args.out, overwrite=args.force, inputs=inputs)
    if args.plot is not None:
        check_output_path(args.plot, overwrite=args.force, inputs=inputs + [args.out])

    import math

    from ringfit.fit.rolling import ANGLE_OFFSET, check_rolling_free, fit_rolling, fitted_ring
    from ringfit.io.profiles import read_profile
    from ringfit.io.tyre import read_tyre, write_tyre
    from ringfit.physics.contact import ContactSolver

    check_rolling_free(free)
    tyre = read_tyre(args.tyre)
    profiles = [read_profile(p) for p in args.profiles]
    for p in profiles:
        pb = float(p.condition["pressure_bar"])
        if abs(pb - float(tyre.geometry.pressure) / 1e5) > 0.05 * pb:
            raise InputError(f"pressure_bar = {pb:g} differs from the tyre file's "
                             f"{float(tyre.geometry.pressure) / 1e5:g} bar", source=p.source)
    result = fit_rolling(profiles, tyre.geometry, tyre.ring, free=free, solver=ContactSolver(n_grid=args.grid))
    print(result.summary())
    for src, speed, (om, how) in zip(args.profiles, result.extra["speed_kmh"],
                                     zip(result.extra["omega"], result.extra["omega_source"])):
        print(f"  {src.name}: {speed:g} km/h, Ω = {om:.3f} rad/s from {how}")
    print(f"residual RMS {result.extra['rms_ms2']:.3g} m/s² over {result.n_data} samples; "
          f"{result.extra['evaluations']} model-evaluation equivalents")
    if ANGLE_OFFSET in result.names:
        print(f"angle offset {math.degrees(result.values[ANGLE_OFFSET]):+.3f}° "
              f"± {math.degrees(result.stderr[ANGLE_OFFSET]):.3f}° (not written to the tyre file)")
    if args.plot is not None:
        from ringfit.report.rolling_plots import profiles_figure

        profiles_figure(result.extra["angle_deg"], result.extra["model"], result.extra["speed_kmh"],
                        result.extra["measured"], title="rolling profiles: measured vs fitted model").savefig(args.plot)
        print(f"wrote {args.plot}")
    if not result.converged:
        raise CommandFailed(f"fit did not converge ({result.status}): {result.message}; nothing written")
    ring_names = [k for k in result.names if k != ANGLE_OFFSET]
    write_tyre(tyre.with_ring(fitted_ring(result), ring_names), args.out, overwrite=args.force)
    print(f"wrote {args.out}")
    return 0
