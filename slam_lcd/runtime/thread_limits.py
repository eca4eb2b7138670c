"""Thread counts of numpy's BLAS and faiss inside the loop-detection thread (``run.lcd_threads``).

Why: with background extraction, SuperPoint's forward (torch's own thread pool) runs while the
main thread detects loops. Loop detection's products are small (one image against another, a
few hundred words), and OpenBLAS's and OpenMP's worker threads keep spinning after each call:
on two cores, two BLAS threads plus two faiss threads plus two torch threads fight over the
cores and everything waits. Limiting the main thread's libraries to one thread leaves the other
core to the extraction. The BLAS pools are looked up once per process (threadpoolctl); faiss's
OpenMP thread count is set for the calling thread only and restored afterwards.
"""
from __future__ import annotations

import contextlib
from types import ModuleType

_CONTROLLER = None


def blas_limit(n: int):
    """Context with at most ``n`` threads in numpy's BLAS (its thread pools are looked up once per process)."""
    global _CONTROLLER
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        return contextlib.nullcontext()
    if _CONTROLLER is None:
        _CONTROLLER = ThreadpoolController()
    return _CONTROLLER.limit(limits=n, user_api="blas")


@contextlib.contextmanager
def limited_threads(n: int):
    """Run the body with at most ``n`` BLAS threads and ``n`` faiss (OpenMP) threads; ``n <= 0``: unchanged."""
    if n <= 0:
        yield
        return
    faiss: ModuleType | None
    try:
        import faiss
    except ImportError:  # pragma: no cover - faiss-cpu is a dependency
        faiss = None
    before = 0  # faiss's thread count, restored afterwards
    if faiss is not None:
        before = faiss.omp_get_max_threads()
        faiss.omp_set_num_threads(min(n, before))
    try:
        with blas_limit(n):
            yield
    finally:
        if faiss is not None:
            faiss.omp_set_num_threads(before)
