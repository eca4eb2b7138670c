"""Descriptor matching shared by every stage (vocabulary training, verification, VO).

Mutual nearest neighbours keep only one-to-one matches, which is what the paper's graph
verification starts from; an optional Lowe ratio test and a distance bound prune the rest.
Float descriptors (SuperPoint, unit vectors) use L2 distance; uint8 descriptors (ORB)
use Hamming distance.
"""
from __future__ import annotations

import numpy as np

_POPCOUNT = np.array([bin(i).count("1") for i in range(256)], dtype=np.uint8)


def descriptor_distances(d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
    """Pairwise distance matrix (N1, N2): L2 for float descriptors, Hamming bits for uint8."""
    if d1.dtype == np.uint8 or d2.dtype == np.uint8:
        x = np.bitwise_xor(d1[:, None, :], d2[None, :, :])
        return _POPCOUNT[x].sum(axis=2, dtype=np.int32).astype(np.float32)
    a = np.asarray(d1, dtype=np.float32)
    b = np.asarray(d2, dtype=np.float32)
    sq = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * (a @ b.T)
    return np.sqrt(np.maximum(sq, 0.0))


def mutual_nn_match(
    d1: np.ndarray,
    d2: np.ndarray,
    ratio: float | None = None,
    max_distance: float | None = None,
    return_distances: bool = False,
):
    """One-to-one matches ``(M, 2)`` of row indices ``[i1, i2]`` (mutual nearest neighbours).

    ``ratio``: keep a match only if best < ratio * second-best (in image 1's row).
    ``max_distance``: keep a match only if its distance is below this bound.
    """
    n1, n2 = len(d1), len(d2)
    empty = np.zeros((0, 2), dtype=np.int64)
    if n1 == 0 or n2 == 0:
        return (empty, np.zeros(0, np.float32)) if return_distances else empty
    dist = descriptor_distances(d1, d2)
    nn12 = dist.argmin(1)
    nn21 = dist.argmin(0)
    i1 = np.arange(n1)
    keep = nn21[nn12] == i1
    best = dist[i1, nn12]
    if ratio is not None and n2 > 1:
        part = np.partition(dist, 1, axis=1)[:, :2]
        second = part[:, 1]
        keep &= best < ratio * np.maximum(second, 1e-12)
    if max_distance is not None:
        keep &= best < max_distance
    m = np.stack([i1[keep], nn12[keep]], axis=1).astype(np.int64)
    if return_distances:
        return m, best[keep].astype(np.float32)
    return m
