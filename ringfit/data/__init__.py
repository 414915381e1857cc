"""The source study's measurements, bundled as ringfit's default dataset.

Files (copied from the seed thesis, see ``README.md`` here):
``free-ssi.modes.csv/.json`` and ``free-frf.modes.csv/.json`` (Table 2),
``table9.tyre.toml`` (Table 9), ``table10.csv`` (Table 10).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def path(name: str) -> Path:
    """Absolute path of a bundled data file, e.g. ``path("free-ssi.modes.csv")``."""
    p = Path(str(resources.files("ringfit.data").joinpath(name)))
    if not p.exists():
        raise FileNotFoundError(f"no bundled data file {name!r}; have {sorted(x.name for x in p.parent.iterdir())}")
    return p
