"""faiss threads for the word index: searches on one OpenMP thread, insertions on one worker thread.

:func:`_one_faiss_thread` runs faiss on one OpenMP thread for a block; :func:`_insertion_thread`
is the process's one thread that inserts words into graphs (forgotten in a forked child), and
:func:`_add_on_one_thread` is what it runs (:mod:`slam_lcd.vocab.word_index`).
"""
from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np


@contextmanager
def _one_faiss_thread():
    """faiss on one OpenMP thread for the duration.

    Why for searches too: a keyframe's few hundred graph searches take ~10 ms; split over
    OpenMP threads they wait on each other whenever a core is busy with something else (the
    extraction workers of a run, another process), which measured twice as slow as one thread
    (18.9 vs 9.2 ms for 470 searches at 72k words, a loaded 2-core machine). The answer does not
    depend on the thread count.
    """
    import faiss

    threads = faiss.omp_get_max_threads()
    faiss.omp_set_num_threads(1)
    try:
        yield
    finally:
        faiss.omp_set_num_threads(threads)


_inserter: ThreadPoolExecutor | None = None
_inserter_lock = threading.Lock()


def _forget_inserter() -> None:
    """In a forked child: the parent's worker thread does not exist there; the child starts its own."""
    global _inserter, _inserter_lock
    _inserter, _inserter_lock = None, threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_inserter)


def _insertion_thread() -> ThreadPoolExecutor:
    """The one worker thread that inserts words into graphs (shared by every index of the process:
    an insertion is ~10 ms and one index waits for its own before the next use)."""
    global _inserter
    with _inserter_lock:
        if _inserter is None:
            _inserter = ThreadPoolExecutor(max_workers=1, thread_name_prefix="slam-lcd-words")
        return _inserter


def _add_on_one_thread(graph, rows: np.ndarray) -> float:
    """Insert ``rows`` (node i = word i) on one faiss thread; returns the CPU seconds it took."""
    t = time.thread_time()
    with _one_faiss_thread():  # the graph's links do not depend on scheduling
        graph.add(rows)
    return time.thread_time() - t
