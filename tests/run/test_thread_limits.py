"""run.lcd_threads: the loop-detection thread's BLAS and faiss thread counts are limited and restored."""
from __future__ import annotations

import threading

import faiss
from threadpoolctl import threadpool_info

from slam_lcd.runtime.thread_limits import limited_threads


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_limits_blas_and_faiss_and_restores_them():
    faiss.omp_set_num_threads(2)
    blas_before = _blas_threads()
    with limited_threads(1):
        assert faiss.omp_get_max_threads() == 1
        assert all(n == 1 for n in _blas_threads())
    assert faiss.omp_get_max_threads() == 2
    assert _blas_threads() == blas_before


def test_zero_leaves_the_libraries_alone():
    faiss.omp_set_num_threads(2)
    with limited_threads(0):
        assert faiss.omp_get_max_threads() == 2


def test_faiss_limit_is_for_the_calling_thread_only():
    """Another thread (e.g. background extraction) keeps its own OpenMP thread count."""
    faiss.omp_set_num_threads(2)
    seen = []
    with limited_threads(1):
        t = threading.Thread(target=lambda: seen.append(faiss.omp_get_max_threads()))
        t.start()
        t.join()
    assert faiss.omp_get_max_threads() == 2
    assert seen == [2]
