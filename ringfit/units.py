"""Unit conversions used across layers, each defined once (NumPy-free, JAX-free; the bottom layer)."""

from __future__ import annotations

#: m/s per km/h.
KMH = 1.0 / 3.6
