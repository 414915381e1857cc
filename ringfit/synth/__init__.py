"""Generators of synthetic data with known truth (records, profiles, cases), for tests, demos and benchmarks."""
