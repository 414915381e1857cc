"""Gap diagnosis on the source study's free-tyre table (Table 2, SSI): what remains after the eq. 18 fit?

The case folder is built from the bundled data: Table 9's tyre, the SSI modes
as ``free.modes.csv``. The frequency noise is taken from the data in a way the
diagnosis cannot do alone: the same nine modes were identified twice (SSI and
FRF peak picking, Table 2), so σ_f ≈ std(f_SSI − f_FRF)/√2. The question is
whether ``cavity_mode`` or ``ring_extensibility`` (the two effects that act
on a free, static tyre's frequencies) claims any of what remains.

Run: ``python experiments/gap_free_tyre.py [--report out.html]``.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

import ringfit  # noqa: F401
from ringfit.data import path as data_path
from ringfit.gap import diagnose
from ringfit.io.modes import read_mode_table


def main(report: str | None = None):
    ssi, frf = read_mode_table(data_path("free-ssi.modes.csv")), read_mode_table(data_path("free-frf.modes.csv"))
    common = sorted(set(ssi.n[ssi.n >= 0]) & set(frf.n[frf.n >= 0]))
    d = np.array([ssi.freq_hz[ssi.n == n][0] - frf.freq_hz[frf.n == n][0] for n in common])
    sigma = float(np.std(d, ddof=1) / np.sqrt(2.0))
    print(f"frequency noise from SSI vs FRF (n = {common[0]}..{common[-1]}): sigma = {sigma:.2f} Hz")
    with tempfile.TemporaryDirectory() as tmp:
        case = Path(tmp) / "free-tyre"
        case.mkdir()
        shutil.copy(data_path("table9.tyre.toml"), case / "tyre.toml")
        shutil.copy(data_path("free-ssi.modes.csv"), case / "free.modes.csv")
        shutil.copy(data_path("free-ssi.modes.json"), case / "free.modes.json")
        for noise in (None, {"freq_hz": sigma}):
            diag = diagnose(case, progress=False, noise=noise)
            c = diag.content
            print(f"\nnoise: {c['baseline']['noise_method']}")
            print(f"baseline RMS {c['baseline']['rms']} ({c['baseline']['unit']}), held-out {c['baseline']['heldout_rms']},"
                  f" reduced chi2 {c['baseline']['reduced_chi2']}")
            print("where:", ", ".join(f"{w['region']} {100 * w['share']:.0f}%" for w in c["where"]))
            for cand in c["candidates"]:
                print(f"  {cand['effect']:20s} held-out shrink {cand['heldout_shrink_pct']:6.1f}%  "
                      f"dBIC {cand['evidence']['delta_bic']}  params {cand['params']}")
            print("verdict:", c["verdict"]["effects"])
        if report:
            from ringfit.report.gap_report import write_gap_report

            write_gap_report(diag, report, overwrite=True)
            print("wrote", report)


if __name__ == "__main__":
    main(sys.argv[sys.argv.index("--report") + 1] if "--report" in sys.argv else None)
