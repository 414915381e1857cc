"""Generators of synthetic data with known truth (records, profiles, cases), for tests, demos and benchmarks.

JAX computes in float64 here even when ``ringfit`` itself is shadowed (:mod:`ringfit._precision`).
"""

from ringfit._precision import enable_x64

enable_x64()
