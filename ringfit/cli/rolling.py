"""``ringfit roll | fit-rolling`` — simulate a rolling profile; fit the tread stiffness to measured profiles."""

from __future__ import annotations

from pathlib import Path

from ringfit.cli._args import drum_diameter, force_flag, integer, number
from ringfit.units import KMH

#: Largest model grid and written profile accepted (a profile of 2^20 angles is 16 MB of CSV already).
MAX_GRID = 1 << 14
MAX_POINTS = 1 << 20


#: A rolling fit whose model explains less than this share of the profiles' variance is refused (exit 1).
MIN_EXPLAINED = 0.2


def explained_share(measured, model) -> float:
    """1 − Σ(model − measured)² / Σ(measured − its mean)², each profile and channel about its own mean."""
    import numpy as np

    measured, model = np.asarray(measured), np.asarray(model)
    total = np.sum((measured - measured.mean(axis=-1, keepdims=True)) ** 2)
    return float(1.0 - np.sum((model - measured) ** 2) / total) if total > 0 else 0.0


def _grid(text: str) -> int:
    import argparse

    value = integer(f"an even number in 64..{MAX_GRID}", lo=64, hi=MAX_GRID)(text)
    if value % 2:
        raise argparse.ArgumentTypeError(f"expected an even number in 64..{MAX_GRID}; got {text!r}")
    return value


def register(sub) -> None:
    p = sub.add_parser("roll", help="simulate the steady rolling tyre and write the sensor profile",
                       description="Solve the steady rolling ring with tread-spring contact (flat road or drum, "
                                   "load imposed) and write what the co-rotating sensor reads (docs/formats.md §3, baseline "
                                   "sensor: radial/tangential, revolution mean removed). The sidecar carries "
                                   "rotation_hz = Ω/2π with Ω = V/R_e, R_e = R_out − δ/3 unless --rotation-hz is given.")
    p.add_argument("--tyre", required=True, type=Path,
                   help="tyre TOML (docs/formats.md §1) with fitted [ring] values")
    p.add_argument("--speed", required=True, type=number("a speed in km/h in [0, 1000]", lo=0.0, hi=1000.0),
                   help="speed [km/h]")
    p.add_argument("--load", type=number("a load in N in (0, 1e6]", lo=0.0, hi=1e6, lo_open=True), default=4000.0,
                   help="vertical load Fz [N] (default 4000)")
    p.add_argument("--drum", type=drum_diameter(),
                   default=None, metavar="DIAMETER_M", help="drum diameter [m]; omit for a flat road")
    p.add_argument("--rotation-hz", type=number("a rotation rate in Hz in (0, 1000]", lo=0.0, hi=1000.0, lo_open=True),
                   default=None, help="wheel rotation rate [Hz] (overrides V/R_e)")
    p.add_argument("--points", type=integer(f"a whole number of angles in 16..{MAX_POINTS}", lo=16, hi=MAX_POINTS),
                   default=1024, help="angles in the written profile (default 1024)")
    p.add_argument("--grid", type=_grid, default=512, help="model grid M, even (default 512, docs/physics.md §4.5)")
    p.add_argument("--out", required=True, type=Path, help="output SIM.profile.csv (sidecar .json next to it)")
    p.add_argument("--plot", type=Path, default=None, help="optional PNG: deformed ring, pressure, channels")
    force_flag(p)
    p.set_defaults(run=run_roll)

    p = sub.add_parser("fit-rolling", help="fit the tread stiffness to rolling profiles",
                       description="Weighted least-squares fit (optimistix Levenberg–Marquardt, log-parameters) of "
                                   "the tread stiffness — optionally damping or other ring parameters — to one or more "
                                   "profiles at different speeds, with the profile block's likelihood (as identify "
                                   "reads profiles: revolution-harmonic rows, each run's angle offset and gain under "
                                   "one sensor's prior, σ per profile, channel and harmonic from the residual; "
                                   "docs/physics.md §11), keeping the ring's other parameters from the tyre file. "
                                   "Writes the tyre file with the fitted ring values (the runs' offsets and gains are "
                                   "printed only). Exit 1 if it does not converge.")
    p.add_argument("profiles", nargs="+", type=Path, help="*.profile.csv files (each with its .json sidecar)")
    p.add_argument("--tyre", required=True, type=Path, help="tyre TOML from the natural-frequency fit")
    p.add_argument("--out", required=True, type=Path, help="output tyre TOML with the fitted [ring] values")
    p.add_argument("--free", default="k_tread",
                   help="comma-separated ring parameters: k_tread, damping_ratio, ei, kw, kv, rho_a (default "
                        "k_tread); each run's angle offset and gain are always fitted")
    p.add_argument("--grid", type=_grid, default=512, help="model grid M, even (default 512)")
    p.add_argument("--plain-reading", action="store_true",
                   help="read each run through its gain and angle offset only (the source study's reading), not "
                        "also through its sensor's nuisances (tilt gain, IEPE corner, liner offset, tangential gain "
                        "under the profile block's priors, as identify reads profiles; the default); faster, and "
                        "wrong on a sensor that tilts or high-passes")
    p.add_argument("--plot", type=Path, default=None, help="optional PNG: measured vs model per channel and speed")
    force_flag(p)
    p.set_defaults(run=run_fit_rolling)


def run_roll(args) -> int:
    from ringfit.errors import InputError
    from ringfit.io.files import check_output_paths
    from ringfit.io.profiles import sidecar_path

    check_output_paths([args.out, sidecar_path(args.out), args.plot], overwrite=args.force, inputs=[args.tyre])

    import numpy as np

    from ringfit.io.profiles import Profile, band_limited_resample, grid_angles_deg, write_profile
    from ringfit.io.tyre import read_tyre, require_ring
    from ringfit.physics.contact import ContactSolver, contact_length, patch_edges
    from ringfit.physics.profile import simulate_profile

    tyre = require_ring(read_tyre(args.tyre), "the rolling simulation needs the tyre's ring")
    if args.rotation_hz is not None:  # the two stated rates must describe one rolling tyre (ringfit.io.conditions)
        from ringfit.io.conditions import rotation_speed_conflict

        note = rotation_speed_conflict(dict(rotation_hz=args.rotation_hz, speed_kmh=args.speed),
                                       float(tyre.geometry.outer_radius))
        if note:
            raise InputError(note.replace("rotation_hz = ", "--rotation-hz ").replace("speed_kmh = ", "--speed "))
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
    r_e = args.speed * KMH / omega if omega > 0 else float("nan")
    omega_src = "--rotation-hz" if args.rotation_hz is not None else f"V/R_e, R_e = R_out − δ/3 = {r_e:.4f} m"
    print(f"{args.speed:g} km/h, Fz = {args.load:g} N on {'a %.4g m drum' % args.drum if args.drum else 'a flat road'}: "
          f"Ω = {omega:.3f} rad/s ({omega_src})")
    print(f"deflection {1e3 * float(sol.deflection):.2f} mm, patch {lead:+.2f}° … {trail:+.2f}° "
          f"({1e3 * float(contact_length(sol)):.1f} mm), p_max {float(sol.pressure.max()):.4g} N/m, "
          f"Fx {float(sol.fx):+.1f} N (rearward +)")
    if tyre.covariance is not None:
        _print_ring_band(tyre, args, solver, omega)
    print(f"wrote {args.out} and {sidecar_path(args.out).name}")
    if args.plot is not None:
        from ringfit.report.rolling_plots import rolling_solution_figure

        from ringfit.io.files import atomic_write

        fig = rolling_solution_figure(sol, tyre.geometry, grid.channels, speed_kmh=args.speed)
        atomic_write(args.plot, lambda tmp: fig.savefig(tmp, format="png"))
        print(f"wrote {args.plot}")
    return 0


#: Rings drawn from the tyre file's [ring.covariance] to propagate it into the standing state.
RING_DRAWS = 32


def _print_ring_band(tyre, args, solver, omega: float) -> None:
    """The tyre's [ring.covariance] propagated into deflection and patch length at this speed and load: 95 % over
    RING_DRAWS drawn rings (Ω held at the nominal ring's; the written profile is the nominal ring's)."""
    import numpy as np

    from ringfit.physics.contact import contact_length, solve_rolling_jit
    from ringfit.physics.operating import OperatingPoint, road_from_drum_diameter

    road = road_from_drum_diameter(args.drum)
    defl, length = [], []
    for ring in tyre.covariance.draws(tyre.ring, RING_DRAWS):
        sol = solve_rolling_jit(ring, tyre.geometry, OperatingPoint(float(omega), float(args.load), road), solver=solver)
        if bool(sol.ok):
            defl.append(1e3 * float(sol.deflection))
            length.append(1e3 * float(contact_length(sol)))
    if len(defl) < RING_DRAWS // 2:
        print(f"the tyre's [ring.covariance]: only {len(defl)} of {RING_DRAWS} drawn rings solved; no band")
        return
    (d0, d1), (l0, l1) = np.percentile(defl, [2.5, 97.5]), np.percentile(length, [2.5, 97.5])
    print(f"with the tyre's [ring.covariance] ({len(defl)} drawn rings): deflection "
          f"{d0:.2f} … {d1:.2f} mm, patch {l0:.1f} … {l1:.1f} mm (95 %); the profile written is the nominal ring's")


def run_fit_rolling(args) -> int:
    from ringfit.cli import CommandFailed
    from ringfit.io.files import check_output_paths

    free = tuple(x.strip() for x in args.free.split(",") if x.strip())
    check_output_paths([args.out, args.plot], overwrite=args.force, inputs=[args.tyre, *args.profiles])

    from ringfit.fit.profile_block import SENSOR_FIELDS
    from ringfit.fit.rolling import check_rolling_free, fit_rolling, fitted_ring
    import warnings

    from ringfit.io.conditions import check_stated, unique_inputs
    from ringfit.io.profiles import read_profile, sidecar_path
    from ringfit.io.tyre import read_tyre, require_ring, write_tyre
    from ringfit.physics.contact import ContactSolver

    check_rolling_free(free)
    tyre = require_ring(read_tyre(args.tyre), "fit-rolling keeps the ring's other parameters from the tyre file")
    # the same profile given twice counts once; a profile's stated conditions checked (ringfit.io.conditions)
    paths, notes = unique_inputs(args.profiles, sidecar_path, "profile")
    for note in notes:
        warnings.warn(note, stacklevel=2)
    keep = list(paths)  # in the order given, each once
    args.profiles = [p for p in args.profiles if p in keep and not keep.remove(p)]
    profiles = []
    for path in args.profiles:
        p = read_profile(path)
        p, notes = check_stated(p, tyre.geometry, source=sidecar_path(path), other_pressure="refuse")
        for note in notes:
            warnings.warn(note, stacklevel=2)
        profiles.append(p)
    result = fit_rolling(profiles, tyre.geometry, tyre.ring, free=free, solver=ContactSolver(n_grid=args.grid),
                         sensor_nuisances=not args.plain_reading)
    # the runs' sensor nuisances are told weakly by clean or short data and held by their priors: their flags (at a
    # bound, poorly determined) are not about the fitted ring; each run's sensor line below gives their values
    sensor_fields = tuple(f"{f}_" for f in SENSOR_FIELDS)
    print(result.summary(flags=False))
    for flag in result.flags:
        if not flag.startswith(sensor_fields):
            print(f"WARNING: {flag}")
    for src, speed, (om, how) in zip(args.profiles, result.extra["speed_kmh"],
                                     zip(result.extra["omega"], result.extra["omega_source"])):
        print(f"  {src.name}: {speed:g} km/h, Ω = {om:.3f} rad/s from {how}")
    ex = result.extra
    k = ex["harmonics"]
    print(f"residual RMS {ex['rms_ms2']:.3g} m/s² over {result.n_data} harmonic rows (k = {k[0]} … {k[-1]}, "
          f"{ex['passes']} noise passes); {ex['evaluations']} model-evaluation equivalents")
    for src, g, gs, a, asd in zip(args.profiles, ex["gain"], ex["gain_sd"], ex["angle_offset_deg"],
                                  ex["angle_offset_sd_deg"]):
        print(f"  {src.name}: angle offset {a:+.3f}° ± {asd:.3f}°, gain {g:.4f} ± {gs:.4f} (not written to the "
              f"tyre file)")
    if "sensor" in ex:  # each run's sensor nuisances (the default; not with --plain-reading)
        for i, src in enumerate(args.profiles):
            v, sd = ex["sensor"], ex["sensor_sd"]
            print(f"  {src.name}: tilt gain {v['tilt_gain'][i]:.3f} ± {sd['tilt_gain'][i]:.3f}, IEPE corner "
                  f"{v['corner_hz'][i]:.3g} Hz ± {sd['corner_hz'][i]:.2g}, liner offset "
                  f"{1e3 * v['liner_offset_m'][i]:+.2f} ± {1e3 * sd['liner_offset_m'][i]:.2f} mm, tangential gain "
                  f"{v['gain_tangential'][i]:.4f} ± {sd['gain_tangential'][i]:.4f}")
    if args.plot is not None:
        from ringfit.report.rolling_plots import profiles_figure

        from ringfit.io.files import atomic_write

        fig = profiles_figure(result.extra["angle_deg"], result.extra["model"], result.extra["speed_kmh"],
                              result.extra["measured"], title="rolling profiles: measured vs fitted model")
        atomic_write(args.plot, lambda tmp: fig.savefig(tmp, format="png"))
        print(f"wrote {args.plot}")
    if not result.converged:
        raise CommandFailed(f"fit did not converge ({result.status}): {result.message}; nothing written")
    explained = explained_share(result.extra["measured"], result.extra["model"])
    print(f"the model explains {100 * explained:.1f} % of the profiles' variance")
    if explained < MIN_EXPLAINED:
        raise CommandFailed(f"the fitted model explains only {100 * explained:.1f} % of the profiles' variance "
                            f"(< {100 * MIN_EXPLAINED:g} %): pure noise, or not a rolling profile; nothing written")
    ring_names = list(free)
    write_tyre(tyre.with_ring(fitted_ring(result), ring_names), args.out, overwrite=args.force)
    print(f"wrote {args.out}")
    return 0
