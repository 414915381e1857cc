"""``ringfit identify FOLDER --out NAME.tyre.toml [--posterior NAME.h5]`` — the tyre identified once from everything measured."""

from __future__ import annotations

import json
import math
from pathlib import Path

from ringfit.cli._args import force_flag, integer, quiet_flag, sampler_flags


def register(sub) -> None:
    p = sub.add_parser("identify", help="identify the ring from every measurement of a case folder at once",
                       description="One joint weighted least squares of the ring (ρA, EI, k_w, k_v, k_tread, ζ) "
                                   "over every measurement of a case folder whose condition is known: "
                                   "free.modes.csv, standing loaded tables at their load_n, rolling profiles at "
                                   "their load_n and speed (per profile a gain and an angle offset). Measurements "
                                   "at two or more pressures identify the pressure law ([ring.pressure] shares), "
                                   "profiles at a stated torque_nm the tread's longitudinal stiffness k_x "
                                   "(docs/physics.md §11). Each data type's noise is estimated from its own "
                                   "residual. Writes the tyre file with [ring] (and the identified laws) and "
                                   "[ring.covariance] and NAME.identify.json beside it (docs/formats.md §18). Exit "
                                   "1 if the fit does not converge.")
    p.add_argument("folder", type=Path, help="case folder (docs/formats.md §6)")
    p.add_argument("--out", required=True, type=Path, help="output tyre TOML (NAME.tyre.toml); NAME.identify.json "
                                                           "is written beside it")
    p.add_argument("--posterior", type=Path, default=None, metavar="NAME.h5",
                   help="also sample the joint posterior (compiled ensemble sampler; the same noise model as "
                        "the intervals) and save it (HDF5)")
    p.add_argument("--walkers", type=integer("an even number of walkers >= 2", lo=2), default=None,
                   help="walkers per ensemble (default: 2 × the free parameters)")
    sampler_flags(p)
    p.add_argument("--min-steps", type=integer("a whole number of steps >= 100", lo=100), default=500,
                   help="posterior chain steps before the first convergence check (default 500)")
    p.add_argument("--max-steps", type=integer("a whole number of steps >= 100", lo=100), default=10000,
                   help="posterior chain steps at most (default 10000: joint cases need 7,000–8,500 for the 50 τ the sampler stops at)")
    p.add_argument("--seed", type=integer("a whole number >= 0", lo=0), default=0, help="random seed (default 0)")
    p.add_argument("--sensor", choices=("fitted", "ideal"), default="fitted",
                   help="'fitted' (default): each profile is read through its sensor's own nuisances — tilt, IEPE "
                        "corner, liner offset, tangential gain — as `ringfit estimate --state` reads a recording "
                        "(docs/physics.md §11 *profiles*); 'ideal': a gain and an angle offset per profile only")
    force_flag(p)
    quiet_flag(p)
    p.set_defaults(run=run_identify)


def report_path(out: Path) -> Path:
    """``NAME.tyre.toml`` → ``NAME.identify.json`` (``NAME.toml`` → ``NAME.identify.json``)."""
    name = out.name
    for suffix in (".tyre.toml", ".toml"):
        if name.endswith(suffix):
            name = name[: -len(suffix)]
            break
    return out.with_name(name + ".identify.json")


def run_identify(args) -> int:
    from ringfit.cli import CommandFailed
    from ringfit.errors import InputError
    from ringfit.io.files import atomic_write_text, check_output_paths

    report = report_path(args.out)
    folder = args.folder
    inputs_listed = list(folder.glob("*")) if folder.is_dir() else []
    check_output_paths([args.out, report, args.posterior], overwrite=args.force, inputs=inputs_listed)
    from ringfit.fit.identify import identification_report, identify, read_identify_folder
    from ringfit.io.tyre import write_tyre

    inputs = read_identify_folder(folder)
    for note in inputs.skipped:
        print(f"WARNING: {note}")
    ident = identify(inputs, progress=not args.quiet, sensor=args.sensor == "fitted")
    if ident.converged and inputs.profiles:  # each free-rolling profile's stated load against its own reading
        import warnings

        from ringfit.fit.estimate.load import stated_load_check

        said = stated_load_check(inputs.profiles, inputs.tyre.geometry, ident.ring, laws=ident.laws,
                                 covariance=ident.covariance)
        for note in said:
            warnings.warn(note, stacklevel=2)
        ident.notes = list(ident.notes) + said
        ident.warned = list(ident.warned) + said
    doc = identification_report(ident)
    _print(ident, doc)
    for note in ident.notes[len(inputs.skipped):]:
        if note not in ident.warned:  # those are WARNING lines on stderr
            print(f"note: {note}")
    if not ident.converged:
        raise CommandFailed(f"the joint fit did not converge ({ident.fit.message}); nothing written")
    tyre = inputs.tyre.with_ring(ident.ring, covariance=ident.covariance)
    if ident.law_values():  # identified across states: [ring.pressure] shares, kx_n_per_m2 (docs/formats.md §1)
        tyre = tyre.with_state_values(**ident.law_values())
    tyre.extra = dict(tyre.extra)
    meta = dict(tyre.extra.get("meta", {}))
    meta.update(identified_from=str(folder), identify_report=report.name)
    tyre.extra["meta"] = meta
    posterior = None
    if args.posterior is not None:
        from ringfit.fit.posterior import sample

        k = len(ident.fit.names)
        walkers = args.walkers or 2 * k
        if walkers < 2 * k or walkers % 2:
            raise InputError(f"--walkers {walkers}: the stretch move needs an even number of at least {2 * k} "
                             f"(2 × {k} free parameters)")
        posterior = sample(ident.posterior_fit(), walkers=walkers, min_steps=args.min_steps, max_steps=args.max_steps,
                           check_every=max(100, args.min_steps // 2), seed=args.seed, progress=not args.quiet,
                           spread=0.25, meta={"model": "identify", "folder": str(folder)}, sampler=args.sampler,
                           chains=args.chains)
        doc["posterior"] = {"file": args.posterior.name, **_posterior_summary(posterior)}
        _print_predictive(posterior)
    write_tyre(tyre, args.out, overwrite=args.force)
    atomic_write_text(report, json.dumps(doc, indent=1, allow_nan=False, default=_json_default) + "\n")
    print(f"wrote {args.out}")
    print(f"wrote {report}")
    if posterior is not None:
        posterior.save(args.posterior, overwrite=args.force)
        print(f"wrote {args.posterior}")
    return 0


def _json_default(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return str(x)


def _posterior_summary(posterior) -> dict:
    return {"sampler": posterior.sampler, "steps": int(posterior.steps), "converged": bool(posterior.converged),
            "parameters": {row["name"]: dict(median=row["median"], lo95=row["lo"], hi95=row["hi"])
                           for row in posterior.summary_table(0.95)},
            "predictive_check": {name: {k: (v if not isinstance(v, float) or math.isfinite(v) else None)
                                        for k, v in c.items()}
                                 for name, c in posterior.meta.get("predictive_check", {}).items()}}


def _print_predictive(posterior) -> None:
    from ringfit.cli.free import print_predictive_check

    print_predictive_check(posterior)


def _print(ident, doc) -> None:
    print(f"joint fit: {doc['status']} after {doc['iterations']} steps ({doc['passes']} noise passes)")
    print(f"{'parameter':16s} {'value':>12s} {'95 % interval':>27s} {'sd ln':>8s}")

    def g(x, width, prec, kind="g"):
        return f"{'—':>{width}s}" if x is None else f"{x:{width}.{prec}{kind}}"

    for name, p in doc["parameters"].items():
        mark = "  (to the plausible bound)" if p.get("to_bound") else ""
        linear = "  (sd of the share itself)" if "sd" in p else ""
        print(f"{name:16s} {g(p['value'], 12, 5)} [{g(p['lo95'], 12, 5)}, {g(p['hi95'], 12, 5)}] "
              f"{g(p.get('sd_ln', p.get('sd')), 8, 3)}{mark}{linear}")
    names = list(doc["parameters"])
    print("Fisher information share per block (which data pin which parameter):")
    print(f"{'block':14s} {'rows':>5s} {'σ scale':>8s} " + " ".join(f"{n[:8]:>8s}" for n in names))
    for b, v in doc["blocks"].items():
        print(f"{b:14s} {v['rows']:5d} {g(v['sigma_scale'], 8, 3)} "
              + " ".join(g(v['fisher_share'].get(n, 0.0), 8, 3, 'f') for n in names))
    corr = doc["correlation"]["matrix"]
    strong = [(names[i], names[j], corr[i][j]) for i in range(len(names)) for j in range(i)
              if corr[i][j] is not None and math.isfinite(corr[i][j]) and abs(corr[i][j]) > 0.9]
    for a, b, c in strong:
        print(f"posterior correlation {a}–{b}: {c:+.3f}")
    for flag in doc["flags"]:
        print(f"flag: {flag}")
