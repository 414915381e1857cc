"""False-accept rate and power of the gap diagnosis's verdicts (issue 20; docs/physics.md §6.4).

A verdict is worth its false-accept rate. This script diagnoses folders with **no effect in them**
and counts how often any effect is accepted, per kind of folder, with the rate's 95 % interval
(Clopper–Pearson) against the target α + 1 %:

- ``rolling-random``: the source study's real free table beside three rolling tables (20/40/60 km/h,
  4 kN, rotating frame) whose rows hold uniformly random frequencies in 75–485 Hz, with the row counts
  of ``ringfit example rolling``, no n, tag or branch (the issue's reproduction);
- ``loaded-random``: the real free table beside two loaded tables (2 and 4 kN) of random frequencies
  in 75–485 Hz with ``extr``/``0`` tags and no n;
- ``modal-noise``: ``make_case(effect="none")`` — noise-only mode tables from the generator, whose
  noise level (0.05–0.2 %) and colour (white, coloured) are drawn per seed;
- ``profile-noise``: ``make_profile_case(effect="none")`` — noise-only rolling profiles (white, pink,
  red and band noise at 0.05–3 m/s²).

With ``--power`` it also diagnoses effect cases (every injected effect of ``bench_gap.py`` and the rolling
cases of ``bench_gap_rolling.py``) twice in the same process, interleaved — with the calibration
(``--alpha``) and without it (``null_draws=0``, the rule alone) — and prints the share of the rule's
detections the calibration keeps (target ≥ 95 %).

Run: ``python benchmarks/bench_gap_calibration.py [--per-kind N] [--kinds a,b] [--power N] [--alpha A]
[--draws D] [--seed-offset S]``. Figures are refused when any diagnosis failed.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

KINDS = ("rolling-random", "loaded-random", "modal-noise", "profile-noise")
HEADER = "n,a,tag,kind,freq_hz,freq_std_hz,damping_pct,branch"


def _args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--per-kind", type=int, default=100, help="null folders per kind (default 100)")
    p.add_argument("--kinds", default=",".join(KINDS), help="comma-separated kinds (default all)")
    p.add_argument("--power", type=int, default=0, help="effect cases per effect for the power table (0: none)")
    p.add_argument("--alpha", type=float, default=0.01)
    p.add_argument("--draws", type=int, default=200)
    p.add_argument("--seed-offset", type=int, default=0)
    a = p.parse_args(argv)
    kinds = [k.strip() for k in a.kinds.split(",") if k.strip()]
    bad = [k for k in kinds if k not in KINDS]
    if bad or a.per_kind < 1 or not 0 < a.alpha < 0.5 or a.draws < 20 or a.power < 0:
        print(f"bench_gap_calibration: bad arguments (kinds {bad or 'ok'}; --per-kind >= 1, 0 < --alpha < 0.5, "
              "--draws >= 20, --power >= 0)", file=sys.stderr)
        raise SystemExit(2)
    a.kinds = kinds
    return a


def _copy_free(out: Path):
    from ringfit.data import path

    out.mkdir(parents=True)
    shutil.copy(path("free-ssi.modes.csv"), out / "free.modes.csv")
    shutil.copy(path("free-ssi.modes.json"), out / "free.modes.json")
    shutil.copy(path("table9.tyre.toml"), out / "tyre.toml")


def _table(out: Path, name: str, freqs, tags, sidecar: dict, rng):
    lines = [HEADER] + [f",0,{t},structural,{f:.4f},,{rng.uniform(2, 8):.2f}," for f, t in zip(freqs, tags)]
    (out / f"{name}.modes.csv").write_text("\n".join(lines) + "\n")
    (out / f"{name}.modes.json").write_text(json.dumps(sidecar))


def rolling_random(out: Path, seed: int, counts) -> None:
    _copy_free(out)
    rng = np.random.default_rng(seed)
    for v, m in zip((20, 40, 60), counts):
        _table(out, f"roll{v}", np.sort(rng.uniform(75, 485, m)), [""] * m,
               {"state": "rolling", "load_n": 4000.0, "speed_kmh": float(v), "pressure_bar": 2.2, "frame": "rotating"},
               rng)


def loaded_random(out: Path, seed: int) -> None:
    _copy_free(out)
    rng = np.random.default_rng(seed)
    for load in (2000.0, 4000.0):
        m = int(rng.integers(8, 13))
        _table(out, f"loaded{int(load)}", np.sort(rng.uniform(75, 485, m)), [("extr", "0")[i % 2] for i in range(m)],
               {"state": "loaded", "load_n": load, "pressure_bar": 2.2}, rng)


def _example_counts(tmp: Path):
    from ringfit.synth.examples import write_example

    write_example("rolling", tmp / "ex")
    folder = next(p.parent for p in (tmp / "ex").rglob("roll20.modes.csv"))
    return [sum(1 for line in (folder / f"roll{v}.modes.csv").read_text().splitlines()[1:] if ",structural," in line)
            for v in (20, 40, 60)]


def clopper_pearson(k: int, n: int, level: float = 0.95):
    from scipy.stats import beta

    a = (1 - level) / 2
    lo = 0.0 if k == 0 else float(beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a, k + 1, n - k))
    return lo, hi


def accepted_effects(content: dict) -> list[str]:
    v = content["verdict"]
    eff = [e for e in v["effects"] if e not in ("none", "unexplained")]
    eff += [e for e in (v.get("damping") or {}).get("effects", []) if e not in ("none", "unexplained")]
    return eff


def main(argv=None) -> int:
    args = _args(sys.argv[1:] if argv is None else argv)
    import ringfit  # noqa: F401
    from ringfit.gap import diagnose
    from ringfit.synth.cases import make_case, make_profile_case

    print(f"load average at start: {' '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs")
    print(f"alpha {args.alpha}, {args.draws} null draws per null; target: false accepts <= alpha + 1 % per kind")
    results = {}
    failures = []
    with tempfile.TemporaryDirectory() as tmpd:
        tmp = Path(tmpd)
        counts = _example_counts(tmp) if "rolling-random" in args.kinds else None
        for kind in args.kinds:
            rows = []
            for i in range(args.per_kind):
                seed = args.seed_offset + 1000 * KINDS.index(kind) + i
                folder = tmp / f"{kind}-{seed}"
                if kind == "rolling-random":
                    rolling_random(folder, seed, counts)
                elif kind == "loaded-random":
                    loaded_random(folder, seed)
                elif kind == "modal-noise":
                    make_case(folder, effect="none", seed=seed)
                else:
                    make_profile_case(folder, effect="none", seed=seed)
                t0, c0 = time.perf_counter(), time.process_time()
                try:
                    d = diagnose(folder, progress=False, alpha=args.alpha, null_draws=args.draws)
                except Exception as exc:  # noqa: BLE001 - counted and reported: no figures then
                    failures.append(f"{kind} seed {seed}: {type(exc).__name__}: {exc}")
                    continue
                eff = accepted_effects(d.content)
                rows.append((eff, time.perf_counter() - t0, time.process_time() - c0))
                print(f"  {kind:15s} seed {seed:5d}: {' + '.join(d.content['verdict']['effects']):40s} "
                      f"{'FALSE ACCEPT ' + '+'.join(eff) if eff else ''} ({rows[-1][1]:.1f} s wall, "
                      f"{rows[-1][2]:.1f} s CPU)", flush=True)
                shutil.rmtree(folder, ignore_errors=True)
            results[kind] = rows
    if failures:
        print("\nbench_gap_calibration: diagnoses failed, no figures printed:", file=sys.stderr)
        for f in failures:
            print("  " + f, file=sys.stderr)
        return 1
    target = args.alpha + 0.01
    print(f"\n| null folders | n | false accepts | rate | 95 % interval | target <= {100 * target:.0f} % | "
          "median wall / CPU per folder |")
    print("|---|---|---|---|---|---|---|")
    for kind, rows in results.items():
        n = len(rows)
        k = sum(1 for e, _, _ in rows if e)
        lo, hi = clopper_pearson(k, n)
        ok = "met" if k / n <= target else "NOT met"
        print(f"| {kind} | {n} | {k} | {100 * k / n:.1f} % | {100 * lo:.1f} … {100 * hi:.1f} % | {ok} | "
              f"{np.median([w for _, w, _ in rows]):.1f} s / {np.median([c for _, _, c in rows]):.1f} s |")
    if args.power:
        _power(args)
    print(f"load average at end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


def _power(args) -> None:
    """Detections of effect cases with the calibration against the rule alone, interleaved per case."""
    from ringfit.gap import diagnose
    from ringfit.synth.cases import MODAL_INJECTIONS, PROFILE_INJECTIONS, make_case, make_profile_case, make_rolling_case

    cases = [("modal", e) for e in MODAL_INJECTIONS if e not in ("none", "tread_pitch")]
    cases += [("profile", e) for e in PROFILE_INJECTIONS if e not in ("none", "tread_pitch")]
    cases += [("rolling", "contact"), ("rolling", "control")]
    kept = found_rule = 0
    print("\n| case | effect | seed | rule alone | calibrated | p |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmpd:
        for kind, effect in cases:
            for i in range(args.power):
                seed = args.seed_offset + 5000 + i
                folder = Path(tmpd) / f"{kind}-{effect}-{seed}"
                if kind == "modal":
                    label = make_case(folder, effect=effect, seed=seed)
                elif kind == "profile":
                    label = make_profile_case(folder, effect=effect, seed=seed)
                else:
                    label = make_rolling_case(folder, contact=effect == "contact", seed=seed)
                want = set(label.expected_verdict.split("+"))
                rule = set(accepted_effects(diagnose(folder, progress=False, null_draws=0).content))
                d = diagnose(folder, progress=False, alpha=args.alpha, null_draws=args.draws)
                cal = set(accepted_effects(d.content))
                hit_rule = bool(want & {x for e in rule for x in e.split("+")})
                hit_cal = bool(want & {x for e in cal for x in e.split("+")})
                found_rule += hit_rule
                kept += hit_rule and hit_cal
                ps = [c["p_value"] for c in d.content["verdict"].get("calibration", [])]
                print(f"| {kind} | {effect} | {seed} | {'+'.join(sorted(rule)) or 'none'} | "
                      f"{'+'.join(sorted(cal)) or 'none'} | {', '.join(f'{p:.3g}' for p in ps)} |", flush=True)
                shutil.rmtree(folder, ignore_errors=True)
    share = kept / found_rule if found_rule else float("nan")
    print(f"\npower: the calibration keeps {kept} of the rule's {found_rule} detections ({100 * share:.0f} %; "
          f"target >= 95 %)")


if __name__ == "__main__":
    raise SystemExit(main())
