"""One BLAS thread for loops of small dense problems (a module of its own: importing it costs nothing)."""

from __future__ import annotations

import functools


def small_matrix_threads():
    """Context manager: one BLAS thread for loops of small dense problems (eig of ≤ 200 × 200).

    Multi-threaded BLAS on matrices this small only adds synchronisation; on
    a loaded machine it made the order sweep 30× slower. One
    ``threadpoolctl.ThreadpoolController`` is kept (finding the BLAS
    libraries costs ~1 ms; setting the limit ~20 µs).
    """
    return _blas_controller().limit(limits=1, user_api="blas")


@functools.lru_cache(maxsize=1)
def _blas_controller():
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()
