"""Rig files (issue 23 item 1): read time and exactness of each format against the npz.

Writes the example hammer records (48 records × 2 axes × 3200 samples plus
force, as `ringfit example records`) as npz, UFF58, NI TDMS (npTDMS), MATLAB
v5 (scipy.io), MATLAB v7.3 (h5py, MATLAB's header and column-major layout)
and CSV (+ channel map), reads each back through `ringfit.io.records.read_records`
(best of 3) and prints wall and CPU time, size, and the largest difference
from the npz's arrays. The issue sets no speed target; these are ours: the
binary formats read no slower than UFF58 (the reader they join) and CSV, a
text format, parses at >= 5 MiB/s; all read exactly (max |Δ| = 0; CSV's
17-digit decimal round trip <= 1e-12 relative).

    .venv/bin/python benchmarks/bench_rig_files.py
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("MPLBACKEND", "Agg")


def _mat73(path, rec):
    import h5py

    with h5py.File(path, "w", userblock_size=512) as f:
        for key, value in (("acc", rec.acc), ("sensor_angle_deg", rec.sensor_angle_deg[None, :]),
                           ("fs_hz", np.array([[rec.fs_hz]])), ("force", rec.force)):
            ds = f.create_dataset(key, data=np.asarray(value).T)
            ds.attrs["MATLAB_class"] = np.bytes_("double")
        width = max(map(len, rec.axes))
        codes = np.array([[ord(c) for c in a.ljust(width)] for a in rec.axes], dtype=np.uint16)
        ds = f.create_dataset("axes", data=codes.T)
        ds.attrs["MATLAB_class"] = np.bytes_("char")
    with open(path, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, written by bench_rig_files".ljust(116) + b"\x00" * 8 + b"\x00\x02IM")


def main() -> int:
    from ringfit.io.channel_map import write_channel_map
    from ringfit.io.csv_records import write_csv_records
    from ringfit.io.records import read_records, write_records
    from ringfit.synth.examples import _records

    load0 = os.getloadavg()
    print(f"load average at start: {load0[0]:.2f} {load0[1]:.2f} {load0[2]:.2f}")
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        _records(d, False)
        ref = read_records(d / "impact.records.npz")
        write_records(ref, d / "impact.tdms")
        write_records(ref, d / "impact.mat")
        _mat73(d / "impact73.mat", ref)
        _, cmap = write_csv_records(ref, d / "impact.csv")
        write_channel_map(cmap, d / "impact.channels.toml")
        cases = [("npz", "impact.records.npz", None), ("UFF58 (reference)", "impact.uff", None),
                 ("NI TDMS", "impact.tdms", None), ("MATLAB v5", "impact.mat", None),
                 ("MATLAB v7.3", "impact73.mat", None), ("CSV + map", "impact.csv", "impact.channels.toml")]
        rows = []
        for name, file, cm in cases:
            best_wall = best_cpu = float("inf")
            for _ in range(3):
                w0, c0 = time.perf_counter(), time.process_time()
                got = read_records(d / file, channels=None if cm is None else d / cm)
                best_wall = min(best_wall, time.perf_counter() - w0)
                best_cpu = min(best_cpu, time.process_time() - c0)
            diff = max(float(np.abs(got.acc - ref.acc).max()), float(np.abs(got.force - ref.force).max()))
            rel = diff / max(float(np.abs(ref.acc).max()), float(np.abs(ref.force).max()))
            rows.append((name, (d / file).stat().st_size / 2**20, best_wall, best_cpu, diff, rel))
    uff_wall = rows[1][2]
    print(f"\nexample records {ref.acc.shape} + force, read by ringfit.io.records.read_records (best of 3)\n")
    print("| format | size [MiB] | wall [s] | CPU [s] | vs UFF58 wall | max abs diff | max rel diff | target met |")
    print("|---|---|---|---|---|---|---|---|")
    ok_all = True
    for name, size, wall, cpu, diff, rel in rows:
        exact_ok = rel <= (1e-12 if name.startswith("CSV") else 0.0)
        if name.startswith("CSV"):
            fast_ok = size / wall >= 5.0
        else:
            fast_ok = wall <= uff_wall * 1.05 or name.startswith(("npz", "UFF"))
        ok = exact_ok and fast_ok
        ok_all &= ok
        print(f"| {name} | {size:.2f} | {wall:.3f} | {cpu:.3f} | {wall / uff_wall:.2f}× | {diff:.3g} | {rel:.3g} | "
              f"{'yes' if ok else 'NO'} |")
    load1 = os.getloadavg()
    print(f"\nload average at end: {load1[0]:.2f} {load1[1]:.2f} {load1[2]:.2f}")
    return 0 if ok_all else 1


if __name__ == "__main__":
    sys.exit(main())
