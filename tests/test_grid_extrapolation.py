"""Richardson's rule on a fit's own grid moves (docs/physics.md §11 and §13.4 *the model's grid*): one function,
``ringfit.fit.result.richardson_tail``, that identify's grid check and the state estimate both use — checked here
against the rule written out by hand, and against a sequence whose limit is known."""

from __future__ import annotations

import numpy as np
import pytest

from ringfit.fit.result import RICHARDSON_RHO, richardson_tail


@pytest.mark.parametrize("order", [1, 2, 3, 4])
def test_the_tail_of_a_power_law_error_is_its_remaining_move(order):
    """An error e(h) = c·hᵖ of grid step h: the moves M → 2M and 2M → 4M are c(1 − 2⁻ᵖ)hᵖ and c(2⁻ᵖ − 4⁻ᵖ)hᵖ; the
    move still to come beyond 4M is c·4⁻ᵖ·hᵖ, which the tail recovers exactly for 1 ≤ p ≤ 4 (ρ = 2ᵖ inside
    the clip), in any metric."""
    c = np.array([0.3, -1.2, 0.05])
    e = lambda h: c * h**order  # noqa: E731
    step_a, step_b = e(0.5) - e(1.0), e(0.25) - e(0.5)  # the optimum's moves: what is left shrinks
    cov = np.array([[2.0, 0.3, 0.0], [0.3, 1.0, 0.1], [0.0, 0.1, 0.5]])
    tail = richardson_tail(step_a, step_b, cov)
    assert tail == pytest.approx(e(0.0) - e(0.25), rel=1e-12, abs=1e-15)


def test_the_ratio_is_clipped_to_a_first_and_a_fourth_order_error():
    """ρ below 2 (a move that does not shrink: no asymptotic order) is taken as 2 — the tail as large as the last
    move — and above 16 as 16; ρ measured in the covariance's metric (Mahalanobis), not Euclidean."""
    b = np.array([1.0, 0.0])
    assert richardson_tail(1.2 * b, b, np.eye(2)) == pytest.approx(b / (RICHARDSON_RHO[0] - 1.0))
    assert richardson_tail(100 * b, b, np.eye(2)) == pytest.approx(b / (RICHARDSON_RHO[1] - 1.0))
    # the same two moves, in a metric that shrinks the first direction: ρ = 3 there (a has its size in the second)
    a = np.array([0.0, 3.0])
    cov = np.diag([1.0, 1.0])
    assert richardson_tail(a, b, cov) == pytest.approx(b / 2.0)
    cov = np.diag([1.0, 9.0])  # a's length in this metric is 1: ρ = 1, clipped to 2
    assert richardson_tail(a, b, cov) == pytest.approx(b / 1.0)


def test_grid_moves_steps_each_halving_and_extrapolates_the_rest():
    """A linear least-squares fit (rows r = J u − y, so a change Δr at the fit moves the optimum by −J⁺Δr exactly)
    whose data rows change with the grid as a second-order error: the steps are the exact optimum moves of each
    halving, and step + tail reaches the continuum's optimum."""
    from types import SimpleNamespace

    from ringfit.fit.result import grid_moves

    rng = np.random.default_rng(3)
    J = rng.standard_normal((30, 3))
    y0, dy = rng.standard_normal(30), rng.standard_normal(30)
    rows_at = lambda h, u: J @ u - (y0 + dy * h**2)  # noqa: E731  (the grid's error ∝ h²)
    u_star = lambda h: np.linalg.lstsq(J, y0 + dy * h**2, rcond=None)[0]  # noqa: E731
    fit = SimpleNamespace(jacobian=J, residuals=rows_at(1.0, u_star(1.0)), covariance_log=np.linalg.inv(J.T @ J))
    steps, tail = grid_moves(fit, [rows_at(h, u_star(1.0)) for h in (1.0, 0.5, 0.25)])
    assert steps[0] == pytest.approx(u_star(0.5) - u_star(1.0), abs=1e-12)
    assert steps[1] == pytest.approx(u_star(0.25) - u_star(0.5), abs=1e-12)
    assert u_star(1.0) + sum(steps) + tail == pytest.approx(u_star(0.0), abs=1e-12)
