"""``ringfit fit | sample | report | demo`` — the free-tyre natural-frequency workflow."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ringfit.cli._args import force_flag, integer, number, quiet_flag, sampler_flags

DEFAULT_FREE = "rho_a,ei,kw,kv"


def register(sub) -> None:
    p = sub.add_parser("fit", help="least-squares fit of ring parameters to a mode table",
                       description="Fit EI, k_w, k_v, ρA (eq. 18) to measured natural frequencies and write the "
                                   "tyre file with the fitted [ring] values. Prints standard errors, correlations "
                                   "and identifiability findings. Exit 1 if the fit does not converge.")
    _common(p)
    p.add_argument("--out", required=True, type=Path, help="output tyre TOML with fitted [ring] values")
    p.add_argument("--max-iterations", type=integer("a whole number of solver iterations >= 1", lo=1), default=256,
                   metavar="N", help="Levenberg–Marquardt iteration limit (default 256)")
    p.add_argument("--max-steps", dest="fit_max_steps", default=None, help=argparse.SUPPRESS)
    p.set_defaults(run=run_fit)

    p = sub.add_parser("sample", help="posterior of the ring parameters (compiled ensemble sampler)",
                       description="Sample the posterior with the affine-invariant stretch move (compiled; "
                                   "`--sampler emcee` for the emcee reference) until the chain exceeds 50 "
                                   "autocorrelation times (or --max-steps), and save the draws to HDF5 for "
                                   "`ringfit report`.")
    _common(p)
    p.add_argument("--out", required=True, type=Path, help="output posterior file (HDF5, e.g. POSTERIOR.h5)")
    p.add_argument("--walkers", type=integer("a whole number of walkers >= 2", lo=2), default=32,
                   help="walkers per ensemble; at least twice the number of free parameters (default 32)")
    sampler_flags(p)
    p.add_argument("--min-steps", type=integer("a whole number of steps >= 100", lo=100), default=2000,
                   help="chain steps run before the first convergence check (default 2000)")
    p.add_argument("--max-steps", type=integer("a whole number of steps >= 100", lo=100), default=20000,
                   help="chain steps at most, converged or not (default 20000)")
    p.add_argument("--seed", type=integer("a whole number >= 0", lo=0), default=0, help="random seed (default 0)")
    p.add_argument("--netcdf", type=Path, default=None, metavar="FILE.nc",
                   help="also write the draws as an arviz InferenceData NetCDF file (arviz.from_netcdf reads it)")
    quiet_flag(p)
    p.set_defaults(run=run_sample)

    p = sub.add_parser("report", help="self-contained HTML uncertainty report from a saved posterior",
                       description="Build the HTML report (data vs fit with predictive intervals, parameters, "
                                   "corner plot, identifiability, sampler diagnostics) from a posterior file.")
    p.add_argument("posterior", type=Path, help="posterior file written by `ringfit sample`")
    p.add_argument("--out", required=True, type=Path, help="output .html")
    force_flag(p)
    p.set_defaults(run=run_report)

    p = sub.add_parser("demo", help="fit + posterior + report on the bundled source-study data",
                       description="Runs the whole free-tyre workflow on the source study's SSI mode table "
                                   "(bundled): least squares, the source's own procedure, emcee posterior and the "
                                   "HTML report, and prints the Table 10 comparison.")
    p.add_argument("--out", type=Path, default=Path("ringfit-demo"), help="output folder (default ./ringfit-demo)")
    p.add_argument("--force", action="store_true", help="replace the outputs of an earlier demo in that folder")
    p.add_argument("--seed", type=integer("a whole number >= 0", lo=0), default=0, help="random seed (default 0)")
    quiet_flag(p)
    p.set_defaults(run=run_demo)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("modes", type=Path, help="mode table *.modes.csv (docs/formats.md §2)")
    p.add_argument("--tyre", required=True, type=Path, help="tyre TOML (docs/formats.md §1); [ring] gives starting values")
    p.add_argument("--free", default=DEFAULT_FREE,
                   help=f"comma-separated parameters to fit (default {DEFAULT_FREE}); others stay at the tyre file's values")
    p.add_argument("--prior", default="physical", choices=("physical", "none"),
                   help="'physical': belt-plate log-normal prior on EI (see docs); 'none': data only (default physical)")
    p.add_argument("--modes-used", default=None, metavar="N-LIST",
                   help="which n take part, e.g. '1-6' or '1,3,7' (default: every structural mode with n)")
    p.add_argument("--default-std", type=number("a fraction between 0 and 1 (e.g. 0.01)", lo=0, hi=1, lo_open=True,
                                                hi_open=True), default=None, metavar="REL",
                   help="stated σ/f where the table has no freq_std_hz, only scaled up by the residual as a stated "
                        "freq_std_hz (default: 0.01 as the start of the σ scale estimated from the residual)")
    force_flag(p)


def parse_n_list(text: str | None):
    """'1-6' -> [1..6]; '1,3,7' -> [1,3,7]; None -> None."""
    from ringfit.errors import InputError

    if text is None:
        return None
    out = []
    try:
        for part in text.split(","):
            part = part.strip()
            if "-" in part:
                a, b = part.split("-")
                out.extend(range(int(a), int(b) + 1))
            elif part:
                out.append(int(part))
    except ValueError:
        raise InputError(f"--modes-used {text!r}: expected e.g. '1-6' or '1,3,7'") from None
    return out


def _inputs(args):
    from ringfit.fit.least_squares import check_free
    from ringfit.io.modes import read_mode_table
    from ringfit.io.tyre import read_tyre

    free = check_free([s.strip() for s in args.free.split(",") if s.strip()])
    rel = args.default_std  # None: 1 % as the start of the estimated scale (docs/physics.md §11)
    table, tyre, modes = read_mode_table(args.modes), read_tyre(args.tyre), parse_n_list(args.modes_used)
    check_well_posed(table, free, args.prior, modes, rel)
    return table, tyre, free, modes, rel


def check_well_posed(table, free, prior, modes, rel) -> None:
    """Refuse a fit with fewer data (modes used + parameters with a prior) than free parameters.

    Such a fit has no unique answer: the solver would wander along the
    unidentified directions and report infinite standard errors.
    """
    from ringfit.errors import InputError
    from ringfit.fit.least_squares import frequency_data
    from ringfit.fit.priors import resolve_priors

    used = frequency_data(table, modes, rel).n.size
    priors = [k for k in resolve_priors(prior, free) if k in free]
    if used + len(priors) < len(free):
        with_prior = f" and a prior on {', '.join(priors)}" if priors else ""
        raise InputError(
            f"{used} mode(s) with an assigned n{with_prior} cannot determine {len(free)} free parameters "
            f"({', '.join(free)}); give more modes or fewer parameters (--free)", source=table.source or None)


def run_fit(args) -> int:
    from ringfit.cli import CommandFailed
    from ringfit.fit.identifiability import identifiability
    from ringfit.fit.free_block import noise_summary
    from ringfit.fit.least_squares import fit_natural_frequencies, fitted_ring
    from ringfit.io.files import check_output_path
    from ringfit.io.tyre import write_tyre

    from ringfit.errors import InputError

    if args.fit_max_steps is not None:
        raise InputError("--max-steps is the sampler's chain length (`ringfit sample`); the fit's iteration limit "
                         "is --max-iterations")
    check_output_path(args.out, overwrite=args.force, inputs=[args.modes, args.tyre])
    table, tyre, free, modes, rel = _inputs(args)
    result = fit_natural_frequencies(table, tyre.geometry, tyre.ring, free=free, prior=args.prior, modes=modes,
                                     default_relative_std=rel, max_steps=args.max_iterations)
    print(result.summary())
    print(f"σ: {noise_summary(result.extra)}")
    print(identifiability(result).summary(known=result.flags))
    if not result.converged:
        raise CommandFailed(f"fit did not converge ({result.status}); nothing written. "
                            + ("Try --prior physical or fix EI." if args.prior == "none" else
                               "Try --max-iterations or fewer free parameters."))
    write_tyre(tyre.with_ring(fitted_ring(result), names=list(tyre.ring_values) + list(free)), args.out,
               overwrite=args.force)
    print(f"wrote {args.out}")
    return 0


def run_sample(args) -> int:
    import warnings

    from ringfit.fit.posterior import sample_posterior
    from ringfit.io.files import check_output_paths

    from ringfit.errors import InputError

    if args.netcdf is not None and args.netcdf.suffix.lower() != ".nc":
        raise InputError(f"--netcdf {args.netcdf}: expected a file name ending in .nc")
    check_output_paths([args.out, args.netcdf], overwrite=args.force, inputs=[args.modes, args.tyre])
    if args.max_steps < args.min_steps:
        raise InputError(f"--max-steps {args.max_steps} is below --min-steps {args.min_steps}")
    table, tyre, free, modes, rel = _inputs(args)
    if args.walkers < 2 * len(free):
        raise InputError(f"--walkers {args.walkers}: expected at least twice the {len(free)} free parameters "
                         f"({2 * len(free)})")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        post = sample_posterior(table, tyre.geometry, tyre.ring, free=free, prior=args.prior, modes=modes,
                                default_relative_std=rel, walkers=args.walkers, min_steps=args.min_steps,
                                max_steps=args.max_steps, seed=args.seed, progress=not args.quiet,
                                sampler=args.sampler, chains=args.chains)
    for w in caught:
        print(f"WARNING: {w.message}", file=sys.stderr)
    _print_posterior(post)
    post.save(args.out, overwrite=args.force)
    print(f"wrote {args.out}")
    if args.netcdf is not None:
        post.save_netcdf(args.netcdf, overwrite=args.force, inputs=[args.modes, args.tyre])
        print(f"wrote {args.netcdf}")
    return 0


def _print_posterior(post) -> None:
    d = post.diagnostics()
    print(f"posterior ({post.sampler} sampler, {d['walkers']} walkers): {d['verdict']}; "
          f"acceptance {d['acceptance_mean']:.2f}")
    print(f"{'parameter':<12}{'median':>13}{'95 % interval':>30}{'R-hat':>8}")
    for row, rh in zip(post.summary_table(), d["rhat"]):
        print(f"{row['name']:<12}{row['median']:>13.5g}{row['lo']:>15.5g} – {row['hi']:<12.5g}{rh:>8.3f}")
    print_predictive_check(post)


#: A posterior predictive p-value below this is flagged in the printout.
PPC_FLAG = 0.01


def print_predictive_check(post) -> None:
    """One line per measured table: its χ², rows and posterior predictive p-value (docs/physics.md §12.4)."""
    ppc = post.meta.get("predictive_check") or {}
    if not ppc:
        return
    print("posterior predictive check (p-value of each table's χ²):")
    for name, c in ppc.items():
        note = "  <- the model does not reproduce this table's scatter" if c["p_value"] < PPC_FLAG else ""
        print(f"  {name:<32s} χ² {c['chi2_median']:9.4g} over {c['rows']:4d} rows  p = {c['p_value']:.3g}{note}")


def run_report(args) -> int:
    from ringfit.io.files import check_output_path
    from ringfit.report.html import write_report

    check_output_path(args.out, overwrite=args.force, inputs=[args.posterior])
    write_report(args.posterior, args.out, overwrite=args.force)
    print(f"wrote {args.out}")
    return 0


def run_demo(args) -> int:
    from ringfit.demo import run_demo as demo
    from ringfit.errors import InputError

    if args.out.exists() and not args.out.is_dir():
        raise InputError("exists and is not a folder; --out names the folder the demo writes into", source=args.out)
    demo(args.out, overwrite=args.force, seed=args.seed, progress=not args.quiet)
    return 0
