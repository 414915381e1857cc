"""Render the tutorials' figures: run every notebook that saves a figure and keep its PNGs in docs/figures/.

The documentation site does not execute the notebooks (JAX compiles for minutes); it shows the figures this
script saved the last time it ran. Each notebook writes its figures to ``RINGFIT_NOTEBOOK_OUT``; the script runs
it in a temporary folder with that variable set (``MPLBACKEND=Agg``, as ``tests/test_notebooks.py`` does) and copies
every PNG it wrote to ``docs/figures/<notebook stem>/``, replacing that folder whole (a figure a notebook no longer
saves goes). :func:`gen_pages.notebook_markdown` then puts each figure under the code cell that saves it.

Run after changing a notebook or a plot::

    python docs/_gen/render_figures.py            # every notebook that saves a figure
    python docs/_gen/render_figures.py 05 09      # the notebooks whose names start so

``tests/test_docs.py`` checks that every figure a notebook saves under a literal name has its rendered PNG here.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
NOTEBOOKS = ROOT / "notebooks"
FIGURES = ROOT / "docs" / "figures"
#: a figure saved under a literal name: ``OUT / "name.png"`` (an f-string name is not resolved here)
SAVED = re.compile(r"""OUT\s*/\s*["']([^"'{}]+\.png)["']""")


def saved_figures(source: str) -> list[str]:
    """PNG names a notebook's (or one cell's) source saves under ``OUT`` with a literal name, in order."""
    return list(dict.fromkeys(SAVED.findall(source)))


def _compact(src: Path, dst: Path) -> Path:
    """``src`` as a 256-colour PNG at ``dst`` (a plot has few colours: a third of the bytes, the same look)."""
    from PIL import Image  # matplotlib's own dependency

    with Image.open(src) as im:
        im.convert("RGB").quantize(256, dither=Image.Dither.NONE).save(dst, optimize=True)
    return dst


def render(notebook: Path) -> list[Path]:
    """Run ``notebook`` in a temporary folder and keep its PNGs in ``docs/figures/<stem>/``; returns them."""
    with tempfile.TemporaryDirectory() as tmpd:
        tmp = Path(tmpd)
        env = dict(os.environ, MPLBACKEND="Agg", RINGFIT_NOTEBOOK_OUT=str(tmp))
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, str(notebook)], cwd=tmp, env=env, capture_output=True, text=True)
        if proc.returncode:
            raise SystemExit(f"{notebook.name} failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
        pngs = sorted(tmp.rglob("*.png"))
        dest = FIGURES / notebook.stem
        shutil.rmtree(dest, ignore_errors=True)
        dest.mkdir(parents=True)
        kept = []
        for p in pngs:
            kept.append(_compact(p, dest / p.name))
        print(f"{notebook.name}: {len(kept)} figure(s) in {time.perf_counter() - t0:.0f} s -> "
              f"{dest.relative_to(ROOT)}", flush=True)
        return kept


def main(argv: list[str]) -> int:
    books = [p for p in sorted(NOTEBOOKS.glob("*.py")) if saved_figures(p.read_text())]
    if argv:
        books = [p for p in books if any(p.name.startswith(a) for a in argv)]
        if not books:
            print(f"no notebook that saves a figure starts with {', '.join(argv)}", file=sys.stderr)
            return 2
    for p in books:
        render(p)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
