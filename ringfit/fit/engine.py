"""The one least-squares engine of ringfit: every fit (free tyre, rolling profiles, identify, gap refits, load and
state estimates) runs here (docs/physics.md §14).

A fit is a *problem definition* handed to :func:`least_squares` (or :func:`least_squares_batch`): a residual model
(:class:`AbstractResiduals`, ``model(theta, data) -> (weighted residuals, aux)``), one :class:`Coordinate` per
parameter (ln θ for positive ones, bounds by the sine transform), the free set per call, and an optional Gaussian
prior on the coordinates (:class:`GaussianPrior`), bundled in a :class:`Problem`. The solve is one jitted region
(optimistix Levenberg–Marquardt with an SVD linear solve, the model linearised once per step by forward mode);
the covariance and flags after it are NumPy on small arrays. The result is a
:class:`~ringfit.fit.result.FitResult`, which never hides a solve that did not converge.

Example (an exponential decay, its rate bounded)::

    class Decay(AbstractResiduals):
        def __call__(self, theta, data):
            t, y, s = data
            model = theta[0] * jnp.exp(-theta[1] * t) + theta[2]
            return (model - y) / s, model

    t = np.linspace(0.0, 2.0, 25)
    y = 3.0 * np.exp(-1.3 * t) + 0.2 + 0.01 * np.random.default_rng(1).standard_normal(t.size)
    coords = (Coordinate("a", LOG), Coordinate("k", LOG, lo=0.01, hi=100.0), Coordinate("c", LINEAR, scale=0.1))
    fit = least_squares(Problem(Decay(), (t, y, np.full(t.size, 0.01)), coords), np.array([1.0, 1.0, 0.0]),
                        ("a", "k", "c"))
    fit.converged, fit.theta, fit.stderr    # True, [3.008, 1.297, 0.195], {'a': 0.0083, 'k': 0.0108, 'c': 0.0089}
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import ClassVar, Literal, get_args

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.special
import lineax as lx
import numpy as np
import optimistix as optx

from ringfit._cache import ExportedJit, jit
from ringfit._precision import require_x64
from ringfit.errors import InputError
from ringfit.fit._steps import SOLVERS, STEP_CAP
from ringfit.fit.result import (BatchFitResult, FitResult, covariance_batch, covariance_from_jacobian, parameter_flags,
                                solver_flags, solver_status)

LOG, LINEAR = "log", "linear"
#: How a problem's σ is known (:class:`Problem`).
SigmaMode = Literal["fixed", "estimate", "inflate"]
#: The solvers of :func:`least_squares` (:data:`ringfit.fit._steps.SOLVERS`).
SolverMethod = Literal["levenberg_marquardt", "gauss_newton"]


@dataclass(frozen=True)
class Coordinate:
    """How one model parameter θ is solved for.

    - ``name``: the parameter's name (key of ``FitResult.values``).
    - ``kind``: ``"log"`` (θ > 0, u = ln θ) or ``"linear"`` (u = (θ − center)/scale).
    - ``center``, ``scale``: of a linear coordinate (natural units).
    - ``lo``, ``hi``: bounds on θ (natural units; ±inf = none). A fit whose
      parameter ends within 1e-6 (in u) of a bound is flagged.
    """

    name: str
    kind: str = LOG
    center: float = 0.0
    scale: float = 1.0
    lo: float = -math.inf
    hi: float = math.inf

    def __post_init__(self):
        if self.kind not in (LOG, LINEAR):
            raise ValueError(f"coordinate {self.name}: kind must be 'log' or 'linear'")
        if not self.scale > 0:
            raise ValueError(f"coordinate {self.name}: scale must be positive")
        if not self.lo < self.hi:
            raise ValueError(f"coordinate {self.name}: need lo < hi")

    def to_u(self, theta):
        """Solver coordinate of ``theta`` (a float or an array)."""
        return np.log(theta) if self.kind == LOG else (theta - self.center) / self.scale

    def from_u(self, u):
        """Natural value of the solver coordinate ``u`` (a float or an array)."""
        return np.exp(u) if self.kind == LOG else self.center + self.scale * u

    @property
    def u_bounds(self) -> tuple[float, float]:
        if self.kind == LOG:
            lo = math.log(self.lo) if self.lo > 0 else -math.inf
            hi = math.log(self.hi) if math.isfinite(self.hi) else math.inf
            return lo, hi
        return (self.lo - self.center) / self.scale, (self.hi - self.center) / self.scale


@dataclass(frozen=True)
class GaussianPrior:
    """A Gaussian prior on the solver coordinates ``u`` of some parameters.

    ``names`` ``(r,)``; ``mean`` ``(r,)`` in u units (log for log parameters);
    ``cov`` ``(r, r)``. Parameters not listed have a flat prior (within bounds).
    """

    names: tuple[str, ...]
    mean: np.ndarray
    cov: np.ndarray

    @staticmethod
    def independent(entries: dict[str, tuple[float, float]]) -> "GaussianPrior":
        """From ``name -> (mean_u, sd_u)``."""
        names = tuple(entries)
        mean = np.array([entries[k][0] for k in names], dtype=np.float64)
        cov = np.diag(np.array([entries[k][1] for k in names], dtype=np.float64) ** 2)
        return GaussianPrior(names, mean, cov)

    def combine(self, other: "GaussianPrior | None") -> "GaussianPrior":
        """Block-diagonal union of two priors on disjoint parameters."""
        if other is None or not other.names:
            return self
        names = self.names + other.names
        cov = np.zeros((len(names), len(names)))
        r = len(self.names)
        cov[:r, :r], cov[r:, r:] = self.cov, other.cov
        return GaussianPrior(names, np.concatenate([self.mean, other.mean]), cov)

    def rows(self, free: tuple[str, ...], size: int) -> tuple[np.ndarray, np.ndarray]:
        """``(W (size, size), mean (size,))`` over the free slots: rows ``W (u_free − mean)``.

        The prior's marginal over the free parameters it covers, whitened by the
        inverse Cholesky factor; slots without a prior get zero rows.
        """
        W = np.zeros((size, size))
        mean = np.zeros(size)
        slots = [i for i, k in enumerate(free) if k in self.names]
        if slots:
            idx = [self.names.index(free[i]) for i in slots]
            L = np.linalg.cholesky(self.cov[np.ix_(idx, idx)])
            W[np.ix_(slots, slots)] = np.linalg.inv(L)
            mean[slots] = self.mean[idx]
        return W, mean


class AbstractResiduals(eqx.Module):
    """A residual model: ``model(theta, data) -> (residuals (m,), aux)``; fields are static configuration.

    ``serial_batches`` (class attribute): evaluate batches of parameter vectors (:func:`residuals_batch`,
    :func:`sum_of_squares_batch`, :func:`log_probability`) one vector after another instead of vmapped — for
    models with several independent LAPACK-backed solves, whose batched calls can hang XLA's CPU thread pool
    (:func:`ringfit.fit.identify.serial_map`). Serial costs nothing there: jaxlib's batched LAPACK kernels loop
    over the batch either way, and such a model's evaluation is its solves (docs/physics.md §12.3: identify's
    joint density, 3.0–3.7 ms per evaluation vmapped or serial after its posterior's narrowed contact window).

    ``compile_quick`` (class attribute, or a static field where it depends on the instance): a small model
    whose fits cost microseconds but whose solve, compiled in a cold process, costs seconds — its
    :func:`least_squares` and :func:`linearize` are compiled with :data:`ringfit._cache.QUICK_COMPILE` (about
    half the compile time; each fit a little slower at most, which a cold process never notices).
    """

    serial_batches: ClassVar[bool] = False
    compile_quick: ClassVar[bool] = False
    #: A model in two stages (``readout`` not empty): an expensive ``inner(theta, data)`` (a solve) that does not
    #: depend on the θ entries ``readout`` (indices; e.g. each run's gain and angle offset on the reading) and a
    #: cheap ``outer(inner, theta, data) -> (residuals, aux)``, with ``model(θ) = outer(inner(θ), θ)``. Its
    #: linearisation over K free slots passes only the first K − len(readout) slots' tangents through ``inner``
    #: and reads the other slots (readout parameters or padding, checked) through ``outer`` alone
    #: (:func:`_linearisation`); :func:`least_squares` and :func:`linearize` order the free set so (results in
    #: the caller's order).
    readout: ClassVar[tuple[int, ...]] = ()

    def __call__(self, theta, data):
        raise NotImplementedError


def map_parameters(model: AbstractResiduals, fn, xs):
    """``fn`` over the leading axis of ``xs`` (parameter vectors): vmapped, or serially for ``model.serial_batches``."""
    return jax.lax.map(fn, xs) if model.serial_batches else jax.vmap(fn)(xs)


@dataclass(frozen=True)
class Problem:
    """A least-squares problem: the model, its data, how each parameter is solved for, the prior.

    - ``model``: :class:`AbstractResiduals`; ``data``: its data pytree.
    - ``coords``: one :class:`Coordinate` per entry of ``theta``.
    - ``prior``: optional :class:`GaussianPrior` on the coordinates.
    - ``sigma``: ``"fixed"`` (residuals are already in units of their σ), ``"estimate"``
      (σ unknown: covariance scaled by χ²/dof; a posterior uses that σ) or ``"inflate"``
      (standard errors × max(1, √(χ²/dof))).
    - ``plausible``: name -> (lo, hi) plausible ranges of log parameters: a fit that ends at
      their edge is flagged (soft), a posterior is truncated there.
    - ``data_label``: what the data are, for flag messages ("these modes").
    """

    model: AbstractResiduals
    data: object
    coords: tuple[Coordinate, ...]
    prior: GaussianPrior | None = None
    sigma: SigmaMode = "fixed"
    plausible: dict | None = None
    data_label: str = "these data"

    def __post_init__(self):
        if self.sigma not in get_args(SigmaMode):
            raise ValueError(f"Problem(sigma={self.sigma!r}): expected one of {list(get_args(SigmaMode))}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.coords)

    def coordinate(self, name: str) -> Coordinate:
        """The :class:`Coordinate` of parameter ``name``."""
        return self.coords[self.names.index(name)]


class _Free(eqx.Module):
    """Traced free set: slot → parameter index, its coordinate transform and its bounds (u units).

    Padding slots point at a dummy entry past the last parameter and change nothing.
    """

    index: jax.Array  # (K,) int
    is_log: jax.Array  # (K,) bool
    center: jax.Array
    scale: jax.Array
    bounded: jax.Array  # (K,) bool
    mid: jax.Array
    half: jax.Array

    def u_of(self, z):
        return jnp.where(self.bounded, self.mid + self.half * jnp.sin(z), z)

    def du_dz(self, z):
        return jnp.where(self.bounded, self.half * jnp.cos(z), 1.0)

    def theta_of(self, u):
        return jnp.where(self.is_log, jnp.exp(u), self.center + self.scale * u)


def _theta_at(u, theta0, free):
    """Every parameter ``(p,)`` at the free slots' coordinates ``u``; theta0 has p + 1 entries.

    θ: the free slots' values where a slot points at the parameter, else theta0 (the padding slots point past
    the last parameter): a gather, whose tangents are gathers too (a scatter here, batched over the Jacobian's
    k tangents, made the compiled solve larger)."""
    hit = free.index[None, :] == jnp.arange(theta0.shape[0] - 1)[:, None]  # (p, K)
    return jnp.where(hit.any(axis=1), free.theta_of(u)[jnp.argmax(hit, axis=1)], theta0[:-1])


def _theta(z, theta0, free):
    """θ at solver point z (:func:`_theta_at` at the free slots' coordinates ``u(z)``)."""
    return _theta_at(free.u_of(z), theta0, free)


def _weighted(z, model, data, theta0, free, prior_w, prior_mean, inner=None):
    """Residual rows (data, then prior) and the model's aux at solver point z; theta0 has p + 1 entries.
    ``inner``: a two-stage model's inner stage as a function of z (:class:`AbstractResiduals`)."""
    u = free.u_of(z)
    theta = _theta_at(u, theta0, free)
    res, aux = model(theta, data) if inner is None else model.outer(inner(z), theta, data)
    return jnp.concatenate([res, prior_w @ (u - prior_mean)]), aux


def _linearisation(model, data, theta0, free, prior_w, prior_mean):
    """``linearise(z) -> (residuals, (aux, jacobian))``: the weighted rows, the model's aux and the rows' dense
    Jacobian in z from one forward-mode pass (primal, aux and k tangents; ``aux`` carries no tangent).

    This is the one place a solve evaluates the model: the solver's step calls it once per step
    (:class:`ringfit.fit._steps._DenseSteps`), so the compiled solve holds one copy of the model.
    """

    def both(z):
        r, aux = _weighted(z, model, data, theta0, free, prior_w, prior_mean)
        return r, (r, aux)

    def linearise(z):
        jac, (res, aux) = jax.jacfwd(both, has_aux=True)(z)
        return res, (aux, jac)

    def linearise_any(z):
        S = inner_slots(model, z.shape[0])
        return linearise_staged(z, S) if S else linearise(z)

    def linearise_staged(z, S):
        # a two-stage model: the inner stage (the solve) linearised over the first S slots only (the others are
        # readout parameters or padding, which it does not depend on), then the outer stage over all K slots
        # through that linearisation: the same Jacobian with S, not K, tangents through the solve
        z_in = z[:S]

        def inner_of(zs):
            x = model.inner(_theta(jnp.concatenate([zs, z[S:]]), theta0, free), data)
            return x, x

        j_in, x0 = jax.jacfwd(inner_of, has_aux=True)(z_in)

        def inner_lin(zz):
            return jax.tree.map(lambda x, j: x + j @ (zz[:S] - z_in), x0, j_in)

        def both_staged(zz):
            r, aux = _weighted(zz, model, data, theta0, free, prior_w, prior_mean, inner=inner_lin)
            return r, (r, aux)

        jac, (res, aux) = jax.jacfwd(both_staged, has_aux=True)(z)
        return res, (aux, jac)

    return linearise_any


def _solve_one(leaves, z0, theta0, free_arrays, prior_w, prior_mean, max_steps, rtol, atol, check_at=0, dtol=0.0, *,
               model, treedef, method="levenberg_marquardt"):
    """One fit (traced): ``data`` arrives as flat leaves (fast dispatch); ``max_steps`` and the tolerances are
    traced, so one compiled solve serves every step limit and tolerance, and with ``max_steps = 0`` every
    evaluation (:func:`linearize`, :func:`evaluate`). ``check_at`` (traced, 0 = never): the step after which a
    solve with a bounded parameter creeping onto its bound stops for the active set (:func:`least_squares`).
    ``dtol`` (traced, 0 = never): an accepted point whose Gauss–Newton decrement is below it has converged
    (:func:`ringfit.fit._steps.gauss_newton_decrement`, :func:`least_squares`).

    Levenberg–Marquardt works on ``s = d·z``, its scaling ``d`` set inside the first step
    (:class:`ringfit.fit._steps._DenseSteps`); a call with ``max_steps = 0`` works on z itself (``d = 1``).
    """
    data = jax.tree.unflatten(treedef, leaves)
    free = _Free(*free_arrays)
    linearise = _linearisation(model, data, theta0, free, prior_w, prior_mean)
    solver = SOLVERS[method](rtol=rtol, atol=atol, linear_solver=lx.SVD())
    creep = (max_steps, jnp.ones_like(z0), check_at, free.bounded, 1.0 - 2.0 * ACTIVE_SET_NEAR, dtol)
    sol = optx.least_squares(lambda s, a: linearise(s / a[1]), solver, z0, args=creep, has_aux=True,
                             max_steps=STEP_CAP, throw=False)
    d = sol.state.scale
    z = sol.value / d
    # residuals, Jacobian and aux at the returned point from the solver's last accepted
    # linearisation: no further trace of the model
    info = sol.state.f_info
    aux = sol.state.aux[0]
    jac_u = info.jac.as_matrix() * d[None, :] / free.du_dz(z)[None, :]
    return free.u_of(z), sol.result._value, sol.stats["num_steps"], info.residual, jac_u, aux


_STATIC = ("model", "treedef", "method")
#: The whole fit in one compiled region.
_solve = jit(_solve_one, static_argnames=_STATIC)
#: The same solve compiled with :data:`ringfit._cache.QUICK_COMPILE` (the CPU backend's optimisation off:
#: about half the compile time), for models with ``compile_quick`` (:class:`AbstractResiduals`).
_solve_quick = jit(_solve_one, quick=True, static_argnames=_STATIC)


#: The two solves as exported programs kept beside the compilation cache (:class:`ringfit._cache.ExportedJit`):
#: a warm process deserialises them instead of tracing; without the cache, the jitted solves themselves.
_solve_kept = ExportedJit(_solve_one, _solve)
_solve_quick_kept = ExportedJit(_solve_one, _solve_quick, quick=True)


def _solve_program(model):
    """The jitted solve of ``model``: :data:`_solve_quick` where it asks for a quick compile, else :data:`_solve`
    (each kept as an exported program where the compilation cache is on)."""
    return _solve_quick_kept if getattr(model, "compile_quick", False) else _solve_kept


@functools.partial(jit, static_argnames=_STATIC)
def _solve_batch(leaves, z0, theta0, free_arrays, prior_w, prior_mean, max_steps, rtol, atol, *, model, treedef,
                 method="levenberg_marquardt"):
    """B fits of one problem structure in one compiled region: data leaves, z0 and theta0 carry a leading axis B."""
    def one(lv, z, th):
        return _solve_one(lv, z, th, free_arrays, prior_w, prior_mean, max_steps, rtol, atol, model=model,
                          treedef=treedef, method=method)

    return jax.vmap(one)(leaves, z0, theta0)


@functools.partial(jit, static_argnames=_STATIC)
def _solve_chain(leaves, z0, theta0, free_arrays, prior_w, prior_mean, max_steps, rtol, atol, *, model, treedef,
                 method="levenberg_marquardt"):
    """B fits one after another in one compiled region (``lax.scan``), each started at the previous optimum.

    ``z0`` ``(K,)`` starts the first fit; a fit that fails (non-finite, or not successful) hands on
    the last good start instead of its own end point.
    """
    def step(z_start, xs):
        lv, th = xs
        out = _solve_one(lv, z_start, th, free_arrays, prior_w, prior_mean, max_steps, rtol, atol, model=model,
                         treedef=treedef, method=method)
        z_end = jnp.where(free_arrays[4], jnp.arcsin(jnp.clip((out[0] - free_arrays[5]) / free_arrays[6], -1, 1)),
                          out[0])
        good = (out[1] == 0) & jnp.all(jnp.isfinite(z_end))
        return jnp.where(good, z_end, z_start), out

    return jax.lax.scan(step, z0, (leaves, theta0))[1]


def inner_slots(model: AbstractResiduals, K: int) -> int:
    """Free slots (of ``K``) whose tangents a two-stage model's inner stage takes: K − len(readout); 0 for a
    model in one stage (or no slot left beside its readout: linearised as one stage)."""
    return max(K - len(model.readout), 0) if model.readout else 0


def _inner_first(problem: Problem, free: tuple[str, ...]) -> tuple[tuple[str, ...], np.ndarray]:
    """``free`` ordered for a two-stage model (:class:`AbstractResiduals`): the parameters its inner stage depends
    on first, then its readout parameters (each group in the given order); and the positions that give back
    the given order. Identity for other models."""
    readout = {problem.names[i] for i in problem.model.readout}
    order = sorted(range(len(free)), key=lambda j: free[j] in readout)
    return tuple(free[j] for j in order), np.argsort(order)


def _check_stages(problem: Problem, index, K: int) -> None:
    """A two-stage model's free slots past :func:`inner_slots` must be readout parameters (or padding)."""
    S = inner_slots(problem.model, K)
    if S and any(i not in problem.model.readout for i in list(index)[S:]):
        raise ValueError(f"free parameters {[problem.names[i] for i in index]}: a two-stage model takes at most {S} "
                         f"parameters of its inner stage (readout: {[problem.names[i] for i in problem.model.readout]})")


def _setup(problem: Problem, free: tuple[str, ...], pad_to: int | None):
    """Free-set arrays of a solve: ``(index, K, free_arrays, prior W, prior mean, lo_u, hi_u)`` (K slots, padded)."""
    coords, prior, names = problem.coords, problem.prior, problem.names
    unknown = [k for k in free if k not in names]
    if unknown or not free or len(set(free)) != len(free):
        raise InputError(f"free parameters {list(free)}: each must be one of {list(names)}, once")
    index = [names.index(k) for k in free]
    K = max(len(free), pad_to or 0)
    pad = K - len(free)
    lo_u = np.array([coords[i].u_bounds[0] for i in index] + [-np.inf] * pad)
    hi_u = np.array([coords[i].u_bounds[1] for i in index] + [np.inf] * pad)
    bounded = np.isfinite(lo_u) & np.isfinite(hi_u)
    mid = np.where(bounded, 0.5 * (np.where(bounded, lo_u, 0.0) + np.where(bounded, hi_u, 0.0)), 0.0)
    half = np.where(bounded, 0.5 * (np.where(bounded, hi_u, 1.0) - np.where(bounded, lo_u, -1.0)), 1.0)
    if prior is not None:
        W, mean = prior.rows(free + ("",) * pad, K)
    else:
        W, mean = np.zeros((K, K)), np.zeros(K)
    slots = [coords[i] for i in index] + [Coordinate("", LINEAR)] * pad
    free_arrays = (np.array(index + [len(names)] * pad, dtype=np.int32), np.array([c.kind == LOG for c in slots]),
                   np.array([c.center for c in slots]), np.array([c.scale for c in slots]), bounded, mid, half)
    return index, K, free_arrays, W, mean, lo_u, hi_u


def _start(problem: Problem, index, K, free_arrays, theta0) -> np.ndarray:
    """Solver start ``z0`` ``(B, K)`` from starting values ``theta0`` ``(B, p)`` (checked: finite, positive logs)."""
    coords = problem.coords
    for i in index:
        c = coords[i]
        bad = ~np.isfinite(theta0[:, i]) | ((c.kind == LOG) & ~(theta0[:, i] > 0))
        if bad.any():
            raise InputError(f"starting value of {c.name} must be {'positive and ' if c.kind == LOG else ''}"
                             f"finite, got {theta0[np.argmax(bad), i]:.6g}")
    _, is_log, center, scale, bounded, mid, half = free_arrays
    start = np.zeros((theta0.shape[0], K))
    for j, i in enumerate(index):
        start[:, j] = coords[i].to_u(theta0[:, i])
    return np.where(bounded, np.arcsin(np.clip((start - mid) / half, -1.0, 1.0)), start)


def least_squares(
    problem: Problem,
    theta0,
    free: tuple[str, ...],
    *,
    max_steps: int = 256,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    n_data: int | None = None,
    pad_to: int | None = None,
    method: SolverMethod = "levenberg_marquardt",
    active_set: bool = True,
    dtol: float = 0.0,
) -> FitResult:
    """Weighted least squares of ``problem`` over the ``free`` parameters (see the module docstring).

    **Arguments:**

    - ``problem``: the :class:`Problem`.
    - ``theta0``: ``(p,)`` starting values of every parameter, natural units, in ``problem.coords`` order.
    - ``free``: names of the parameters to fit (the rest stay at ``theta0``).
    - ``max_steps``, ``rtol``, ``atol``: optimistix Levenberg–Marquardt limits (Cauchy termination
      on the solver coordinates and the residuals).
    - ``n_data``: number of rows that carry data (default: every model row; rows of weight zero
      should not be counted).
    - ``pad_to``: pad the free set to this size (one compilation for several free-set sizes).
    - ``method``: ``"levenberg_marquardt"`` (default) or ``"gauss_newton"`` (:data:`SOLVERS`).
    - ``dtol``: also converged at an accepted point whose Gauss–Newton decrement (the drop of Σr², data and prior
      rows, that the linearised rows promise to their optimum) is below ``dtol`` (default 0: the Cauchy test
      alone). A weakly told nuisance whose linearisation mis-states its curvature (a high-pass corner far below
      the first harmonic) converges only linearly; the decrement says how far in standard errors the optimum still
      is, where the Cauchy test asks for steps of 1e-8 (docs/physics.md §11 *convergence*).
    - ``active_set``: finish a solve that has a bounded parameter on its bound and has not converged by holding
      it there (:func:`_hold_on_bounds`; docs/physics.md §11 *bounds*), checked inside the compiled solve after
      :data:`ACTIVE_SET_AFTER` steps and again at ``max_steps``; a solve with nothing on a bound at the check
      runs on uninterrupted (the answer it gives without the check). ``False``: one solve, as it ended.

    **Returns:** :class:`~ringfit.fit.result.FitResult` with ``theta`` (all parameters at the
    optimum), the model's aux in ``extra["aux"]`` and ``problem``; ``extra["held"]`` names the parameters
    the active set held on a bound. Never raises on non-convergence: check ``converged``.
    """
    require_x64("ringfit.fit.engine.least_squares")
    kw = dict(max_steps=max_steps, rtol=rtol, atol=atol, n_data=n_data, method=method, dtol=dtol)
    # A solve still running after ACTIVE_SET_AFTER steps with a parameter on its bound is creeping there: the
    # compiled solve stops at that step and the active set finishes it, instead of after the whole budget. A solve
    # with nothing on a bound there runs on, as it would without the check (checked inside the solve's loop: a
    # Levenberg–Marquardt solve stopped and resumed would be another solve).
    check_at = ACTIVE_SET_AFTER if active_set and max_steps > ACTIVE_SET_AFTER else 0
    result = _least_squares(problem, theta0, free, pad_to=pad_to, check_at=check_at, **kw)
    if not (active_set and result.status == "max_steps_reached" and max_steps > 0):
        return result
    held = _hold_on_bounds(problem, result, tuple(free), pad_to, kw)
    if held.converged or result.iterations >= max_steps:
        return held
    # stopped at the check, and the active set could not finish it: the whole solve, without the check
    result = _least_squares(problem, theta0, free, pad_to=pad_to, **kw)
    if result.status == "max_steps_reached":
        result = _hold_on_bounds(problem, result, tuple(free), pad_to, kw)
    return result


#: The Gauss–Newton decrement under which :func:`least_squares` (``dtol``) takes a fit of σ-weighted rows as
#: converged: its linearisation promises a drop of Σr² (a χ²) under 1e-6, i.e. the optimum is ~1e-3 standard
#: errors away (docs/physics.md §11 *convergence*). Used where weakly told nuisances converge only linearly
#: (the profile block's sensor: ``fit-rolling``, ``identify``).
DECREMENT_TOL = 1e-6


#: A solve that reaches its step limit with a bounded parameter within this share of its solver coordinate's
#: range of a bound is finished by an active set (:func:`_hold_on_bounds`). The sine transform's slope vanishes
#: on the bound, so Levenberg–Marquardt creeps there and never meets its tolerances (docs/physics.md §11 *bounds*).
ACTIVE_SET_NEAR = 1e-3
#: Steps after which a solve that has not converged is checked, inside its compiled loop, for a bounded parameter
#: creeping onto its bound (the solve then stops and the active set finishes it; without one it runs on).
ACTIVE_SET_AFTER = 128
#: Rounds of hold, re-solve and release before the active set gives up (each round frees what the gradient
#: pulls inwards).
ACTIVE_SET_ROUNDS = 3


def _hold_on_bounds(problem: Problem, fit: FitResult, free: tuple[str, ...], pad_to, kw) -> FitResult:
    """The active set of bounds (docs/physics.md §11 *bounds*): a fit that ran out of steps with parameters on
    their bounds, finished with those held there.

    Each bounded free parameter within :data:`ACTIVE_SET_NEAR` of a bound is set on it; the others are solved
    again from there (the same compiled program: the free set padded to its size). The Karush–Kuhn–Tucker
    condition is then checked on the full free set: a held parameter whose cost gradient (data and prior
    rows) points into its range is released a little inside it and the rest solved again, at most
    :data:`ACTIVE_SET_ROUNDS` times. The answer is the full free set evaluated at the end point (its
    covariance and flags as any fit's), ``converged`` with ``extra["held"]`` naming the held ones; when the
    re-solve does not converge either, the original fit is returned as it was."""
    coords, names = problem.coords, problem.names
    K = pad_to if pad_to is not None else len(free)
    lo_u, hi_u = _u_bounds(problem, free)
    u = np.array([coords[names.index(n)].to_u(fit.values[n]) for n in free])
    near = ACTIVE_SET_NEAR * (hi_u - lo_u)  # nan/inf where a side is open: never near
    bounds = {n: (lo_u[j] if u[j] <= lo_u[j] + near[j] else hi_u[j]) for j, n in enumerate(free)
              if np.isfinite(near[j]) and (u[j] <= lo_u[j] + near[j] or u[j] >= hi_u[j] - near[j])}
    if not bounds:
        return fit
    theta, held, steps = fit.theta.copy(), dict(bounds), fit.iterations
    for _ in range(ACTIVE_SET_ROUNDS):
        for n, b in held.items():
            theta[names.index(n)] = coords[names.index(n)].from_u(b)
        rest = tuple(n for n in free if n not in held)
        if rest:
            sub = _least_squares(problem, theta, rest, pad_to=K, **kw)
            steps += sub.iterations
            if not sub.converged:
                return fit
            theta = sub.theta.copy()
        fs, u_all, res, jac, aux = _linearize_all(problem, theta, free, K)
        grad = jac[:, : len(free)].T @ res  # d(½Σr²)/du over data and prior rows
        # inwards: the cost falls as the parameter moves off its bound into its range
        inward = [n for n, b in held.items() if (grad[free.index(n)] < 0) == (b == lo_u[free.index(n)])]
        if not inward:
            m = res.size - fs.size
            res = np.concatenate([res[:m], res[m:][: len(free)]])
            jac = np.concatenate([jac[:m, : len(free)], jac[m:][: len(free), : len(free)]])
            index = list(fs.index[: len(free)])
            message = (f"converged with {', '.join(held)} held on the bound of its range (active set)" if held
                       else "converged (the active set released every bound it had held)")
            out = _result(problem, free, index, theta, u_all[: len(free)], "converged", message, steps, res, jac, m,
                          aux, kw["n_data"], lo_u, hi_u, held=tuple(held))
            out.problem = problem
            return out
        for n in inward:  # released a little inside its range, where the sine transform can move it
            j, b = free.index(n), held.pop(n)
            theta[names.index(n)] = coords[names.index(n)].from_u(b + 10 * near[j] * (1 if b == lo_u[j] else -1))
    return fit


def _u_bounds(problem: Problem, free) -> tuple[np.ndarray, np.ndarray]:
    """Solver-coordinate bounds ``(lo_u, hi_u)`` of the ``free`` parameters, in their order."""
    b = [problem.coords[problem.names.index(n)].u_bounds for n in free]
    return np.array([x[0] for x in b]), np.array([x[1] for x in b])


def _least_squares(problem: Problem, theta0, free, *, max_steps, rtol, atol, n_data, pad_to, method,
                   check_at: int = 0, dtol: float = 0.0) -> FitResult:
    """One solve of :func:`least_squares` (no active set; ``check_at``: :func:`_solve_one`)."""
    model, data, coords = problem.model, problem.data, problem.coords
    names = problem.names
    free = tuple(free)
    solve_free, back = _inner_first(problem, free)
    index, K, free_arrays, W, mean, lo_u, hi_u = _setup(problem, solve_free, pad_to)
    _check_stages(problem, index, K)
    theta0 = np.asarray(theta0, dtype=np.float64)
    if theta0.shape != (len(names),):
        raise ValueError(f"theta0 has shape {theta0.shape}, coords {len(names)}")
    z0 = _start(problem, index, K, free_arrays, theta0[None])[0]
    leaves, treedef = jax.tree.flatten(data)
    if method not in SOLVERS:
        raise ValueError(f"method={method!r}; expected one of {list(SOLVERS)}")
    if not 0 <= int(max_steps) <= STEP_CAP:
        raise InputError(f"max_steps = {max_steps}: expected 1 … {STEP_CAP} (0: evaluate only)")
    args = (leaves, z0, np.append(theta0, 0.0), free_arrays, W, mean)
    tol = (np.float64(rtol), np.float64(atol))
    out = _solve_program(model)(*args, np.int64(max_steps), *tol, np.int64(check_at), np.float64(dtol), model=model,
                                treedef=treedef,
                                method=method)
    u_free, result, steps, res, jac = jax.device_get(out[:5])  # one transfer; the model's aux stays as it is
    aux = out[5]
    # back to the caller's order of ``free`` (prior rows stay whitened rows: their sum of squares is the same)
    u_free, jac = u_free[: len(free)][back], jac[:, : len(free)][:, back]
    index, lo_u, hi_u = [index[j] for j in back], lo_u[: len(free)][back], hi_u[: len(free)][back]
    m = res.size - K
    res, jac = np.concatenate([res[:m], res[m:][: len(free)]]), np.concatenate([jac[:m], jac[m:][: len(free)]])
    status, message = solver_status(result)
    result = _result(problem, free, index, theta0, u_free, status, message, int(steps), res, jac, m, aux,
                     n_data, lo_u, hi_u)
    result.problem = problem
    return result


def _result(problem, free, index, theta0, u_free, status, message, steps, res, jac, m, aux, n_data,
            lo_u, hi_u, held: tuple[str, ...] = ()) -> FitResult:
    coords, sigma = problem.coords, problem.sigma
    priors = tuple(k for k in free if problem.prior is not None and k in problem.prior.names)
    theta = theta0.copy()
    for j, i in enumerate(index):
        theta[i] = coords[i].from_u(float(u_free[j]))
    k = len(free)
    data_rows = int(m if n_data is None else n_data)
    chi2 = float(res[:m] @ res[:m])
    dof = max(data_rows - k, 1)
    s = math.sqrt(chi2 / dof) if chi2 > 0 else 1.0
    J = jac.copy()
    if sigma == "estimate":
        J[:m] = J[:m] / s
    cov = covariance_from_jacobian(J)
    infl = max(1.0, s) if sigma == "inflate" else 1.0
    stderr, flags, at_bound = {}, solver_flags(status, message), []
    values = {c.name: float(t) for c, t in zip(coords, theta)}
    for j, name in enumerate(free):
        c = coords[index[j]]
        sd_u = math.sqrt(cov[j, j]) * infl if np.isfinite(cov[j, j]) else math.inf
        stderr[name] = values[name] * sd_u if c.kind == LOG else c.scale * sd_u
        lo, hi = lo_u[j], hi_u[j]
        span = hi - lo if math.isfinite(hi - lo) else 1.0
        if (math.isfinite(lo) and u_free[j] <= lo + 1e-6 * span) or (math.isfinite(hi) and u_free[j] >= hi - 1e-6 * span):
            at_bound.append(name)
            flags.append(f"{name} = {values[name]:.4g} is at the bound of its range "
                         f"[{c.from_u(lo) if math.isfinite(lo) else -math.inf:.4g}, "
                         f"{c.from_u(hi) if math.isfinite(hi) else math.inf:.4g}]: "
                         + ("held there, the data pulling it beyond (active set)" if name in held
                            else "the data do not bound it"))
    logs = tuple(n for j, n in enumerate(free) if coords[index[j]].kind == LOG)
    flags += parameter_flags(logs, values, stderr, data=problem.data_label, priors=priors,
                             plausible=problem.plausible)
    if data_rows < k:
        flags.append(f"{k} free parameters but only {data_rows} data rows: the fit is under-determined")
    return FitResult(
        status=status, message=message or "converged", names=free, values=values, stderr=stderr,
        covariance_log=cov * infl**2, residuals=res[:m] / (s if sigma == "estimate" else 1.0),
        jacobian=J, n_data=data_rows, iterations=steps, flags=flags,
        extra={"aux": aux, "sigma_scale": s if sigma == "estimate" else 1.0, "chi2_raw": chi2,
               "prior_chi2": float(res[m:] @ res[m:]), "at_bound": tuple(at_bound), "held": tuple(held)},
        theta=theta, coords=tuple(coords),
    )


def least_squares_batch(
    problem: Problem,
    theta0,
    free: tuple[str, ...],
    data,
    *,
    max_steps: int = 256,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    n_data: int | None = None,
    warm_start: bool = False,
    method: SolverMethod = "levenberg_marquardt",
) -> BatchFitResult:
    """B fits of one problem structure in one compiled region: vmapped, or one after another warm-started.

    Each fit is what :func:`least_squares` does for ``problem`` with the b-th data set.

    - ``warm_start=False``: the fits are independent, each from its own start ``theta0[b]``,
      vmapped. The vmapped solver iterates until every fit has met its tolerances (or
      ``max_steps``), and every branch of the solver is evaluated for all of them, so a batch
      costs about B × the slowest fit: best on an accelerator.
    - ``warm_start=True``: the fits run in order in a ``lax.scan``, the free parameters of fit b
      starting at fit b − 1's optimum (the first at ``theta0[0]``; a failed fit passes on its own
      start); the fixed parameters come from ``theta0[b]``. For a sequence of similar data sets
      (revolutions of a recording) this costs the sum of a few steps each with no Python in
      between: best on a CPU.

    One compilation serves every batch of the same size B and structure: pad the last batch.

    **Arguments:**

    - ``problem``: the :class:`Problem` (its ``data`` is not used, only its model, coordinates,
      prior and ``sigma``).
    - ``theta0``: ``(B, p)`` or ``(p,)`` starting values, natural units.
    - ``free``: names of the parameters to fit (the same for every fit).
    - ``data``: the model's data pytree with a leading axis B on every leaf.
    - ``max_steps``, ``rtol``, ``atol``, ``n_data``, ``method``: as :func:`least_squares`; ``warm_start``: see above.

    **Returns:** :class:`~ringfit.fit.result.BatchFitResult` (arrays with a leading axis B; no flag
    strings: check ``converged`` and ``at_bound``). Never raises on non-convergence.
    """
    require_x64("ringfit.fit.engine.least_squares_batch")
    free = tuple(free)
    index, K, free_arrays, W, mean, lo_u, hi_u = _setup(problem, free, None)
    _check_stages(problem, index, K)  # a two-stage model's free set must come inner stage first here
    leaves, treedef = jax.tree.flatten(data)
    if not leaves:
        raise ValueError("data has no arrays to batch over")
    B = int(np.shape(leaves[0])[0])
    if any(np.shape(x)[:1] != (B,) for x in leaves):
        raise ValueError("every leaf of data needs the same leading batch axis")
    p = len(problem.names)
    theta0 = np.broadcast_to(np.asarray(theta0, dtype=np.float64), (B, p)).copy()
    z0 = _start(problem, index, K, free_arrays, theta0)
    theta0_pad = np.concatenate([theta0, np.zeros((B, 1))], axis=1)
    if method not in SOLVERS:
        raise ValueError(f"method={method!r}; expected one of {list(SOLVERS)}")
    if not 1 <= int(max_steps) <= STEP_CAP:
        raise InputError(f"max_steps = {max_steps}: expected 1 … {STEP_CAP}")
    solve = _solve_chain if warm_start else _solve_batch
    u, codes, steps, res, jac, aux = solve(leaves, z0[0] if warm_start else z0, theta0_pad, free_arrays, W, mean,
                                           np.int64(max_steps), np.float64(rtol), np.float64(atol),
                                           model=problem.model, treedef=treedef, method=method)
    u, res, jac, codes = np.asarray(u), np.asarray(res), np.asarray(jac), np.asarray(codes)
    coords = problem.coords
    theta = theta0.copy()
    for j, i in enumerate(index):
        theta[:, i] = coords[i].from_u(u[:, j])
    m = res.shape[1] - K
    chi2 = np.sum(res[:, :m] ** 2, axis=1)
    rows = int(m if n_data is None else n_data)
    s = np.where(chi2 > 0, np.sqrt(chi2 / max(rows - K, 1)), 1.0)
    J = jac.copy()
    scale = s if problem.sigma == "estimate" else np.ones(B)
    J[:, :m] /= scale[:, None, None]
    cov = covariance_batch(J)
    if problem.sigma == "inflate":
        cov = cov * np.maximum(1.0, s)[:, None, None] ** 2
    sd_u = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0.0, None))
    stderr = np.empty((B, K))
    for j, i in enumerate(index):
        stderr[:, j] = theta[:, i] * sd_u[:, j] if coords[i].kind == LOG else coords[i].scale * sd_u[:, j]
    span = np.where(np.isfinite(hi_u - lo_u), hi_u - lo_u, 1.0)
    at_bound = ((np.isfinite(lo_u) & (u <= lo_u + 1e-6 * span)) | (np.isfinite(hi_u) & (u >= hi_u - 1e-6 * span)))
    names = {c: solver_status(c)[0] for c in np.unique(codes)}
    status = np.array([names[c] for c in codes])
    return BatchFitResult(names=free, coords=tuple(coords), theta=theta, status=status, iterations=np.array(steps),
                          stderr=stderr, covariance_log=cov, residuals=res[:, :m] / scale[:, None], chi2_raw=chi2,
                          sigma_scale=s if problem.sigma == "estimate" else np.ones(B), at_bound=at_bound,
                          aux=jax.tree.map(np.array, aux), n_data=rows)


@functools.partial(jit, static_argnames=("model", "treedef"))
def _batched_sum_of_squares(thetas, leaves, *, model, treedef):
    data = jax.tree.unflatten(treedef, leaves)
    return map_parameters(model, lambda th: jnp.sum(model(th, data)[0] ** 2), thetas)


def in_fixed_chunks(batched_fn, rows, size: int) -> np.ndarray:
    """``batched_fn`` over the rows of ``rows`` ``(G, …)`` in chunks of exactly ``size`` rows.

    The last chunk is padded with copies of its last row (results dropped), so a jitted
    ``batched_fn`` compiles once per chunk size, not once per remainder.
    """
    rows = np.asarray(rows, dtype=np.float64)
    n, size = rows.shape[0], max(1, int(size))
    pad = -n % size
    if pad:
        rows = np.concatenate([rows, np.repeat(rows[-1:], pad, axis=0)])
    return np.concatenate([np.asarray(batched_fn(rows[i : i + size])) for i in range(0, rows.shape[0], size)])[:n]


def sum_of_squares_batch(problem: Problem, thetas, chunk: int = 64) -> np.ndarray:
    """Σ r² of the data rows for each parameter vector of ``thetas`` ``(G, p)`` (natural units).

    Evaluated in chunks of exactly ``min(chunk, G)`` rows (the last padded), so one
    compilation serves every grid size.
    """
    require_x64("ringfit.fit.engine.sum_of_squares_batch")
    leaves, treedef = jax.tree.flatten(problem.data)
    return in_fixed_chunks(lambda th: _batched_sum_of_squares(th, leaves, model=problem.model, treedef=treedef),
                           thetas, min(int(chunk), len(thetas)))


# ---------------------------------------------------------------------------------------------
# The public surface besides the fits: residuals, Jacobian, log-probability at given parameters.
# Other modules (the posterior, the gap ranking, the joint identification) build on these and
# never on the solver's internals (the free-set arrays, the weighted rows, zero-step solves).
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FreeSet:
    """A checked free set of a problem: parameter ``index`` per free name, solver-coordinate bounds.

    - ``names``: the free parameters; ``index``: their positions in ``problem.coords``.
    - ``lo_u``, ``hi_u``: ``(k,)`` bounds of their solver coordinates ``u`` (``±inf`` when open).
    - ``prior_w``, ``prior_mean``: whitened prior rows ``W (u − mean)`` over the (padded) free set.
    """

    names: tuple[str, ...]
    index: tuple[int, ...]
    size: int
    arrays: tuple
    prior_w: np.ndarray
    prior_mean: np.ndarray
    lo_u: np.ndarray
    hi_u: np.ndarray

    def u_of_theta(self, problem: Problem, theta) -> np.ndarray:
        """Solver coordinates ``(k,)`` of the free parameters at ``theta`` (natural units, ``(p,)``)."""
        return np.array([problem.coords[i].to_u(float(theta[i])) for i in self.index])

    def unbounded_arrays(self) -> tuple:
        """``arrays`` without the solver's sine transform of bounded coordinates: functions of ``u`` itself."""
        K = self.size
        return self.arrays[:4] + (np.zeros(K, dtype=bool), np.zeros(K), np.ones(K))


def free_set(problem: Problem, free: tuple[str, ...], pad_to: int | None = None) -> FreeSet:
    """Check ``free`` against ``problem`` and build its :class:`FreeSet` (padded to ``pad_to`` slots)."""
    index, K, arrays, W, mean, lo_u, hi_u = _setup(problem, tuple(free), pad_to)
    k = len(tuple(free))
    return FreeSet(tuple(free), tuple(index), K, arrays, W, mean, lo_u[:k], hi_u[:k])


@dataclass(frozen=True)
class Linearization:
    """Weighted data rows at given parameters: ``residuals`` ``(m,)``, ``jacobian`` ``(m, k)`` with respect to
    the free parameters' solver coordinates ``u`` (ln θ or (θ − center)/scale), the model's ``aux``."""

    residuals: np.ndarray
    jacobian: np.ndarray
    aux: object
    names: tuple[str, ...]


def _linearize_all(problem: Problem, theta, free, pad_to):
    solve_free, back = _inner_first(problem, tuple(free))
    fs = free_set(problem, solve_free, pad_to)
    _check_stages(problem, fs.index, fs.size)
    theta = np.asarray(theta, dtype=np.float64)
    if theta.shape != (len(problem.names),):
        raise ValueError(f"theta has shape {theta.shape}, coords {len(problem.names)}")
    _start(problem, fs.index, fs.size, fs.arrays, theta[None])  # checks the values
    u = np.concatenate([fs.u_of_theta(problem, theta), np.zeros(fs.size - len(fs.names))])
    leaves, treedef = jax.tree.flatten(problem.data)
    # the solve's own compiled program, evaluating only (no step): with the free set unbounded, z = u
    # (no sine transform), so its Jacobian is in u; no second program holding the model
    solve = _solve_program(problem.model)
    _, _, _, res, jac, aux = solve(leaves, u, np.append(theta, 0.0), fs.unbounded_arrays(), fs.prior_w,
                                   fs.prior_mean, np.int64(0), np.float64(1e-10), np.float64(1e-10), np.int64(0),
                                   np.float64(0.0), model=problem.model, treedef=treedef, method="levenberg_marquardt")
    jac = np.asarray(jac)
    if solve_free != tuple(free):  # back to the caller's order (a two-stage model's free set was reordered)
        k = len(back)
        fs = free_set(problem, free, pad_to)
        u = np.concatenate([u[:k][back], u[k:]])
        jac = np.concatenate([jac[:, :k][:, back], jac[:, k:]], axis=1)
    return fs, u, np.asarray(res), jac, aux


def linearize(problem: Problem, theta, free: tuple[str, ...], *, pad_to: int | None = None) -> Linearization:
    """Weighted residual rows, their Jacobian and the model's aux at ``theta`` — no fit.

    Evaluated by the compiled solve of :func:`least_squares` (a step limit of 0), so a problem's fits and
    linearisations with the same (padded) free-set size share one program: ``pad_to`` pads the free
    set so that chunks of several sizes share it. The Jacobian is with respect to the
    solver coordinates ``u`` of ``free`` (``∂r/∂ln θ`` for log parameters); prior rows are left out.
    """
    require_x64("ringfit.fit.engine.linearize")
    fs, _, res, jac, aux = _linearize_all(problem, theta, free, pad_to)
    m = res.size - fs.size
    return Linearization(res[:m], jac[:m, : len(fs.names)], aux, fs.names)


@functools.partial(jit, static_argnames=("model", "treedef"))
def _residuals_at(theta, leaves, *, model, treedef):
    return model(theta, jax.tree.unflatten(treedef, leaves))


def residuals(problem: Problem, theta) -> tuple[np.ndarray, object]:
    """The model's weighted residual rows ``(m,)`` and aux at ``theta`` (natural units, ``(p,)``); no prior rows."""
    require_x64("ringfit.fit.engine.residuals")
    leaves, treedef = jax.tree.flatten(problem.data)
    res, aux = _residuals_at(jnp.asarray(theta, dtype=jnp.float64), leaves, model=problem.model, treedef=treedef)
    return np.asarray(res), aux


@functools.partial(jit, static_argnames=("model", "treedef"))
def _batched_residuals(thetas, leaves, *, model, treedef):
    data = jax.tree.unflatten(treedef, leaves)
    return map_parameters(model, lambda th: model(th, data)[0], thetas)


def residuals_batch(problem: Problem, thetas, chunk: int = 64) -> np.ndarray:
    """Weighted residual rows ``(G, m)`` for each parameter vector of ``thetas`` ``(G, p)``, in fixed chunks."""
    require_x64("ringfit.fit.engine.residuals_batch")
    leaves, treedef = jax.tree.flatten(problem.data)
    return in_fixed_chunks(lambda th: _batched_residuals(th, leaves, model=problem.model, treedef=treedef),
                           thetas, min(int(chunk), len(thetas)))


@dataclass(frozen=True)
class DensityKernel:
    """The log density of a problem's free parameters as a traceable function: ``kernel(u, consts) -> (n,)``.

    Hashable (the model and the data's tree structure), so it is a static argument of a compiled program
    (:func:`log_probability`'s, the ensemble sampler's, :mod:`ringfit.fit.ensemble`) while ``consts`` (the
    data, the fixed parameters, prior rows, bounds, row weights: :func:`log_density`) are traced: one
    compilation per problem structure, whatever the data. Batches over ``u`` ``(n, k)`` are vmapped, or
    serial for ``model.serial_batches`` (:func:`map_parameters`).
    """

    model: AbstractResiduals
    treedef: object

    def __call__(self, u, consts):
        leaves, theta0, free_arrays, prior_w, prior_mean, lo, hi, inv_s2, marginal = consts
        data = jax.tree.unflatten(self.treedef, leaves)
        free = _Free(*free_arrays)
        k = u.shape[1]
        on, half_m, s_min = marginal[0], 0.5 * marginal[1], marginal[2]

        def one(ui):
            # u itself (the free set is unbounded: no sine transform) and the prior rows as a sum of products
            # (k ≤ 15; a dot here is a library call per evaluation in the sampler's loop)
            r, _ = self.model(_theta_at(ui, theta0, free), data)
            prior = jnp.sum(prior_w[:k, :k] * (ui - prior_mean[:k])[None, :], axis=1)
            chi2 = jnp.sum(inv_s2 * r**2)
            # the rows' common σ scale s integrated out (prior 1/s on s ≥ s_min, docs/physics.md §12.3):
            # −(m/2) ln χ² + ln P(m/2, χ²/(2 s_min²)), P the regularised lower incomplete gamma (1 for s_min = 0)
            tiny = jnp.finfo(jnp.float64).tiny
            cut = jnp.where(s_min > 0, jax.scipy.special.gammainc(half_m, 0.5 * chi2 / jnp.maximum(s_min, tiny) ** 2),
                            1.0)
            data_term = jnp.where(on > 0, -half_m * jnp.log(jnp.maximum(chi2, tiny)) + jnp.log(cut), -0.5 * chi2)
            value = data_term - 0.5 * jnp.sum(prior**2)
            inside = jnp.all((ui >= lo) & (ui <= hi))
            value = jnp.where(inside, value, -jnp.inf)
            return jnp.where(jnp.isnan(value), -jnp.inf, value)

        return map_parameters(self.model, one, u)


def log_density(problem: Problem, theta, free: tuple[str, ...], *, lo_u=None, hi_u=None,
                sigma_scale: float = 1.0, row_scale=None, scale_marginal: dict | None = None) -> tuple[DensityKernel, tuple]:
    """``(kernel, consts)``: the log posterior density of the free parameters' solver coordinates, traceable.

    ``kernel(u (n, k), consts) -> (n,)`` is ``−½ (χ² + prior rows²)``, χ² = ``Σ_i r_i²/(s² c_i²)``, with ``r`` the
    model's weighted rows, ``s`` = ``sigma_scale`` (the fit's residual σ when the problem's ``sigma`` is
    ``"estimate"``) and ``c`` = ``row_scale`` (``(m,)`` per-row widening of the σ, e.g. identify's Student-t
    widening per block; default 1). ``scale_marginal`` = ``dict(rows=m, s_min=…)``: the rows' σ is known only up
    to a common scale, integrated out under a 1/s prior on s ≥ ``s_min`` (0: none), so the data term is
    ``−(m/2) ln χ² + ln P(m/2, χ²/(2 s_min²))`` (docs/physics.md §12.3: the Student-t shape at every level, where
    a fixed t-widening of σ fits one level). ``−inf`` outside ``[lo_u, hi_u]`` (default: the coordinates' bounds) or
    where the model is not finite. The fixed parameters stay at ``theta``. The density is over u itself (no
    sine transform of bounded coordinates). ``consts`` is a tuple of arrays (traced by whatever compiles the
    kernel).
    """
    require_x64("ringfit.fit.engine.log_density")
    fs = free_set(problem, free)
    lo = fs.lo_u if lo_u is None else np.asarray(lo_u, dtype=np.float64)
    hi = fs.hi_u if hi_u is None else np.asarray(hi_u, dtype=np.float64)
    free_arrays = tuple(jnp.asarray(a) for a in fs.unbounded_arrays())
    leaves, treedef = jax.tree.flatten(problem.data)
    inv_s2 = 1.0 / float(sigma_scale) ** 2
    if row_scale is not None:
        inv_s2 = inv_s2 / np.asarray(row_scale, dtype=np.float64) ** 2
    marginal = (np.zeros(3) if scale_marginal is None else
                np.array([1.0, float(scale_marginal["rows"]), float(scale_marginal.get("s_min", 0.0))]))
    consts = (tuple(jnp.asarray(x) for x in leaves), jnp.asarray(np.append(np.asarray(theta, np.float64), 0.0)),
              free_arrays, jnp.asarray(fs.prior_w), jnp.asarray(fs.prior_mean), jnp.asarray(lo), jnp.asarray(hi),
              jnp.asarray(inv_s2, dtype=jnp.float64), jnp.asarray(marginal))
    return DensityKernel(problem.model, treedef), consts


@functools.partial(jit, static_argnames=("kernel",))
def _batched_log_probability(u, consts, *, kernel):
    """Log density ``(n,)`` of solver coordinates ``u`` ``(n, k)``, up to a constant."""
    return kernel(u, consts)


def log_probability(problem: Problem, theta, free: tuple[str, ...], *, lo_u=None, hi_u=None,
                    sigma_scale: float = 1.0, chunk: int | None = None, row_scale=None,
                    scale_marginal: dict | None = None):
    """``u (n, k) -> (n,)``: the log posterior density of the free parameters' solver coordinates (NumPy).

    :func:`log_density` (see there for ``lo_u``, ``hi_u``, ``sigma_scale``, ``row_scale``, ``scale_marginal``) as one jitted,
    vmapped region; ``chunk`` evaluates in chunks of exactly that many rows (padded), so one compilation
    serves every batch size.
    """
    kernel, consts = log_density(problem, theta, free, lo_u=lo_u, hi_u=hi_u, sigma_scale=sigma_scale,
                                 row_scale=row_scale, scale_marginal=scale_marginal)

    def evaluate_u(u):
        return np.asarray(_batched_log_probability(u, consts, kernel=kernel), dtype=np.float64)

    def log_prob(u):
        u = np.asarray(u, dtype=np.float64)
        return evaluate_u(u) if chunk is None else in_fixed_chunks(evaluate_u, u, chunk)

    return log_prob


def evaluate(problem: Problem, theta, free: tuple[str, ...], *, pad_to: int | None = None,
             n_data: int | None = None, **_ignored) -> FitResult:
    """Residuals, Jacobian (w.r.t. the free parameters' solver coordinates), covariance and aux at ``theta`` — no fit.

    :func:`linearize` packed as a :class:`~ringfit.fit.result.FitResult` (``status`` ``"evaluated"``,
    no flags), for code that wants standard errors at given parameters.
    """
    require_x64("ringfit.fit.engine.evaluate")
    fs, u, res, jac, aux = _linearize_all(problem, theta, free, pad_to)
    k = len(fs.names)
    m = res.size - fs.size
    res, jac = np.concatenate([res[:m], res[m:][:k]]), np.concatenate([jac[:m], jac[m:][:k]])[:, :k]
    result = _result(problem, fs.names, list(fs.index), np.asarray(theta, dtype=np.float64), u[:k], "evaluated",
                     "residuals and Jacobian at the given parameters (no fit)", 0, res, jac, m, aux, n_data,
                     fs.lo_u, fs.hi_u)
    result.flags = []
    result.problem = problem
    return result


__all__ = ["ACTIVE_SET_AFTER", "DECREMENT_TOL", "least_squares", "least_squares_batch", "SOLVERS", "evaluate", "sum_of_squares_batch", "linearize",
           "Linearization", "inner_slots", "residuals", "residuals_batch", "log_probability", "log_density", "DensityKernel", "free_set", "FreeSet", "in_fixed_chunks", "Problem", "Coordinate", "GaussianPrior", "AbstractResiduals", "LOG", "LINEAR"]
