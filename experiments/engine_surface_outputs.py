"""Before/after check of the engine's public surface (issue 22 item 4): run fit, roll, fit-rolling and
diagnose on the bundled data and on `ringfit example case`, and compare every number with a reference run.

    python experiments/engine_surface_outputs.py OUT_DIR            # write outputs
    python experiments/engine_surface_outputs.py OUT_DIR --compare REF_DIR

Numbers are compared to a relative 1e-6 (+1e-9 absolute): the refactor moves code, not arithmetic, but
evaluating a Jacobian by its own compiled region may differ from the zero-step solve in the last bits.
"""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

RINGFIT = [sys.executable, "-m", "ringfit"]
DATA = Path(__file__).resolve().parents[1] / "ringfit" / "data"


def run(*args):
    subprocess.run([*RINGFIT, *map(str, args)], check=True, stdout=subprocess.DEVNULL)


def produce(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    run("fit", DATA / "free-ssi.modes.csv", "--tyre", DATA / "table9.tyre.toml", "--out", out / "fitted.tyre.toml",
        "--force")
    run("roll", "--tyre", out / "fitted.tyre.toml", "--speed", 40, "--load", 4000, "--out", out / "sim.profile.csv",
        "--force")
    run("example", "case", "--out", out / "example", "--force")
    run("fit-rolling", out / "sim.profile.csv", "--tyre", out / "fitted.tyre.toml", "--out", out / "fr.tyre.toml",
        "--force")
    run("diagnose", out / "example" / "case", "--out", out / "case.diagnosis.json", "--force")


NUM = re.compile(r"-?\d+\.\d+(?:[eE][-+]?\d+)?|-?\d+[eE][-+]?\d+")


def numbers(text: str) -> list[float]:
    return [float(x) for x in NUM.findall(text)]


def _strip_timings(x):
    if isinstance(x, dict):
        return {k: _strip_timings(v) for k, v in x.items() if k != "elapsed_s"}
    if isinstance(x, list):
        return [_strip_timings(v) for v in x]
    return x


def _text(path: Path) -> str:
    """The file's text; JSON without its wall-clock timings (``elapsed_s``)."""
    if path.suffix == ".json":
        return json.dumps(_strip_timings(json.loads(path.read_text())))
    return path.read_text()


def compare(out: Path, ref: Path) -> int:
    bad = 0
    for f in sorted(ref.rglob("*")):
        if not f.is_file() or f.suffix in (".png", ".html", ".h5", ".npz"):
            continue
        g = out / f.relative_to(ref)
        a, b = numbers(_text(f)), numbers(_text(g))
        if len(a) != len(b):
            print(f"DIFF {f.relative_to(ref)}: {len(a)} vs {len(b)} numbers")
            bad += 1
            continue
        worst = max((abs(x - y) / (1e-9 + 1e-6 * abs(x)) for x, y in zip(a, b)
                     if not (math.isnan(x) and math.isnan(y))), default=0.0)
        print(f"{'ok  ' if worst <= 1 else 'DIFF'} {f.relative_to(ref)}: {len(a)} numbers, worst {worst:.3g} × tol")
        bad += worst > 1
    return bad


if __name__ == "__main__":
    out = Path(sys.argv[1])
    produce(out)
    if "--compare" in sys.argv:
        sys.exit(1 if compare(out, Path(sys.argv[sys.argv.index("--compare") + 1])) else 0)
