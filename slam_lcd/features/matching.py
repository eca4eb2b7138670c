"""Descriptor matching shared by every stage (vocabulary training, verification, VO).

Mutual nearest neighbours keep only one-to-one matches, which is what the paper's graph
verification starts from; an optional Lowe ratio test and a distance bound prune the rest.
Float descriptors (SuperPoint, unit vectors) use L2 distance; uint8 descriptors (ORB)
use Hamming distance.

:func:`mutual_nn_match` works on a numpy distance matrix; :func:`mutual_nn_match_bf` applies
the same rule through OpenCV's brute-force matcher, which is several times faster for ORB
descriptors and for the many candidate pairs that loop verification checks.
"""
from __future__ import annotations

import cv2
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


def mutual_nn_match_bf(
    d1: np.ndarray,
    d2: np.ndarray,
    ratio: float | None = None,
    max_distance: float | None = None,
    *,
    ratio_floor: float = 1e-12,
    max_inclusive: bool = False,
) -> np.ndarray:
    """:func:`mutual_nn_match` on OpenCV's brute-force matcher: one-to-one matches ``(M, 2)``.

    L2 for float descriptors, Hamming for uint8. A match is kept if it is mutual, if
    ``best < ratio * max(second, ratio_floor)`` (when ``ratio`` is given and ``d2`` has two
    rows or more) and if ``best < max_distance`` (``<=`` with ``max_inclusive``).
    The front end's tracker uses ``ratio_floor=0, max_inclusive=True``.
    """
    empty = np.zeros((0, 2), np.int64)
    if len(d1) == 0 or len(d2) == 0:
        return empty
    binary = d1.dtype == np.uint8
    norm = cv2.NORM_HAMMING if binary else cv2.NORM_L2
    a = np.ascontiguousarray(d1 if binary else d1.astype(np.float32))
    b = np.ascontiguousarray(d2 if binary else d2.astype(np.float32))
    bf = cv2.BFMatcher(norm, crossCheck=False)
    k = 2 if (ratio is not None and len(b) > 1) else 1
    fwd = bf.knnMatch(a, b, k=k)
    back = bf.match(b, a)
    nn21 = np.full(len(b), -1, np.int64)
    for m in back:
        nn21[m.queryIdx] = m.trainIdx
    out = []
    for row in fwd:
        if not row:
            continue
        best = row[0]
        if nn21[best.trainIdx] != best.queryIdx:
            continue
        if k == 2 and len(row) > 1 and not best.distance < ratio * max(row[1].distance, ratio_floor):
            continue
        if max_distance is not None:
            if max_inclusive and not best.distance <= max_distance:
                continue
            if not max_inclusive and not best.distance < max_distance:
                continue
        out.append((best.queryIdx, best.trainIdx))
    return np.asarray(out, dtype=np.int64).reshape(-1, 2)
