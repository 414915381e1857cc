"""The compiled affine-invariant ensemble sampler: Goodman & Weare's stretch move as one XLA program.

The algorithm is emcee's default (``emcee.moves.StretchMove``, a = 2, docs/physics.md §12.1), written so that
a whole block of steps is one compiled program instead of one Python iteration and one dispatch per step:

- **State**: ``C`` independent ensembles ("chains") of ``W`` walkers each, ``x`` ``(C, W, k)`` in the solver
  coordinates of a problem's free parameters, and their log densities ``(C, W)``.
- **One step** (per ensemble): the walkers are split at random into two halves (emcee's
  ``randomize_split``); every walker j of the first half proposes ``y = x_c + z (x_j − x_c)`` with x_c a
  walker of the other half drawn uniformly and ``z`` from ``g(z) ∝ 1/√z`` on [1/a, a], and accepts with
  probability ``min(1, z^{k−1} p(y)/p(x_j))``; then the second half does the same against the updated
  first half. Updating one half against the other, held fixed, keeps the move exact while every walker of
  a half is evaluated at once (vmapped, or serially for models whose batches must not be vmapped).
- **A block**: ``lax.scan`` over the ``2·steps`` half-steps of ``steps`` such steps (:func:`_block`); the draws ``(steps, C, W, k)`` and log densities come
  back to the host. The density is a :class:`~ringfit.fit.engine.DensityKernel` (static: the model) with its
  data traced, so one compilation serves every block, every seed and every data set of the same structure.
- **Stopping** (on the host, between blocks): emcee's integrated autocorrelation time
  (:func:`integrated_time`, Sokal's automatic window c = 5) over the whole chain; the run stops once the
  chain is longer than ``TAU_FACTOR`` × the largest τ and ``min_steps`` long, or at ``max_steps``.

:func:`run_compiled` is the driver; :func:`ringfit.fit.posterior.sample` calls it (``sampler="compiled"``,
the default) or emcee (``sampler="emcee"``, the reference).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from ringfit._cache import jit

#: Goodman & Weare's stretch scale (emcee's default).
STRETCH_A = 2.0


def autocorrelation(x: np.ndarray) -> np.ndarray:
    """Normalised autocorrelation function along axis 0 of ``x`` ``(steps, …)``: emcee's ``function_1d`` for
    every series at once (FFT zero-padded to at least 2·steps, so the correlation is linear, not circular;
    the series contiguous along the transform)."""
    import scipy.fft

    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    y = np.ascontiguousarray(np.moveaxis(x - x.mean(axis=0), 0, -1))
    m = scipy.fft.next_fast_len(2 * n, real=True)
    f = scipy.fft.rfft(y, n=m, axis=-1)
    acf = scipy.fft.irfft(f.real**2 + f.imag**2, n=m, axis=-1)[..., :n]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.moveaxis(acf / acf[..., :1], -1, 0)


def _mean_autocorrelation(chain: np.ndarray, lags: int) -> np.ndarray:
    """The walkers' mean normalised autocorrelation ``(lags, k)`` of ``chain`` ``(steps, walkers, k)`` at lags
    ``0 … lags − 1``: what ``nanmean(autocorrelation(chain), axis=1)[:lags]`` gives, with two transforms fewer.

    Each walker's series is zero-padded to ``steps + lags`` (enough for a linear, not circular, correlation up
    to that lag); its normalised autocorrelation is ``irfft(|F_w|²) / a_w`` with ``a_w = Σ x_w²`` (its value at
    lag 0), and since the inverse transform is linear the walkers' mean is one inverse transform per
    parameter of ``Σ_w |F_w|² / a_w`` over the walkers that are not constant (the others are NaN in emcee's
    mean and left out of it)."""
    import scipy.fft

    steps = chain.shape[0]
    y = np.ascontiguousarray(np.moveaxis(chain - chain.mean(axis=0), 0, -1))  # (walkers, k, steps)
    m = scipy.fft.next_fast_len(steps + lags, real=True)
    f = scipy.fft.rfft(y, n=m, axis=-1)
    a = np.einsum("wkt,wkt->wk", y, y)
    moving = a > 0
    weight = np.divide(1.0, a, out=np.zeros_like(a), where=moving)
    power = np.einsum("wkf,wk->kf", f.real**2 + f.imag**2, weight)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = scipy.fft.irfft(power, n=m, axis=-1)[:, :lags] / moving.sum(axis=0)[:, None]
    return rho.T


def integrated_time(chain: np.ndarray, c: float = 5.0) -> np.ndarray:
    """Integrated autocorrelation time per parameter of ``chain`` ``(steps, walkers, k)`` [steps].

    emcee's estimator (``emcee.autocorr.integrated_time(chain, c, tol=0)``): the walkers' normalised
    autocorrelation functions are averaged, ``τ(M) = 2 Σ_{t ≤ M} ρ(t) − 1``, and the window M is the first with
    ``M ≥ c τ(M)`` (Sokal), else the last lag. NaN for a constant parameter.

    The averaged function is first computed only up to lag ``steps/4`` (:func:`_mean_autocorrelation`, a
    shorter transform); where the window lies beyond, for any parameter, again at every lag. A chain long
    enough to stop (``steps > 50 τ``) has its window near ``c τ < steps/10``, so the τ checks between blocks
    pay the short transform.
    """
    chain = np.asarray(chain, dtype=np.float64)
    steps, walkers, k = chain.shape
    out = np.full(k, np.nan)
    for lags in (max(1, steps // 4), steps):
        taus = 2.0 * np.cumsum(_mean_autocorrelation(chain, lags), axis=0) - 1.0  # (lags, k)
        found = True
        for d in range(k):
            m = np.arange(lags) < c * taus[:, d]
            if np.any(~m):
                out[d] = taus[int(np.argmin(m)), d]
            elif lags == steps:
                out[d] = taus[-1, d]
            else:
                found = False
        if found:
            break
    return out


#: Compiled with :data:`ringfit._cache.BALANCED_COMPILE` (the CPU backend at optimisation level 1): a cold
#: process compiles the free table's block in ~1–2 s. The model appears once in the program: every half-step,
#: and the starting densities (two first, "init" half-steps that move nothing), run through one loop body.
#: Every random number of a block is drawn before the loop, in a few vectorised calls (drawn inside the loop
#: body, a dozen small threefry programs per step cost more than the free table's model itself; the random
#: split is the ranks of random words, XLA's CPU sort of 32 keys being ~10× dearer), and a half-step only
#: reorders the walkers (one gather) so that the moving half is a static slice. Measured on the free table
#: (32 walkers, a shared 2-core machine at load ~10): ~25 µs of CPU per step with the lean density
#: (:class:`~ringfit.fit.engine.DensityKernel`), against ~100 µs for the loop that drew its random numbers per
#: step and moved each half by scatter.
@functools.partial(jit, quick="balanced", static_argnames=("kernel", "steps", "a"))
def _block(x, key, consts, *, kernel, steps: int, a: float = STRETCH_A):
    """``steps`` stretch moves of ``C`` ensembles from ``x`` ``(C, W, k)``: one compiled program.

    The loop runs over half-steps on the walkers of every ensemble in one flat array of ``C·W`` slots: the
    first ``C·h`` (``h = W/2``, ensemble c's at ``c·h …``) move, each against a walker of its own ensemble in
    the last ``C·h`` held fixed. Before half-step t the slots are reordered by a permutation ``perm[t]`` that
    keeps every walker within its ensemble. A step is two half-steps: per ensemble a uniformly random
    permutation (emcee's ``randomize_split``), then the swap of its two halves, so that the other half moves
    against the updated first, exactly emcee's order. Which walker sits in which slot (``who``) travels with
    the state; the draws are put back in walker order after the loop.

    **Returns:** ``(chain (steps, C, W, k), log_prob (steps, C, W), accepted (C, W) counts, key)``.
    """
    C, W, k = x.shape
    h = W // 2
    n = 2 * steps + 2  # two init half-steps (the start's densities, no move), then two per step
    key, k_perm, k_z, k_pick, k_acc = jax.random.split(key, 5)
    local = jnp.arange(W, dtype=jnp.int32)
    swap = jnp.roll(local, h)
    # a uniformly random permutation per step and ensemble: the ranks of W random words, ties broken by position
    # (XLA's sort on the CPU is ~10× slower than these W² comparisons at these sizes)
    bits = jax.random.bits(k_perm, (steps, C, W), dtype=jnp.uint32)
    bi, bj = bits[..., :, None], bits[..., None, :]
    shuffle = jnp.sum((bj < bi) | ((bj == bi) & (local[None, :] < local[:, None])), axis=-1, dtype=jnp.int32)
    # local permutations (n, C, W): position q of ensemble c takes the walker at position perm[q]
    perm = jnp.concatenate([jnp.broadcast_to(local, (1, C, W)), jnp.broadcast_to(swap, (1, C, W)),
                            jnp.stack([shuffle, jnp.broadcast_to(swap, (steps, C, W))], axis=1).reshape(-1, C, W)])
    # local position q of ensemble c -> flat slot: moving half first, then the fixed half
    chain_of = jnp.arange(C, dtype=jnp.int32)[None, :, None]
    slot = jnp.where(perm < h, chain_of * h + perm, C * h + chain_of * h + perm - h)  # (n, C, W)
    perm = jnp.concatenate([slot[..., :h].reshape(n, C * h), slot[..., h:].reshape(n, C * h)], axis=1)
    z = ((a - 1.0) * jax.random.uniform(k_z, (n, C * h), dtype=x.dtype) + 1.0) ** 2 / a  # g(z) ∝ 1/√z on [1/a, a]
    partner = C * h + (jnp.arange(C * h, dtype=jnp.int32) // h) * h + jax.random.randint(
        k_pick, (n, C * h), 0, h, dtype=jnp.int32)
    log_u = jnp.log(jax.random.uniform(k_acc, (n, C * h), dtype=x.dtype))
    init = jnp.arange(n) < 2

    def half(carry, inputs):
        x, lp, who = carry
        p, zz, pk, lu, first = inputs
        x, lp, who = x[p], lp[p], who[p]
        xa, lpa, xp = x[: C * h], lp[: C * h], x[pk]
        y = jnp.where(first, xa, xp + zz[:, None] * (xa - xp))
        lpy = kernel(y, consts)
        accept = (lu < (k - 1) * jnp.log(zz) + lpy - lpa) | first
        x = jnp.concatenate([jnp.where(accept[:, None], y, xa), x[C * h :]])
        lp = jnp.concatenate([jnp.where(accept, lpy, lpa), lp[C * h :]])
        return (x, lp, who), (x, lp, who, accept & ~first)

    # the start in the slot layout: ensemble c's walkers 0 … h−1 in the moving half, h … W−1 in the fixed one
    ids = jnp.arange(C * W, dtype=jnp.int32).reshape(C, 2, h).transpose(1, 0, 2).reshape(-1)  # walker c·W + w
    start = (x.reshape(C * W, k)[ids], jnp.zeros(C * W, dtype=x.dtype), ids)
    _, (xs, lps, whos, accepted) = jax.lax.scan(half, start, (perm, z, partner, log_u, init))
    counts = jnp.zeros(C * W, jnp.int32).at[whos[:, : C * h]].add(accepted.astype(jnp.int32))
    xs, lps, whos = xs[3::2], lps[3::2], whos[3::2]  # the state after each whole step
    rows = jnp.arange(steps)[:, None]
    xs = jnp.zeros_like(xs).at[rows, whos].set(xs).reshape(steps, C, W, k)  # back in walker order
    lps = jnp.zeros_like(lps).at[rows, whos].set(lps).reshape(steps, C, W)
    return xs, lps, counts.reshape(C, W), key


class CompiledRun:
    """What :func:`run_compiled` returns: ``chain`` ``(steps, C·W, k)`` (ensembles side by side along the walker
    axis), ``log_prob`` ``(steps, C·W)``, ``acceptance`` ``(C·W,)`` fractions, ``tau`` ``(k,)``, ``chains`` C."""

    def __init__(self, chain, log_prob, acceptance, tau, chains):
        self.chain, self.log_prob, self.acceptance, self.tau, self.chains = chain, log_prob, acceptance, tau, chains


def run_compiled(kernel, consts, p0, *, min_steps: int, max_steps: int, block: int, seed: int = 0,
                 tau_factor: float = 50.0, progress: bool = False, interrupted=None) -> CompiledRun:
    """Run the compiled stretch move from ``p0`` ``(C, W, k)`` in blocks of ``block`` steps until the chain is
    longer than ``tau_factor`` × the largest integrated τ (and at least ``min_steps``), or ``max_steps``.

    **Arguments:** ``kernel``, ``consts`` — :func:`ringfit.fit.engine.log_density`; ``p0`` — start, every
    walker inside the support; ``block`` — steps per compiled call (the τ check runs between blocks; every
    block is the same program); ``seed``; ``progress`` — a tqdm bar on stderr; ``interrupted`` — an
    ``Event`` read between blocks (set: ``KeyboardInterrupt``).

    **Returns:** :class:`CompiledRun` (the chain cut to ``max_steps``).
    """
    p0 = np.asarray(p0, dtype=np.float64)
    C, W, k = p0.shape
    block = int(max(1, block))
    # host arrays in, host arrays back: every block sees the same argument types (one executable)
    key = np.asarray(jax.random.PRNGKey(int(seed)))
    x = p0
    chains, lps = [], []
    accepted = np.zeros((C, W))
    done = 0
    tau = np.full(k, np.inf)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=min_steps, desc="sampling", unit="step", leave=False)
    try:
        while done < max_steps:
            xs, lp, acc, key = _block(x, key, consts, kernel=kernel, steps=block)
            xs, lp, key = np.asarray(xs), np.asarray(lp), np.asarray(key)
            x = xs[-1]
            chains.append(xs.reshape(block, C * W, k))
            lps.append(lp.reshape(block, C * W))
            accepted += np.asarray(acc)
            done += block
            if interrupted is not None and interrupted.is_set():
                raise KeyboardInterrupt
            chain = np.concatenate(chains) if len(chains) > 1 else chains[0]
            chains = [chain]
            if done < min_steps and done < max_steps and bar is None:
                continue  # no stop before min_steps: τ is estimated from there on
            tau = integrated_time(chain[:max_steps])
            if bar is not None:
                t = float(np.max(tau))
                need = int(min(max_steps, max(min_steps, tau_factor * t))) if math.isfinite(t) else bar.total
                bar.total = max(bar.total, need, min(done, max_steps))
                bar.update(min(done, max_steps) - bar.n)
                bar.set_postfix_str(f"τ≈{t:.0f}")
            if done >= min_steps and np.all(np.isfinite(tau)) and min(done, max_steps) > tau_factor * np.max(tau):
                break
    finally:
        if bar is not None:
            bar.close()
    chain = np.concatenate(chains)[:max_steps]
    log_prob = np.concatenate(lps)[:max_steps]
    # acceptance counted over every step run (a last block cut at max_steps counts whole)
    acceptance = (accepted / max(done, 1)).reshape(C * W)
    return CompiledRun(chain, log_prob, acceptance, tau, C)


__all__ = ["run_compiled", "integrated_time", "autocorrelation", "CompiledRun", "STRETCH_A"]
