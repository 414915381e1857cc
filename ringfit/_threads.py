"""The BLAS thread limiter, in one place below every layer that uses it (threadpoolctl; no NumPy, no JAX).

- :func:`small_matrix_threads` — a context manager: one BLAS thread for loops of small dense problems
  (eig of ≤ 200 × 200: the SSI order sweep, the fits' covariance algebra, the Campbell diagram's
  eigenproblems). Multi-threaded BLAS on matrices this small only adds synchronisation; on a loaded
  machine it made the SSI order sweep 30× slower. One ``threadpoolctl.ThreadpoolController`` is kept
  (finding the BLAS libraries costs ~1 ms; setting the limit ~20 µs).
- :func:`limit_threads` — one BLAS/OpenMP thread for the rest of this process (a batch worker; Dask's
  nanny sets ``OMP/MKL/OPENBLAS_NUM_THREADS=1`` for the workers it starts, this covers the others).
"""

from __future__ import annotations

import functools


@functools.lru_cache(maxsize=1)
def _controller():
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def small_matrix_threads():
    """Context manager: one BLAS thread inside the block (see the module docstring)."""
    return _controller().limit(limits=1, user_api="blas")


_PROCESS_LIMIT: list = []  # the process-wide limit holds while referenced


def limit_threads() -> None:
    """One BLAS/OpenMP thread in this process, from now on (idempotent; a missing or odd BLAS is ignored)."""
    if _PROCESS_LIMIT:
        return
    try:
        from threadpoolctl import threadpool_limits

        _PROCESS_LIMIT.append(threadpool_limits(limits=1))
    except Exception:  # noqa: BLE001 - a missing or odd BLAS must not stop the worker
        _PROCESS_LIMIT.append(None)
