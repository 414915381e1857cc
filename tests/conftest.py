"""Test configuration: float64 everywhere, strict promotion, headless plots."""

import os

os.environ.setdefault("MPLBACKEND", "Agg")

import jax  # noqa: E402

import ringfit  # noqa: E402,F401  (enables jax_enable_x64)

jax.config.update("jax_numpy_dtype_promotion", "standard")
assert jax.config.jax_enable_x64, "importing ringfit must enable float64"
