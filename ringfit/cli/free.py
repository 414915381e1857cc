"""``ringfit fit | sample | report | demo`` — the free-tyre natural-frequency workflow."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

DEFAULT_FREE = "rho_a,ei,kw,kv"


def register(sub) -> None:
    p = sub.add_parser("fit", help="least-squares fit of ring parameters to a mode table",
                       description="Fit EI, k_w, k_v, ρA (eq. 18) to measured natural frequencies and write the "
                                   "tyre file with the fitted [ring] values. Prints standard errors, correlations "
                                   "and identifiability findings. Exit 1 if the fit does not converge.")
    _common(p)
    p.add_argument("--out", required=True, type=Path, help="output tyre TOML with fitted [ring] values")
    p.add_argument("--max-steps", type=int, default=256, help="solver step limit (default 256)")
    p.set_defaults(run=run_fit)

    p = sub.add_parser("sample", help="emcee posterior of the ring parameters",
                       description="Sample the posterior with emcee until the chain exceeds 50 autocorrelation "
                                   "times (or --max-steps), and save the draws to HDF5 for `ringfit report`.")
    _common(p)
    p.add_argument("--out", required=True, type=Path, help="output posterior file (HDF5, e.g. POSTERIOR.h5)")
    p.add_argument("--walkers", type=int, default=32)
    p.add_argument("--min-steps", type=int, default=2000)
    p.add_argument("--max-steps", type=int, default=20000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(run=run_sample)

    p = sub.add_parser("report", help="self-contained HTML uncertainty report from a saved posterior",
                       description="Build the HTML report (data vs fit with predictive intervals, parameters, "
                                   "corner plot, identifiability, sampler diagnostics) from a posterior file.")
    p.add_argument("posterior", type=Path, help="posterior file written by `ringfit sample`")
    p.add_argument("--out", required=True, type=Path, help="output .html")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")
    p.set_defaults(run=run_report)

    p = sub.add_parser("demo", help="fit + posterior + report on the bundled source-study data",
                       description="Runs the whole free-tyre workflow on the source study's SSI mode table "
                                   "(bundled): least squares, the source's own procedure, emcee posterior and the "
                                   "HTML report, and prints the Table 10 comparison.")
    p.add_argument("--out", type=Path, default=Path("ringfit-demo"), help="output folder (default ./ringfit-demo)")
    p.add_argument("--force", action="store_true", help="replace the outputs of an earlier demo in that folder")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(run=run_demo)


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("modes", type=Path, help="mode table *.modes.csv (DATA.md §2)")
    p.add_argument("--tyre", required=True, type=Path, help="tyre TOML (DATA.md §1); [ring] gives starting values")
    p.add_argument("--free", default=DEFAULT_FREE,
                   help=f"comma-separated parameters to fit (default {DEFAULT_FREE}); others stay at the tyre file's values")
    p.add_argument("--prior", default="physical", choices=("physical", "none"),
                   help="'physical': belt-plate log-normal prior on EI (see docs); 'none': data only (default physical)")
    p.add_argument("--modes-used", default=None, metavar="N-LIST",
                   help="which n take part, e.g. '1-6' or '1,3,7' (default: every structural mode with n)")
    p.add_argument("--default-std", type=float, default=None, metavar="REL",
                   help="σ/f where the table has no freq_std_hz (default 0.01)")
    p.add_argument("--force", action="store_true", help="overwrite an existing output")


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
    from ringfit.errors import InputError
    from ringfit.fit.least_squares import DEFAULT_RELATIVE_STD, check_free
    from ringfit.io.modes import read_mode_table
    from ringfit.io.tyre import read_tyre

    free = check_free([s.strip() for s in args.free.split(",") if s.strip()])
    rel = DEFAULT_RELATIVE_STD if args.default_std is None else args.default_std
    if not 0 < rel < 1:
        raise InputError(f"--default-std {rel}: expected a fraction between 0 and 1 (e.g. 0.01)")
    return read_mode_table(args.modes), read_tyre(args.tyre), free, parse_n_list(args.modes_used), rel


def run_fit(args) -> int:
    from ringfit._cache import enable_compilation_cache

    enable_compilation_cache()
    from ringfit.cli import CommandFailed
    from ringfit.fit.identifiability import identifiability
    from ringfit.fit.least_squares import fit_natural_frequencies, fitted_ring
    from ringfit.io.files import check_output_path
    from ringfit.io.tyre import write_tyre

    check_output_path(args.out, overwrite=args.force, inputs=[args.modes, args.tyre])
    table, tyre, free, modes, rel = _inputs(args)
    result = fit_natural_frequencies(table, tyre.geometry, tyre.ring, free=free, prior=args.prior, modes=modes,
                                     default_relative_std=rel, max_steps=args.max_steps)
    print(result.summary())
    print(identifiability(result).summary(known=result.flags))
    if not result.converged:
        raise CommandFailed(f"fit did not converge ({result.status}); nothing written. "
                            + ("Try --prior physical or fix EI." if args.prior == "none" else
                               "Try --max-steps or fewer free parameters."))
    write_tyre(tyre.with_ring(fitted_ring(result), names=list(tyre.ring_values) + list(free)), args.out,
               overwrite=args.force)
    print(f"wrote {args.out}")
    return 0


def run_sample(args) -> int:
    from ringfit._cache import enable_compilation_cache

    enable_compilation_cache()
    import warnings

    from ringfit.fit.posterior import sample_posterior
    from ringfit.io.files import check_output_path

    check_output_path(args.out, overwrite=args.force, inputs=[args.modes, args.tyre])
    table, tyre, free, modes, rel = _inputs(args)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        post = sample_posterior(table, tyre.geometry, tyre.ring, free=free, prior=args.prior, modes=modes,
                                default_relative_std=rel, walkers=args.walkers, min_steps=args.min_steps,
                                max_steps=args.max_steps, seed=args.seed, progress=not args.no_progress)
    for w in caught:
        print(f"WARNING: {w.message}", file=sys.stderr)
    _print_posterior(post)
    post.save(args.out, overwrite=args.force)
    print(f"wrote {args.out}")
    return 0


def _print_posterior(post) -> None:
    d = post.diagnostics()
    print(f"posterior: {d['verdict']}; acceptance {d['acceptance_mean']:.2f}")
    print(f"{'parameter':<12}{'median':>13}{'95 % interval':>30}{'R-hat':>8}")
    for row, rh in zip(post.summary_table(), d["rhat"]):
        print(f"{row['name']:<12}{row['median']:>13.5g}{row['lo']:>15.5g} – {row['hi']:<12.5g}{rh:>8.3f}")


def run_report(args) -> int:
    from ringfit.io.files import check_output_path
    from ringfit.report.html import write_report

    check_output_path(args.out, overwrite=args.force, inputs=[args.posterior])
    write_report(args.posterior, args.out, overwrite=args.force)
    print(f"wrote {args.out}")
    return 0


def run_demo(args) -> int:
    from ringfit._cache import enable_compilation_cache

    enable_compilation_cache()
    from ringfit.demo import run_demo as demo

    demo(args.out, overwrite=args.force, seed=args.seed)
    return 0
