"""The engine's two-stage models (:class:`ringfit.fit.engine.AbstractResiduals` ``readout``): a linearisation that
passes only the inner stage's slots through the inner stage gives the one-stage Jacobian (checked against central
differences too), in the caller's order of the free set, and the same fits."""

import jax.numpy as jnp
import numpy as np
import pytest

from ringfit.fit.engine import LINEAR, LOG, AbstractResiduals, Coordinate, Problem, least_squares, linearize

X = np.linspace(0.0, 3.0, 40)


def _inner(theta):
    return jnp.exp(-theta[0] * X) * jnp.sin(theta[1] * X)


def _outer(inner, theta):
    return theta[2] * inner + theta[3] * inner**2  # nonlinear in the inner stage: the chain rule matters


class OneStage(AbstractResiduals):
    compile_quick = True  # small: compiled quickly (two free-set sizes, 4 and 6, for both models)

    def __call__(self, theta, data):
        pred = _outer(_inner(theta), theta)
        return pred - data, pred


class TwoStage(OneStage):
    readout = (2, 3)

    def inner(self, theta, data):
        return _inner(theta)

    def outer(self, inner, theta, data):
        pred = _outer(inner, theta)
        return pred - data, pred


COORDS = (Coordinate("a", LOG), Coordinate("b", LOG), Coordinate("gain", LOG, lo=0.5, hi=2.0),
          Coordinate("curv", LINEAR, scale=0.1))
THETA = np.array([0.7, 2.1, 1.2, 0.05])
Y = np.asarray(_outer(_inner(np.array([0.5, 2.4, 0.9, -0.1])), np.array([0.5, 2.4, 0.9, -0.1])))


def _u_fd(theta, free, h=1e-6):
    """Central differences of the residuals in the solver coordinates u (ln θ or θ/scale), written here."""
    cols = []
    for name in free:
        i = [c.name for c in COORDS].index(name)
        step = np.zeros(4)
        step[i] = h
        if COORDS[i].kind == LOG:
            hi, lo = theta * np.exp(step), theta * np.exp(-step)
        else:
            hi, lo = theta + step * COORDS[i].scale, theta - step * COORDS[i].scale
        f = lambda t: np.asarray(_outer(_inner(t), t)) - Y  # noqa: E731
        cols.append((f(hi) - f(lo)) / (2 * h))
    return np.stack(cols, axis=1)


@pytest.mark.parametrize("free,pad", [(("a", "gain", "b", "curv"), None), (("gain", "a", "curv", "b"), 6),
                                      (("curv", "a"), 4), (("b",), 4)])
def test_two_stage_jacobian_is_the_one_stage_jacobian_in_the_callers_order(free, pad):
    one = linearize(Problem(OneStage(), Y, COORDS), THETA, free, pad_to=pad)
    two = linearize(Problem(TwoStage(), Y, COORDS), THETA, free, pad_to=pad)
    assert two.names == free
    np.testing.assert_allclose(two.residuals, one.residuals, rtol=0, atol=1e-14)
    np.testing.assert_allclose(two.jacobian, one.jacobian, rtol=0, atol=1e-12)
    np.testing.assert_allclose(two.jacobian, _u_fd(THETA, free), rtol=0, atol=1e-7)


def test_two_stage_fit_is_the_one_stage_fit():
    free = ("gain", "a", "curv", "b")
    one = least_squares(Problem(OneStage(), Y, COORDS), THETA, free, pad_to=6)
    two = least_squares(Problem(TwoStage(), Y, COORDS), THETA, free, pad_to=6)
    assert one.converged and two.converged and two.names == free
    np.testing.assert_allclose(two.theta, one.theta, rtol=1e-9)
    np.testing.assert_allclose(two.theta, [0.5, 2.4, 0.9, -0.1], rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(two.covariance_log, one.covariance_log, rtol=1e-8, atol=1e-14)


def test_two_stage_refuses_more_inner_parameters_than_its_slots():
    """K = 3 slots, 2 readout parameters: one slot for the inner stage, so two inner parameters are refused."""
    with pytest.raises(ValueError, match="two-stage model takes at most 1"):
        linearize(Problem(TwoStage(), Y, COORDS), THETA, ("a", "b", "gain"))
