"""Matplotlib plumbing shared by every ringfit figure and HTML report.

``new_figure`` creates a figure on the Agg backend without touching pyplot's
global state; ``png_data_uri`` turns a figure into an embeddable
``data:image/png;base64,...`` string, so reports are single self-contained files.
"""

from __future__ import annotations

import base64
import io
import logging

# A missing font falls back to DejaVu Sans (shipped with matplotlib); matplotlib logs each fallback as a
# WARNING, which on a machine whose font cache lacks the mathtext fonts is a score of lines on stderr that
# would bury the one line an error or a warning of ours gives. The figure is drawn all the same.
logging.getLogger("matplotlib.font_manager").setLevel(logging.ERROR)


def pyplot():
    """``matplotlib.pyplot`` on the Agg backend (for code that still draws through pyplot)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def new_figure(nrows: int = 1, ncols: int = 1, *, figsize=(7, 4), layout=None, **kwargs):
    """``(fig, axes)`` on the Agg canvas; ``kwargs`` go to ``Figure.subplots``.

    With ``nrows = ncols = 1`` and no extra kwargs, ``axes`` is a single Axes. ``layout="constrained"`` keeps
    stacked panels' titles and axis labels apart (matplotlib's constrained layout).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    height_ratios = kwargs.pop("height_ratios", None)
    if height_ratios is not None:
        kwargs["gridspec_kw"] = {"height_ratios": height_ratios}
    fig = Figure(figsize=figsize, dpi=110, layout=layout)
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, **kwargs)
    return fig, axes


def blank_figure(figsize=(7, 4)):
    """A Figure with no axes on the Agg canvas (for libraries that add their own, e.g. corner)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=110)
    FigureCanvasAgg(fig)
    return fig


def png_bytes(fig, dpi: int = 110) -> bytes:
    """PNG encoding of a figure."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()


def png_data_uri(fig, dpi: int = 110) -> str:
    """``data:image/png;base64,...`` for an ``<img src=...>``."""
    return "data:image/png;base64," + base64.b64encode(png_bytes(fig, dpi)).decode("ascii")


def save_figure(fig, path, dpi: int = 110, *, overwrite: bool = True):
    """Save a figure to ``path`` atomically (format from the suffix)."""
    from pathlib import Path

    from ringfit.io.files import atomic_write, check_output_path

    path = check_output_path(path, overwrite=overwrite)
    fmt = Path(path).suffix.lstrip(".") or "png"
    atomic_write(path, lambda tmp: fig.savefig(tmp, format=fmt, dpi=dpi, bbox_inches="tight"))
    return path
