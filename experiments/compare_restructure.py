"""Before/after check of two moves of issue 22 item 4 — ``ringfit/fit/estimate.py`` split into a package, the
Campbell diagram moved from ``gap/campbell.py`` to ``physics/campbell.py`` — on ``ringfit example`` data:
run ``ringfit estimate`` and ``ringfit campbell`` and compare every number of the outputs with a reference run.

    python experiments/compare_restructure.py INPUTS OUT_DIR [--make-inputs] [--only campbell|estimate|recording]
    python experiments/compare_restructure.py INPUTS OUT_DIR --compare REF_DIR

INPUTS is made once (``--make-inputs``) so that both runs read the same files:
``ringfit example profiles``, ``ringfit example cleat`` (a continuous recording: averaged profile and every
revolution), ``ringfit example identify`` (a profile of its case) and ``ringfit example rolling`` (rolling
mode tables at 20/40/60 km/h). The estimate runs cover a fixed k_trd, a ``--k-tread-sd``, a tyre file with
``[ring.covariance]``, fewer harmonics and a coarser grid; the Campbell runs the sensor and fixed frames, a
drum, and the three rolling tables matched (data tolerance and a given one).

Produce the reference with the code before the change on ``PYTHONPATH`` (e.g. ``git archive`` of the
old commit), the new outputs with the new code. The split moves code, not arithmetic: every number must be
equal (the table prints the worst relative difference; the tolerance is 1e-12 relative, to allow for
nothing but the printing of floats).
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

RINGFIT = [sys.executable, "-m", "ringfit"]
COVARIANCE = """
[ring.covariance]
names = ["k_tread", "ei"]
ln = [[0.0025, 0.0], [0.0, 0.01]]
source = "experiments/compare_estimate_split.py"
"""


def run(*args):
    """Run one command; its exit status and error line go to ``OUT.status`` (a refusal is an output too)."""
    quiet = ["--quiet"] if args[0] != "campbell" else []  # campbell prints no progress
    done = subprocess.run([*RINGFIT, *map(str, args), *quiet, "--force"], stdout=subprocess.DEVNULL,
                          stderr=subprocess.PIPE, text=True)
    out = Path(str(args[list(args).index("--out") + 1]))
    out.with_name(out.name + ".status").write_text(f"exit {done.returncode}\n{done.stderr.strip()}\n")


def make_inputs(inputs: Path) -> None:
    for kind in ("profiles", "cleat", "identify", "rolling"):
        subprocess.run([*RINGFIT, "example", kind, "--out", str(inputs / kind), "--quiet", "--force"], check=True,
                       stdout=subprocess.DEVNULL)
    tyre = (inputs / "profiles" / "tyre.toml").read_text()
    (inputs / "covariance.tyre.toml").write_text(tyre.rstrip() + "\n" + COVARIANCE)


def produce(inputs: Path, out: Path, only: str | None = None) -> None:
    out.mkdir(parents=True, exist_ok=True)
    if only in (None, "campbell"):
        produce_campbell(inputs, out)
    if only in (None, "estimate"):
        produce_estimate(inputs, out)
    if only in (None, "recording"):
        produce_recording(inputs, out)


def produce_campbell(inputs: Path, out: Path) -> None:
    tyre = inputs / "rolling" / "rolling" / "tyre.toml"
    tables = [inputs / "rolling" / "rolling" / f"roll{v}.modes.csv" for v in (20, 40, 60)]
    run("campbell", "--tyre", tyre, "--load", 4000, "--speeds", "0:60:5", "--modes", *tables,
        "--out", out / "rolling.campbell.csv")
    run("campbell", "--tyre", tyre, "--load", 4000, "--speeds", "0:60:5", "--modes", *tables, "--tolerance", 0.01,
        "--out", out / "tol.campbell.csv")
    run("campbell", "--tyre", tyre, "--load", 3000, "--speeds", "0:80:10", "--frame", "fixed", "--drum", 1.2192,
        "--out", out / "drum-fixed.campbell.csv")


def produce_estimate(inputs: Path, out: Path) -> None:
    tyre = inputs / "profiles" / "tyre.toml"
    for name in ("run30", "run60"):
        run("estimate", inputs / "profiles" / f"{name}.profile.csv", "--tyre", tyre, "--out",
            out / f"{name}.estimate.json")
    p30 = inputs / "profiles" / "run30.profile.csv"
    run("estimate", p30, "--tyre", tyre, "--k-tread-sd", 0.1, "--out", out / "run30-sd.estimate.json")
    run("estimate", p30, "--tyre", inputs / "covariance.tyre.toml", "--out", out / "run30-cov.estimate.json")
    run("estimate", p30, "--tyre", tyre, "--harmonics", 24, "--grid", 384, "--out", out / "run30-k24.estimate.json")
    run("estimate", inputs / "identify" / "case" / "run2.profile.csv", "--tyre", tyre, "--k-tread-sd", 0.3,
        "--out", out / "identify-run2.estimate.json")


def produce_recording(inputs: Path, out: Path) -> None:
    run("estimate", inputs / "cleat" / "cleat.records.npz", "--tyre", inputs / "profiles" / "tyre.toml",
        "--out", out / "cleat.estimate.json", "--per-revolution", out / "cleat.revolutions.csv")


NUM = re.compile(r"-?(?:\d+\.\d*|\d*\.\d+|\d+)(?:[eE][-+]?\d+)?|nan|NaN")


def numbers(text: str) -> list[float]:
    return [float(x) for x in NUM.findall(text)]


def _strip(x):
    if isinstance(x, dict):
        return {k: _strip(v) for k, v in x.items() if k not in ("elapsed_s", "input", "tyre", "per_revolution_csv")}
    if isinstance(x, list):
        return [_strip(v) for v in x]
    return x


def _text(path: Path) -> str:
    """The file's text; JSON without wall-clock timings and paths."""
    if path.suffix == ".json":
        return json.dumps(_strip(json.loads(path.read_text())), sort_keys=True)
    return path.read_text()


def compare(out: Path, ref: Path) -> int:
    bad = 0
    print(f"| file | numbers | identical | worst relative difference |\n|---|---|---|---|")
    for f in sorted(ref.rglob("*")):
        if not f.is_file() or f.suffix in (".png", ".html"):
            continue
        g = out / f.relative_to(ref)
        a, b = numbers(_text(f)), numbers(_text(g))
        if len(a) != len(b):
            print(f"| {f.name} | {len(a)} vs {len(b)} | DIFF | — |")
            bad += 1
            continue
        same = sum(x == y or (math.isnan(x) and math.isnan(y)) for x, y in zip(a, b))
        worst = max((abs(x - y) / max(abs(x), 1e-300) for x, y in zip(a, b) if x != y
                     and not (math.isnan(x) and math.isnan(y))), default=0.0)
        print(f"| {f.name} | {len(a)} | {same} | {worst:.3g} |")
        bad += worst > 1e-12
    return bad


if __name__ == "__main__":
    inputs, out = Path(sys.argv[1]), Path(sys.argv[2])
    if "--make-inputs" in sys.argv:
        make_inputs(inputs)
    produce(inputs, out, sys.argv[sys.argv.index("--only") + 1] if "--only" in sys.argv else None)
    if "--compare" in sys.argv:
        sys.exit(1 if compare(out, Path(sys.argv[sys.argv.index("--compare") + 1])) else 0)
