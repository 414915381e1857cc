"""Covariance SSI: ringfit vs pyOMA2 on the SAME data, decimation, block rows and orders (issue 3, item 11).

Prints, per case, wall-clock and CPU time (best of ``--repeats`` runs of each
tool after one untimed warm-up run, each configuration in its own fresh
worker process with OMP/OPENBLAS/MKL_NUM_THREADS set before numpy is
imported; a second round of every configuration after the first, pyOMA2's
where it takes < 20 s), the time ratios, peak memory (tracemalloc peak of one
more run; numpy reports its buffers to tracemalloc), whether both find the
same modes, ringfit's wall time per stage, and then how ringfit's cost grows
with channels, block rows and model orders.

Four configurations, three ratios:

- ringfit ``x1``: one core — ``workers=1`` and one BLAS thread;
- ringfit ``default``: its default threads (one per usable CPU, ≤ 8: the
  order sweep's LAPACK calls and the SVD's block products run in parallel),
  one BLAS thread each;
- pyOMA2 ``x1``: one BLAS thread (the setting the issue measured pyOMA2 in);
- pyOMA2 ``all``: as many BLAS threads as cores (its only parallelism).

"one core" = pyOMA2 x1 / ringfit x1 (same resources); "issue's setting" =
pyOMA2 x1 / ringfit default; "whole machine" = the faster of pyOMA2 x1 and
all / ringfit default (each tool as fast as it runs on this machine; more
BLAS threads slow pyOMA2 down on the small cases). The load average is printed before
and after each case: this is a shared virtual machine and wall times move by
±20 % between runs.

Cases (3.2 kHz after decimation from 25.6 kHz, 30 block rows, orders 2–160
step 2, synthetic free ring n = 1…20 with double poles + cavity mode):

- (a) 128 channels (64 angles × radial/tangential) × 4 s, white-noise excitation at θ = 0
- (b) 32 channels × 20 s, same excitation
- (c) 32 channels × 4 s of hammer decays (aligned, first 0.0127 s dropped)

Decimation (and alignment) happen once, outside the timed call, and both
tools get the same decimated array: neither tool's time includes it.

Case (c) also times the σ step of ``ringfit ssi`` (issue 12 item 4,
:func:`ringfit.targets.uncertainty.jackknife_modes` after clustering; the
other cases are one excitation seen by every channel, where a jackknife over
sensor angles does not apply) as a share of the SSI's wall time, and
:func:`ringfit.targets.ssi.ssi_cov_factors` (the SSI keeping its SVD factors).

Timed scope on both sides, the same job: covariances and block Hankel
matrix (30 block rows), SVD, A, C and the eigen-decomposition (poles AND
mode shapes) of every model order 2, 4, …, 160, and stabilization labels
from frequency, damping and shape criteria (pyOMA2: ``SSI.run()`` with method
``cov``: full SVD, ``SSI_fast``, ``SSI_poles``, MPC/MPD hard criteria and
``SC_apply``; ringfit: ``ssi_cov`` (covariances by blocked FFT, randomized
rank-160 SVD, per order one Hessenberg–Schur reduction carrying only the
output rows, :mod:`ringfit.targets.eigen`) + ``stabilization_diagram``).
Clustering into modes is timed separately (pyOMA2 has no automatic
clustering in ``SSI.run``). "Same modes": for each mode of the synthetic
truth in 20–700 Hz, both tools have stable poles within 0.5 % at ≥ 15 % of
the orders (ringfit: label ≥ 1, i.e. frequency and pair-aware shape stable;
pyOMA2: its ``Lab == 1`` poles, frequency 5 %, damping 10 %, MAC criteria),
and the median frequencies of those poles agree within 0.3 %. (The source's
5 % damping criterion, ringfit's squares, is strict for 4 s of ambient
data: damping estimates scatter more than that between orders.)

Usage: ``python benchmarks/bench_ssi.py [--cases a,b,c] [--repeats 3] [--no-pyoma] [--no-growth] [--quick]``
(pyOMA2 is a benchmark-only extra: ``pip install pyOMA-2``; without it the pyOMA2 runs are left
out with a note). ``--quick``: case (c), one repeat, no growth table (a smoke run). A worker
process that fails ends the run with the failure listed and no figures for its case.
"""

from __future__ import annotations

import os

_BLAS_THREADS = os.environ.get("BENCH_SSI_BLAS_THREADS", "1")  # set per worker by the parent
for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_v] = _BLAS_THREADS

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _common as bc  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CASES = ("a", "b", "c")
FS_RAW, FS = 25600.0, 3200.0
BLOCK_ROWS, ORDMAX, STEP = 30, 160, 2
BAND = (20.0, 700.0)


def make_case(case: str, path: Path) -> None:
    """Write the decimated data (channels, samples) and the truth to ``path`` (npz)."""
    sys.path.insert(0, str(ROOT))
    from ringfit.params import table9
    from ringfit.synth.records import impact_records, ring_modes
    from ringfit.targets.decimation import decimate
    from ringfit.targets.identify import prepare_decays

    geometry, ring = table9()
    modes = ring_modes(ring, geometry, n_values=range(1, 21), seed=1)
    rng = np.random.default_rng(0)
    if case in ("a", "b"):
        n_angles, duration = (64, 4.0) if case == "a" else (16, 20.0)
        angles = np.arange(n_angles) * 360.0 / n_angles
        # response to a very short pulse at t = 0, circularly convolved with a white-noise force
        h = impact_records(modes, angles, fs_hz=FS_RAW, duration_s=duration, pre_trigger_s=0.0, trigger_jitter_s=0.0,
                           hammer_duration_s=2 / FS_RAW, hammer_spread=0.0, noise=0.0, with_force=False, seed=2).acc
        w = np.fft.rfft(rng.standard_normal(h.shape[-1]))
        y = np.fft.irfft(np.fft.rfft(h, axis=-1) * w, n=h.shape[-1], axis=-1)
        y += 0.02 * y.std() * rng.standard_normal(y.shape)
        y, fs = decimate(y.reshape(-1, y.shape[-1]), FS_RAW, int(FS_RAW / FS))
    else:
        angles = np.arange(16) * 22.5
        rec = impact_records(modes, angles, fs_hz=FS_RAW, duration_s=4.0 + 0.1, seed=3)
        y, _, _, fs = prepare_decays(rec, decimate_to=FS, average=False)
        angle = np.repeat(np.deg2rad(angles), 2)  # radial, tangential per record: the jackknife's groups
    truth = modes.freq_hz[(modes.freq_hz > BAND[0]) & (modes.freq_hz < BAND[1])]
    np.savez(path, y=y, fs=fs, truth=truth, **({"angle": angle} if case == "c" else {}))


def worker(tool: str, data: Path, out: Path, block_rows: int, ordmax: int, channels: int, repeats: int,
           stages: bool, workers: int | None) -> None:
    os.environ["TQDM_DISABLE"] = "1"
    import logging
    import tracemalloc

    logging.disable(logging.CRITICAL)
    d = np.load(data)
    y, fs = np.ascontiguousarray(d["y"][:channels]), float(d["fs"])
    sys.path.insert(0, str(ROOT))
    orders = range(STEP, ordmax + 1, STEP)
    if tool == "ringfit":
        from ringfit.targets import ssi
        from ringfit.targets.clustering import cluster_modes
        from ringfit.targets.stabilization import stabilization_diagram
    else:
        from pyoma2.algorithms import SSI
        from pyoma2.setup import SingleSetup

    def run():
        if tool == "ringfit":
            poles = ssi.ssi_cov(y, fs, orders=orders, block_rows=block_rows, workers=workers)
            return poles, stabilization_diagram(poles)
        setup = SingleSetup(y.T, fs=fs)
        alg = SSI(name="ssicov", method="cov", br=block_rows, ordmax=ordmax, step=STEP)
        setup.add_algorithms(alg)
        setup.run_by_name("ssicov")
        return alg, None

    walls, cpus = [], []
    run()  # warm-up, untimed (imports, FFT plans, first-touch of memory), for both tools alike
    for _ in range(repeats):  # timed without tracemalloc (it slows Python-level loops)
        t0, c0 = time.perf_counter(), time.process_time()
        first, stab = run()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        del first, stab
    tracemalloc.start()
    first, stab = run()  # the same run again, for the peak memory
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    stage_s = {}
    if tool == "ringfit" and stages:  # the same pipeline, step by step (wall seconds, best of `repeats`)
        w = ssi.default_workers() if workers is None else workers
        for _ in range(repeats):
            t = {}
            c = time.perf_counter()
            cov = ssi.output_covariances(y, 2 * block_rows - 1)
            t["covariances"] = time.perf_counter() - c
            c = time.perf_counter()
            u, sv = ssi.truncated_svd(ssi.hankel_for_svd(cov, block_rows), ordmax, workers=w)
            t["Hankel + SVD"] = time.perf_counter() - c
            c = time.perf_counter()
            poles = ssi.poles_from_svd(u, sv, y.shape[0], orders, 1 / fs, workers=w)
            t["poles + shapes"] = time.perf_counter() - c
            c = time.perf_counter()
            stabilization_diagram(poles)
            t["stabilization"] = time.perf_counter() - c
            stage_s = {k: min(v, stage_s.get(k, np.inf)) for k, v in t.items()}
    unc = {}
    if tool == "ringfit" and "angle" in d.files:  # hammer decays: the σ step of `ringfit ssi` (issue 12 item 4)
        from ringfit.targets.identify import mode_table
        from ringfit.targets.uncertainty import angle_groups, jackknife_modes

        angle = d["angle"][:channels]
        groups = angle_groups(angle)[0]
        axis = np.tile(np.array(["radial", "tangential"], dtype=object), angle.size // 2)
        walls_f, walls_j = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            poles_f, factors = ssi.ssi_cov_factors(y, fs, orders=orders, block_rows=block_rows, workers=workers,
                                                   unbiased=False)
            walls_f.append(time.perf_counter() - t0)
            modes_f = mode_table(cluster_modes(poles_f, stabilization_diagram(poles_f), f_range=BAND), angle, axis,
                                 "ssi-cov", poles=poles_f)[1]
            t0 = time.perf_counter()
            res = jackknife_modes(factors, poles_f, modes_f, groups,
                                  workers=ssi.default_workers() if workers is None else workers)
            walls_j.append(time.perf_counter() - t0)
        unc = {"ssi_factors_s": min(walls_f), "jackknife_s": min(walls_j), "groups": res.groups,
               "modes": len(modes_f)}
    if tool == "ringfit":
        poles = first
        t1 = time.perf_counter()
        modes = cluster_modes(poles, stab, f_range=BAND)
        t_cluster = time.perf_counter() - t1
        freq = [m.freq_hz for m in modes]
        stable_f, stable_o = poles.freq_hz[stab.label >= 1], poles.order[stab.label >= 1]
    else:
        t_cluster = float("nan")
        res = first.result
        fn, lab = np.asarray(res.Fn_poles), np.asarray(res.Lab)
        order = np.broadcast_to(np.arange(fn.shape[1])[None, :] * STEP, fn.shape)
        ok = (lab == 1) & np.isfinite(fn)
        stable_f, stable_o, freq = fn[ok], order[ok], []
    json.dump({"wall_s": min(walls), "cpu_s": min(cpus), "walls": walls, "cluster_s": t_cluster,
               "peak_mb": peak / 2**20, "stages": stage_s, "modes": freq, "stable_f": stable_f.tolist(),
               "stable_o": stable_o.tolist(), "uncertainty": unc}, open(out, "w"))


def run_worker(tool, data, block_rows=BLOCK_ROWS, ordmax=ORDMAX, channels=10**6, repeats=3, stages=False,
               workers=None, blas_threads=1):
    """One tool in a fresh process. ``workers``: ringfit's threads (None = its default); ``blas_threads``: BLAS pool."""
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as fh:
        out = Path(fh.name)
    cmd = [sys.executable, __file__, "--worker", tool, "--data", str(data), "--out", str(out),
           "--block-rows", str(block_rows), "--ordmax", str(ordmax), "--channels", str(channels),
           "--repeats", str(repeats), "--workers", str(0 if workers is None else workers)]
    cmd += ["--stages"] if stages else []
    env = dict(os.environ, BENCH_SSI_BLAS_THREADS=str(blas_threads))
    proc = subprocess.run(cmd, env=env, cwd=ROOT)
    if proc.returncode:
        out.unlink(missing_ok=True)
        failures = bc.Failures()
        failures.add(f"{tool} worker on {Path(data).name}", f"exit status {proc.returncode} (its error above)")
        failures.refuse()
    r = json.loads(out.read_text())
    out.unlink()
    return r


def found(stable_f, stable_o, f0, n_orders):
    sel = np.abs(np.asarray(stable_f) - f0) <= 0.005 * f0
    if np.unique(np.asarray(stable_o)[sel]).size < 0.15 * n_orders:
        return None
    return float(np.median(np.asarray(stable_f)[sel]))


def load() -> str:
    return bc.loadavg()


def main():
    ap = bc.parser(__doc__.splitlines()[0], quick_help="case (c), one repeat, no growth table (smoke run)")
    ap.add_argument("--cases", type=bc.choices_list(CASES, "cases"), default=list(CASES),
                    help="comma-separated cases (default a,b,c)")
    ap.add_argument("--repeats", type=bc.count("a number of runs", 1, 100), default=3,
                    help="timed runs per tool and case (best is reported)")
    ap.add_argument("--no-pyoma", action="store_true")
    ap.add_argument("--no-growth", action="store_true")
    ap.add_argument("--worker", choices=("ringfit", "pyoma2"), help=argparse.SUPPRESS)
    ap.add_argument("--data", help=argparse.SUPPRESS)
    ap.add_argument("--out", help=argparse.SUPPRESS)
    ap.add_argument("--block-rows", type=bc.count("a number of block rows", 2, 1000), default=BLOCK_ROWS)
    ap.add_argument("--ordmax", type=bc.count("a maximum model order", 2 * STEP, 10**4), default=ORDMAX)
    ap.add_argument("--channels", type=bc.count("a number of channels", 1, 10**6), default=10**6)
    ap.add_argument("--stages", action="store_true")
    ap.add_argument("--workers", type=bc.count("a number of threads (0: the default)", 0, 1024), default=0)
    args = ap.parse_args()
    if args.quick:
        args.cases, args.repeats, args.no_growth = ["c"], 1, True
    if not args.cases:
        bc.fail("--cases: give at least one of a,b,c")
    if args.worker and not (args.data and args.out):
        bc.fail("--worker needs --data and --out")
    if args.worker:
        return worker(args.worker, Path(args.data), Path(args.out), args.block_rows, args.ordmax, args.channels,
                      args.repeats, args.stages, args.workers or None)
    if not args.no_pyoma:
        try:
            import pyoma2  # noqa: F401
        except ImportError:
            print("pyOMA2 is not installed (pip install pyOMA-2): its runs are left out")
            args.no_pyoma = True
    bc.start("bench_ssi: ringfit's covariance SSI" + ("" if args.no_pyoma else " vs pyOMA2")
             + (" [--quick]" if args.quick else ""))
    tmp = Path(tempfile.mkdtemp(prefix="bench_ssi_"))
    n_orders = ORDMAX // STEP
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"{FS:.0f} Hz after decimation; {BLOCK_ROWS} block rows; orders {STEP}-{ORDMAX} step {STEP}; "
          f"best of {args.repeats} runs per tool; {cores} cores")
    print("configurations: ringfit x1 = one core (workers=1, one BLAS thread); ringfit default = its default "
          f"threads ({min(8, cores)} workers, one BLAS thread each); pyOMA2 x1 = one BLAS thread (the issue's "
          f"setting); pyOMA2 all = {cores} BLAS threads")
    summary = []
    for case in args.cases:
        data = tmp / f"{case}.npz"
        make_case(case, data)
        d = np.load(data)
        truth = d["truth"]
        print(f"\n== case ({case}): {d['y'].shape[0]} channels x {d['y'].shape[1] / d['fs']:.1f} s "
              f"({d['y'].shape[1]} samples), {truth.size} true modes in {BAND[0]:.0f}-{BAND[1]:.0f} Hz")
        reps = max(args.repeats, 5)
        rf = {"x1": run_worker("ringfit", data, repeats=reps, stages=True, workers=1),
              "default": run_worker("ringfit", data, repeats=reps, stages=True)}
        for key, r in rf.items():
            print(f"ringfit {key:<7}: wall {r['wall_s']:7.3f} s  cpu {r['cpu_s']:7.3f} s  peak +{r['peak_mb']:7.1f} MB  "
                  f"(+ clustering {r['cluster_s']:.2f} s, {len(r['modes'])} modes)")
            print("  stages (wall s): " + ", ".join(f"{k} {v:.3f}" for k, v in r["stages"].items()))
            u = r.get("uncertainty") or {}
            if u:
                print(f"  σ of the modes (jackknife over {u['groups']} groups of sensor angles, {u['modes']} modes): "
                      f"{u['jackknife_s']:.3f} s = {100 * u['jackknife_s'] / r['wall_s']:.0f} % of the SSI wall time; "
                      f"SSI keeping the SVD factors {u['ssi_factors_s']:.3f} s (+"
                      f"{100 * (u['ssi_factors_s'] / r['wall_s'] - 1):.0f} %, stabilization not included)")
        rf_hits = {f0: found(rf["x1"]["stable_f"], rf["x1"]["stable_o"], f0, n_orders) for f0 in truth}
        print(f"ringfit finds {sum(v is not None for v in rf_hits.values())}/{truth.size} true modes "
              f"(stable poles within 0.5 % at >= 15 % of orders)")
        if args.no_pyoma:
            continue
        py = {"x1": run_worker("pyoma2", data, repeats=args.repeats),
              "all": run_worker("pyoma2", data, repeats=args.repeats, blas_threads=cores)}
        # a second round, interleaved (ringfit always, pyOMA2 where it is quick): best of both rounds per run
        for key, w in (("x1", 1), ("default", None)):
            again = run_worker("ringfit", data, repeats=reps, workers=w)
            rf[key]["wall_s"], rf[key]["cpu_s"] = min(rf[key]["wall_s"], again["wall_s"]), min(rf[key]["cpu_s"], again["cpu_s"])
        for key, bt in (("x1", 1), ("all", cores)):
            if py[key]["wall_s"] < 20.0:  # quick: as many timed runs as ringfit gets
                again = run_worker("pyoma2", data, repeats=reps, blas_threads=bt)
                py[key]["wall_s"], py[key]["cpu_s"] = (min(py[key]["wall_s"], again["wall_s"]),
                                                       min(py[key]["cpu_s"], again["cpu_s"]))
        for key, r in rf.items():
            print(f"ringfit {key:<7}: best of two rounds: wall {r['wall_s']:7.3f} s  cpu {r['cpu_s']:7.3f} s")
        for key, r in py.items():
            print(f"pyOMA2  {key:<7}: wall {r['wall_s']:7.3f} s  cpu {r['cpu_s']:7.3f} s  peak +{r['peak_mb']:7.1f} MB")
        py_hits = {f0: found(py["x1"]["stable_f"], py["x1"]["stable_o"], f0, n_orders) for f0 in truth}
        both = [f0 for f0 in truth if rf_hits[f0] is not None and py_hits[f0] is not None]
        agree = [f0 for f0 in both if abs(rf_hits[f0] - py_hits[f0]) <= 0.003 * f0]
        print(f"pyOMA2 finds {sum(v is not None for v in py_hits.values())}/{truth.size}; found by both: {len(both)}, "
              f"agreeing within 0.3 %: {len(agree)}")
        for f0 in (f0 for f0 in both if f0 not in agree):
            print(f"  apart by > 0.3 %: truth {f0:.2f} Hz, ringfit {rf_hits[f0]:.2f} ({100 * (rf_hits[f0] / f0 - 1):+.2f} %), "
                  f"pyOMA2 {py_hits[f0]:.2f} ({100 * (py_hits[f0] / f0 - 1):+.2f} %)")
        missing = [f"{f0:.1f}" for f0 in truth if (rf_hits[f0] is None) != (py_hits[f0] is None)]
        if missing:
            print("  found by only one tool: " + ", ".join(missing) + " Hz")
        ratios = {"one core (pyOMA2 x1 / ringfit x1)": (py["x1"], rf["x1"]),
                  "issue's setting (pyOMA2 x1 / ringfit default)": (py["x1"], rf["default"]),
                  "whole machine (pyOMA2 at its best / ringfit default)":
                      (min(py.values(), key=lambda r: r["wall_s"]), rf["default"])}
        for label, (a_, b_) in ratios.items():
            print(f"time ratio, {label}: wall {a_['wall_s'] / b_['wall_s']:.1f}x, cpu {a_['cpu_s'] / b_['cpu_s']:.1f}x")
        ratio_m = py["x1"]["peak_mb"] / max(rf["default"]["peak_mb"], 1e-3)
        print(f"memory ratio (tracemalloc peak, pyOMA2 x1 / ringfit default): {ratio_m:.1f}x")
        summary.append((case, [a_["wall_s"] / b_["wall_s"] for a_, b_ in ratios.values()], ratio_m, len(agree),
                        truth.size))
        print(load())
    if summary:
        print("\n== summary: wall-time ratios pyOMA2 / ringfit (one core | issue's setting | whole machine)")
        for case, rw, rm, n_agree, n_truth in summary:
            print(f"case ({case}): {rw[0]:5.1f}x | {rw[1]:5.1f}x | {rw[2]:5.1f}x   memory {rm:5.1f}x  "
                  f"same modes {n_agree}/{n_truth}")
    if args.no_growth:
        bc.finish()
        return
    data = tmp / "a.npz"
    if not data.exists():
        make_case("a", data)
    print("\n== ringfit cost growth on case (a) data (4 s; default workers; wall s, best of 3)")
    base = run_worker("ringfit", data, repeats=3, stages=True)

    def row(label, r):
        st = ", ".join(f"{k} {v:.3f}" for k, v in r["stages"].items())
        return f"{label}: {r['wall_s']:6.3f} s  +{r['peak_mb']:6.1f} MB   ({st})"

    for ch in (32, 64, 128):
        r = base if ch == 128 else run_worker("ringfit", data, channels=ch, repeats=3, stages=True)
        print(row(f"channels   {ch:4d}", r))
    for br in (20, 30, 40):
        r = base if br == BLOCK_ROWS else run_worker("ringfit", data, block_rows=br, repeats=3, stages=True)
        print(row(f"block rows {br:4d}", r))
    for om in (80, 160, 240):
        r = base if om == ORDMAX else run_worker("ringfit", data, ordmax=om, repeats=3, stages=True)
        print(row(f"max order  {om:4d}", r))
    bc.finish()


if __name__ == "__main__":
    main()
