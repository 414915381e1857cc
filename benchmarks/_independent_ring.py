"""An independent discretisation of the steady rolling ring's radial reading, for truths that do not share
ringfit's spectral contact solve (issue 22 item 5; used by bench_estimate, tests/test_estimate.py,
_independent_effects and experiments/light_load_bias.py).

It lives in the package now, with the free and loaded modes of the same finite-difference ring and the joint
identification cases built on it (:mod:`ringfit.synth.independent`, issue 32 item 4); this module keeps the
names the benchmarks import. Nothing of ringfit's physics is used there.
"""

from __future__ import annotations

from ringfit.synth.independent import fd_profile, stencils as _stencils

__all__ = ["fd_profile", "_stencils"]
