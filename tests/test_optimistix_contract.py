"""The optimistix internals the engine builds on, pinned (issue 31 item 4).

:class:`ringfit.fit._steps._DenseSteps` is optimistix's ``AbstractGaussNewton.step`` with a dense Jacobian and
Marquardt's scaling set in step one; it calls ``optimistix._misc.cauchy_termination`` and carries the Gauss–Newton
state's fields plus ``scale``. pyproject pins the tested range (``optimistix>=0.1.0,<0.2``); this test fails when an
installed optimistix differs from the release the step was written against, so that an upgrade is a reviewed
change (re-read the upstream step, update ``_DenseSteps`` and the fingerprint), never a silent drift."""

import hashlib
import inspect

import optimistix as optx

import ringfit  # noqa: F401  (x64)
from ringfit.fit import _steps as engine

#: sha256 (first 16 hex) of ``inspect.getsource(optx.AbstractGaussNewton.step)`` in optimistix 0.1.0.
UPSTREAM_STEP = "3d7630405579a4c5"


def test_upstream_gauss_newton_step_is_the_one_dense_steps_follows():
    src = inspect.getsource(optx.AbstractGaussNewton.step)
    got = hashlib.sha256(src.encode()).hexdigest()[:16]
    assert got == UPSTREAM_STEP, (
        f"optimistix {optx.__version__}: AbstractGaussNewton.step changed (fingerprint {got}); re-read it, bring "
        "ringfit.fit._steps._DenseSteps.step in line, then update UPSTREAM_STEP")
    for call in ("self.search.step", "self.descent.query", "self.descent.step", "cauchy_termination"):
        assert call in src and call in inspect.getsource(engine._DenseSteps.step)


def test_cauchy_termination_signature():
    from optimistix._misc import cauchy_termination

    assert list(inspect.signature(cauchy_termination).parameters) == ["rtol", "atol", "norm", "y", "y_diff", "f",
                                                                      "f_diff"]


def test_dense_state_is_the_gauss_newton_state_plus_scale_and_the_accepted_point():
    from optimistix._solver.gauss_newton import _GaussNewtonState

    upstream = list(_GaussNewtonState.__dataclass_fields__)
    ours = list(engine._DenseState.__dataclass_fields__)
    assert ours == upstream + ["scale", "accepted"]
