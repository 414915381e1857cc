"""NumPy front end: from impact records to mode tables (no JAX).

One concept per module: :mod:`~ringfit.targets.preprocessing` (impact
alignment, group-velocity sync), :mod:`~ringfit.targets.decimation`,
:mod:`~ringfit.targets.ssi` (covariance-driven SSI), :mod:`~ringfit.targets.stabilization`,
:mod:`~ringfit.targets.clustering`, :mod:`~ringfit.targets.shapes` (n,
travelling waves, real shapes, acoustic flag), :mod:`~ringfit.targets.frf`
(H1, coherence, peak picking) and :mod:`~ringfit.targets.identify` (the chains
end to end: :func:`~ringfit.targets.identify.ssi_modes`,
:func:`~ringfit.targets.frf.frf_modes`). Axis order: ``(channels, samples)``.
"""
