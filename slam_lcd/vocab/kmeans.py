"""Small spherical k-means (k-means++ seeding, Lloyd steps on dot products).

Used at every node of the hierarchical k-means baseline and to split over-wide DP parents;
thousands of tiny problems, so a few lines of numpy beat a library call per node.
"""
from __future__ import annotations

import numpy as np

from .descriptors import group_sums, nearest_by_dot, normalise_rows


def spherical_kmeans(x: np.ndarray, k: int, rng: np.random.Generator, iters: int = 10):
    """Cluster unit rows ``x`` into at most ``k`` groups; returns (labels, unit centres), no empty group."""
    n = len(x)
    if n <= k:
        return np.arange(n), normalise_rows(x.copy())
    # k-means++ seeding on squared chord distance 2 - 2 cos
    idx = [int(rng.integers(n))]
    d2 = np.maximum(2.0 - 2.0 * (x @ x[idx[0]]), 0.0)
    for _ in range(1, k):
        tot = d2.sum()
        if tot <= 1e-12:
            break
        j = int(np.searchsorted(np.cumsum(d2), rng.random() * tot))
        j = min(j, n - 1)
        idx.append(j)
        d2 = np.minimum(d2, np.maximum(2.0 - 2.0 * (x @ x[j]), 0.0))
    c = x[idx].copy()
    labels = np.zeros(n, dtype=np.int64)
    for it in range(iters):
        new = nearest_by_dot(x, c)
        if it and np.array_equal(new, labels):
            break
        labels = new
        c = normalise_rows(group_sums(x, labels, len(c)))
    used = np.unique(labels)
    remap = np.full(len(c), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    labels = remap[labels]
    return labels, normalise_rows(group_sums(x, labels, len(used)))
