"""Identify across states (issue 33 item 3): the pressure law and the tread's k_x recovered with the ring, their
95 % coverage, and the time of one identification.

Run ``python benchmarks/bench_identify_states.py [--cases 6] [--seed 1]`` (about 1.5 min per case on one core).
Each case is ``ringfit.synth.identify.make_state_identify_case`` with its own seed: a ring drawn around Table 9,
state laws drawn (kw_share 0.3–0.7, kv_share 0.2–0.6, k_tread_share 0.1–0.5, k_x 15·10⁶ N/m² ± 20 %), free tables
at p_ref and 0.8 p_ref, loaded tables at 3 and 5 kN (p_ref) and 4 kN (0.8 p_ref), five profiles (two of them at a
drive and a brake slip of ±0.015, their torque T = Fx·H stated with a 2 % σ), coloured noise, random gains and angle
offsets; the truth solved on a 1024- or 2048-point grid (ringfit: 512). The truth's friction μ is drawn per case
with ln μ ~ N(0, ``--mu-spread``) (default 0.1, the doubt identify holds μ = 1 with when the tyre file states none,
docs/physics.md §11 *friction*; 0: the held value is the truth). It prints, per parameter (ring and laws), the
median |error| (ln θ; the share itself for a share) and the share of cases whose 95 % interval covers the truth
(target: 95 %; with 6 cases, 5 … 6 covered is inside a binomial 95 % band), beside it the coverage without the held
μ's doubt, the slips' z-scores, and the first case's identification cold and warm (wall and CPU time), with the load
average at start and end.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import tempfile
import time
from pathlib import Path


def parse():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=6, help="random cases (default 6)")
    ap.add_argument("--seed", type=int, default=1, help="first seed (default 1)")
    ap.add_argument("--cores", type=int, default=1, help="pin to this many cores (0: no pinning)")
    ap.add_argument("--mu-spread", type=float, default=0.1,
                    help="σ of the truth's ln μ about the held μ = 1 (default 0.1, identify's default doubt)")
    return ap.parse_args()


ARGS = parse()
if ARGS.cores:
    os.sched_setaffinity(0, set(sorted(os.sched_getaffinity(0))[: ARGS.cores]))

import numpy as np  # noqa: E402
from ringfit.fit.free_block import Z95  # noqa: E402
from ringfit.fit.identify import LAW_FIELDS, identify, read_identify_folder  # noqa: E402
from ringfit.io.tyre import LINEAR_COVARIANCE  # noqa: E402
from ringfit.synth.identify import make_state_identify_case  # noqa: E402

NAMES = ("rho_a", "ei", "kw", "kv", "k_tread", "damping_ratio") + LAW_FIELDS


def main() -> None:
    load0 = os.getloadavg()
    print(f"load average at start: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")
    err = {n: [] for n in NAMES}
    cover = {n: [] for n in NAMES}
    cover0 = {n: [] for n in NAMES}
    mu_z = []  # μ read from the data (docs/physics.md §11 *friction: read from the data*) against the truth's
    slip_z, times = [], None
    with tempfile.TemporaryDirectory() as tmp:
        for c in range(ARGS.cases):
            seed = ARGS.seed + c
            folder = Path(tmp) / f"case{seed}"
            mu = math.exp(ARGS.mu_spread * np.random.default_rng([seed, 31]).standard_normal())
            truth = make_state_identify_case(folder, seed=seed, truth_file=False, friction=mu)
            inputs = read_identify_folder(folder)
            t0, c0 = time.perf_counter(), time.process_time()
            ident = identify(inputs)
            cold = (time.perf_counter() - t0, time.process_time() - c0)
            if c == 0:
                t0, c0 = time.perf_counter(), time.process_time()
                identify(inputs)
                times = (cold, (time.perf_counter() - t0, time.process_time() - c0))
            params = ident.parameters()
            values = {**truth["ring"], **truth["laws"]}
            for n in NAMES:
                p, v = params[n], values[n]
                err[n].append(abs(p["value"] - v) if n in LINEAR_COVARIANCE else abs(math.log(p["value"] / v)))
                cover[n].append(p["lo95"] <= v <= p["hi95"])
                held = ident.held["friction"] if ident.held else None
                sd0 = held["sd_without"][n] if held else (p.get("sd_ln") or p.get("sd"))
                z0 = ((p["value"] - v) if n in LINEAR_COVARIANCE else math.log(p["value"] / v)) / sd0
                cover0[n].append(abs(z0) <= 1.959964)
            if ident.held and "data" in ident.held["friction"]:
                f = ident.held["friction"]
                mu_z.append((math.log(f["value"] / mu), f["sd_ln"]))
            by_source = {Path(x["source"]).name: x for x in ident.nuisances}
            for i, tp in enumerate(truth["profiles"]):
                got = by_source.get(f"run{i + 1}.profile.csv", {})
                if "slip" in got:
                    slip_z.append((got["slip"] - tp["slip"]) / got["slip_sd"])
            worst = max(NAMES, key=lambda n: err[n][-1] / max(1e-300, (params[n].get("sd_ln") or params[n].get("sd")
                                                                          or 1.0)))
            print(f"case seed {seed} (μ {mu:.3f}): {ident.fit.status}, {cold[0]:.1f} s wall / {cold[1]:.1f} s CPU, "
                  f"covered {sum(cover[n][-1] for n in NAMES)}/{len(NAMES)}, largest error/σ: {worst}", flush=True)
    k = ARGS.cases
    print(f"\n{k} cases (seeds {ARGS.seed}…{ARGS.seed + k - 1}); target coverage 95 % per parameter")
    print(f"{'parameter':14s} {'median |err|':>13s} {'covered':>8s} {'without μ doubt':>16s}")
    for n in NAMES:
        unit = "" if n in LINEAR_COVARIANCE else " (ln)"
        print(f"{n:14s} {statistics.median(err[n]):13.4g} {sum(cover[n]):4d}/{k} {sum(cover0[n]):12d}/{k}{unit}")
    if mu_z:
        errs = [abs(e) for e, _ in mu_z]
        print(f"{'friction μ':14s} {statistics.median(errs):13.4g} {sum(abs(e) <= Z95 * sd for e, sd in mu_z):4d}/"
              f"{len(mu_z)} {'(read from the data; held: σ 0.1)':>16s} (ln); its σ median "
              f"{statistics.median(sd for _, sd in mu_z):.3g}, |z| max {max(abs(e) / sd for e, sd in mu_z):.2f}")
    total = sum(sum(v) for v in cover.values())
    total0 = sum(sum(v) for v in cover0.values())
    print(f"all parameters: {total}/{k * len(NAMES)} covered ({100 * total / (k * len(NAMES)):.1f} %); without the "
          f"held μ's doubt {total0}/{k * len(NAMES)} ({100 * total0 / (k * len(NAMES)):.1f} %)")
    if slip_z:
        print(f"slip z-scores ({len(slip_z)}): median |z| {statistics.median(abs(z) for z in slip_z):.2f}, "
              f"max |z| {max(abs(z) for z in slip_z):.2f}")
    if times:
        (cw, cc), (ww, wc) = times
        print(f"one identification (2 free, 3 loaded tables, 5 profiles): cold {cw:.1f} s wall / {cc:.1f} s CPU, "
              f"warm {ww:.1f} s wall / {wc:.1f} s CPU")
    load1 = os.getloadavg()
    print(f"load average at end: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")


if __name__ == "__main__":
    main()
