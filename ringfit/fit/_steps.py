"""The solver steps under :mod:`ringfit.fit.engine`: optimistix's Gauss–Newton family on a dense Jacobian.

:class:`_DenseSteps` is optimistix's ``AbstractGaussNewton.step`` (search, descent, Cauchy termination) with the
Jacobian built once per step as a dense matrix and Marquardt's scaling set in step one; :data:`SOLVERS` are its
Levenberg–Marquardt and Gauss–Newton forms. The engine's public surface (problems, coordinates, results) stays in
:mod:`ringfit.fit.engine`; this module holds only the steps, which follow optimistix 0.1.x
(``tests/test_optimistix_contract.py`` pins the release they copy).
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx
from optimistix._misc import cauchy_termination  # the Cauchy test optimistix's own Gauss–Newton step uses

#: Consecutive rejected steps after which a solve that has accepted at least two steps is at a minimum
#: to rounding: the trust region shrank by 4^STALL_STEPS without any decrease of the cost.
STALL_STEPS = 4


#: Diagonal of JᵀJ at the start in the solver's scaled variables (see :class:`_DenseSteps`).
JTJ_DIAGONAL = 1e3
#: Static cap on solver steps; the step limit of a call is traced (``least_squares(max_steps=…)``),
#: so every limit shares one compiled solve.
STEP_CAP = 100_000


def _limited_terminate(done, result, state, args):
    """Stop at the traced step limit ``max_steps`` and, after two accepted steps, after STALL_STEPS rejections.

    ``args`` = ``(max_steps, _, check_at, bounded, near_sin, dtol)``: a solve still running after ``check_at`` steps
    (> 0) whose accepted point has a bounded slot creeping onto its bound (``|sin z| ≥ near_sin``, z = s/scale:
    the engine's sine transform, ``ringfit.fit.engine.ACTIVE_SET_NEAR``) stops there too, reported as
    ``nonlinear_max_steps_reached`` (the engine's active set finishes it); otherwise it runs on uninterrupted."""
    max_steps, _, check_at, bounded, near_sin, _ = args
    stalled = (state.num_accepted_steps >= 2) & (state.num_steps_since_acceptance >= STALL_STEPS)
    creeping = jnp.any(bounded & (jnp.abs(jnp.sin(state.accepted / state.scale)) >= near_sin))
    at_check = (check_at > 0) & (state.num_steps == check_at) & creeping
    limit = ((state.num_steps >= jnp.maximum(max_steps, 1)) | at_check) & ~(done | stalled)
    result = optx.RESULTS.where(limit & (max_steps > 0), optx.RESULTS.nonlinear_max_steps_reached, result)
    return done | stalled | limit, result


def gauss_newton_decrement(residual: jax.Array, jac: jax.Array) -> jax.Array:
    """The Gauss–Newton decrement ``|J δ|²`` with ``δ = −J⁺ r``: the drop of the cost Σr² that the linearised rows
    promise to their own optimum (docs/physics.md §11 *convergence*). Invariant to a scaling of the columns of
    ``J`` (its columns are normalised first); columns of zeros (a padded free set) and directions ``JᵀJ`` does not
    resolve (eigenvalues under 1e-12 of its largest) are left out."""
    norms = jnp.sqrt(jnp.sum(jac**2, axis=0))
    jac = jac / jnp.where(norms > 0, norms, 1.0)[None, :]
    g = jac.T @ residual
    w, v = jnp.linalg.eigh(jac.T @ jac)
    keep = w > 1e-12 * jnp.max(w)
    c = v.T @ g
    return jnp.sum(jnp.where(keep, c**2 / jnp.where(keep, w, 1.0), 0.0))


class _DenseState(eqx.Module):
    """optimistix's Gauss–Newton state (same fields, same meaning) plus the variable scaling ``scale`` (d) and the
    last accepted point ``accepted`` (for the creep check of :func:`_limited_terminate`)."""

    first_step: jax.Array
    y_eval: jax.Array
    search_state: object
    f_info: optx.FunctionInfo.ResidualJac
    aux: object
    descent_state: object
    terminate: jax.Array
    result: optx.RESULTS
    num_steps: jax.Array
    num_accepted_steps: jax.Array
    num_steps_since_acceptance: jax.Array
    scale: jax.Array
    #: the last accepted point (optimistix's loop passes ``terminate`` the point before the step)
    accepted: jax.Array


class _DenseSteps:
    """The step of optimistix's Gauss–Newton family on a dense Jacobian, with Marquardt's scaling set in step one.

    ``fn(s, (max_steps, d, …)) -> (residuals, (aux, J_z))`` evaluates the model at ``z = s / d`` and returns its
    Jacobian in z (:func:`_linearisation`); the step builds the Jacobian in s, ``J_z / d``, as a matrix
    operator, so every further product in the step (trust region, damped solve) is a small matrix product.
    Otherwise the step is optimistix's ``AbstractGaussNewton.step`` (search, descent, Cauchy termination).

    **Scaling** (``scaled``, Levenberg–Marquardt): the solver works on ``s = d·z`` with ``d`` ∝ the Jacobian's
    column norms at the start (Marquardt's scaling, scipy's ``x_scale="jac"``): the damping then acts alike
    on every direction; the diagonal of JᵀJ in s is :data:`JTJ_DIAGONAL`, so optimistix's initial damping
    λ = 1 starts near Gauss–Newton (λ/diag = 1e-3). The solve starts at ``s = z0`` with ``d = 1``; the first
    step's linearisation at z0 gives the norms, and the step then moves its start and that linearisation
    to s (``s0 = d·z0``, ``J_z / d``) before its search and descent, which therefore see what a solve started
    at ``d·z0`` with ``d`` known would see. One program, one linearisation per step, one copy of the model.
    A step limit of 0 (evaluate only) keeps ``d = 1``. Gauss–Newton is invariant to the scaling: ``d = 1``.
    """

    scaled: ClassVar[bool] = False

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        del fn, args, options
        f_info = optx.FunctionInfo.ResidualJac(jnp.zeros(f_struct.shape, f_struct.dtype),
                                               lx.MatrixLinearOperator(jnp.zeros(f_struct.shape + y.shape, y.dtype),
                                                                       tags))
        return _DenseState(
            first_step=jnp.array(True), y_eval=y, search_state=self.search.init(y, f_info), f_info=f_info,
            aux=jax.tree.map(lambda s: jnp.zeros(s.shape, s.dtype), aux_struct),
            descent_state=self.descent.init(y, f_info), terminate=jnp.array(False), result=optx.RESULTS.successful,
            num_steps=jnp.array(0), num_accepted_steps=jnp.array(0), num_steps_since_acceptance=jnp.array(0),
            scale=jnp.ones_like(y), accepted=y)

    def step(self, fn, y, args, options, state, tags):
        max_steps = args[0]
        res, fn_aux = fn(state.y_eval, (max_steps, state.scale, *args[2:]))
        jac_z = fn_aux[1]
        if self.scaled:
            norms = jnp.sqrt(jnp.sum(jac_z**2, axis=0))
            fresh = jnp.where(norms > 0, norms, 1.0) / jnp.sqrt(JTJ_DIAGONAL)
            scale = jnp.where(state.first_step & (max_steps > 0), fresh, state.scale)
            # the first step: its start (y = y_eval = z0) moves to s0 = d·z0
            y_eval = jnp.where(state.first_step, state.y_eval * scale, state.y_eval)
            y = jnp.where(state.first_step, y * scale, y)
        else:
            scale, y_eval = state.scale, state.y_eval
        f_eval_info = optx.FunctionInfo.ResidualJac(res, lx.MatrixLinearOperator(jac_z * (1.0 / scale)[None, :],
                                                                                 tags))
        step_size, accept, search_result, search_state = self.search.step(
            state.first_step, y, y_eval, state.f_info, f_eval_info, state.search_state)
        num_steps = state.num_steps + 1
        num_accepted_steps = state.num_accepted_steps + jnp.where(accept, 1, 0)
        num_steps_since_acceptance = jnp.where(accept, 0, state.num_steps_since_acceptance + 1)

        def accepted(descent_state):
            descent_state = self.descent.query(y_eval, f_eval_info, descent_state)
            terminate = cauchy_termination(self.rtol, self.atol, self.norm, y_eval, y_eval - y, f_eval_info.residual,
                                            f_eval_info.residual - state.f_info.residual)
            dtol = args[5]
            near = jax.lax.cond(dtol > 0, lambda: gauss_newton_decrement(res, jac_z) < dtol, lambda: jnp.array(False))
            return y_eval, f_eval_info, fn_aux, descent_state, terminate | near

        def rejected(descent_state):
            return y, state.f_info, state.aux, descent_state, jnp.array(False)

        y, f_info, aux, descent_state, terminate = jax.lax.cond(accept, accepted, rejected, state.descent_state)
        y_descent, descent_result = self.descent.step(step_size, descent_state)
        result = optx.RESULTS.where(search_result == optx.RESULTS.successful, descent_result, search_result)
        prev_aux = jax.tree.map(lambda new, old: jnp.where(state.first_step, new, old), aux, state.aux)
        state = _DenseState(
            first_step=jnp.array(False), y_eval=y + y_descent, search_state=search_state, f_info=f_info, aux=aux,
            descent_state=descent_state, terminate=terminate, result=result, num_steps=num_steps,
            num_accepted_steps=num_accepted_steps, num_steps_since_acceptance=num_steps_since_acceptance,
            scale=scale, accepted=y)
        return y, state, prev_aux

    def terminate(self, fn, y, args, options, state, tags):
        return _limited_terminate(state.terminate, state.result, state, args)


class _LevenbergMarquardt(_DenseSteps, optx.LevenbergMarquardt):
    """optimistix Levenberg–Marquardt on a dense Jacobian (:class:`_DenseSteps`, with Marquardt's scaling),
    with a traced step limit and a stop when it stalls at a minimum.

    - The step limit is ``args[0]`` (a traced integer): reaching it without convergence
      reports ``nonlinear_max_steps_reached``, as optimistix's own ``max_steps`` does.
      A limit of 0 evaluates the residuals, Jacobian and aux at the start and stops
      (:func:`evaluate`).
    - Near the optimum of a model that is smooth only to rounding (the contact solve's
      active set, float64 sums over thousands of rows) every further Gauss–Newton step
      raises the cost by ~1e-12 relative; the trust region then shrinks until the step is
      below the Cauchy tolerances, which can take twenty wasted linearisations. After at
      least two accepted steps, :data:`STALL_STEPS` rejections in a row end the solve at
      the last accepted point (reported as converged).
    """

    scaled: ClassVar[bool] = True


class _GaussNewton(_DenseSteps, optx.GaussNewton):
    """optimistix Gauss–Newton on a dense Jacobian with the same traced step limit (every step is accepted)."""


#: Solvers of :func:`least_squares`: Levenberg–Marquardt (the default; trust region, robust from far
#: away) and undamped Gauss–Newton (every step taken: for well-started fits, e.g. warm-started
#: sequences, it stops as soon as the steps are small, where Levenberg–Marquardt may spend steps
#: rejecting round-off-sized trial steps before its tolerance test runs).
SOLVERS = {"levenberg_marquardt": _LevenbergMarquardt, "gauss_newton": _GaussNewton}
