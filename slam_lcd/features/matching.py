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

from ..vision.column_best import first_in_column

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


def _nearest_two(d1: np.ndarray, d2: np.ndarray, k: int, column_second: bool = False):
    """Per row of ``d1``: index and distance of its nearest ``d2`` row, the second distance (k=2),
    whether the row is also its nearest row's nearest (first) ``d1`` row (the mutual check), and with
    ``column_second`` (float only, else None) the second smallest distance of each ``d2`` row's column.

    uint8 (Hamming): OpenCV's ``batchDistance``, the routine inside its brute-force matcher,
    so values and ties (the first index wins) are the matcher's own. Float (L2): one float32
    BLAS product, ``|a|^2 + |b|^2 - 2 a.b``, then arg-minima (first index wins); it differs
    from OpenCV's direct sum of squares only by rounding (~1e-7 on unit descriptors) and
    takes ~4 ms instead of ~34 ms for 1000 x 1000 SuperPoint descriptors on one core. The
    mutual check reads the column minima (:mod:`slam_lcd.vision.column_best`, the same answer as a
    column argmin in a fifth of the time), and the columns' second distances come from the
    same product (a symmetric ratio needs them; they cost one more reduction, not a product).
    """
    rows = np.arange(len(d1))
    if d1.dtype == np.uint8:
        a, b = np.ascontiguousarray(d1), np.ascontiguousarray(d2)
        dist, idx = cv2.batchDistance(a, b, cv2.CV_32S, normType=cv2.NORM_HAMMING, K=k)
        _, back = cv2.batchDistance(b, a, cv2.CV_32S, normType=cv2.NORM_HAMMING, K=1)
        second = dist[:, 1].astype(np.float64) if k == 2 else None
        nn12 = idx[:, 0].astype(np.int64)
        return nn12, dist[:, 0].astype(np.float64), second, back[nn12, 0] == rows, None
    a = np.asarray(d1, dtype=np.float32)
    b = np.asarray(d2, dtype=np.float32)
    sq = (a * np.float32(-2.0)) @ b.T  # scaling by -2 is exact: the same bits as scaling the product, on fewer numbers
    sq += np.einsum("ij,ij->i", a, a)[:, None]
    sq += np.einsum("ij,ij->i", b, b)[None, :]
    np.maximum(sq, 0.0, out=sq)
    nn12 = sq.argmin(1)
    best_sq = sq[rows, nn12]
    mutual = first_in_column(sq, nn12, best_sq, largest=False)
    best = np.sqrt(best_sq).astype(np.float64)
    col_second = None
    if column_second:  # each column without its first best row (a mutual pair's own entry)
        first_rows = np.flatnonzero(mutual)
        sq[first_rows, nn12[first_rows]] = np.inf
        col_second = np.sqrt(sq.min(0)).astype(np.float64) if len(sq) > 1 else np.full(sq.shape[1], np.inf)
    second = None
    if k == 2:  # second smallest of each row: the smallest once the best is masked (cheaper than a partition)
        sq[rows, nn12] = np.inf
        second = np.sqrt(sq.min(1)).astype(np.float64)
    return nn12.astype(np.int64), best, second, mutual, col_second


def mutual_nn_match_bf(
    d1: np.ndarray,
    d2: np.ndarray,
    ratio: float | None = None,
    max_distance: float | None = None,
    *,
    ratio_floor: float = 1e-12,
    max_inclusive: bool = False,
    return_distances: bool = False,
):
    """:func:`mutual_nn_match` by brute force, without Python loops: one-to-one matches ``(M, 2)``.

    L2 for float descriptors, Hamming for uint8 (see :func:`_nearest_two`). A match is
    kept if it is mutual, if ``best < ratio * max(second, ratio_floor)`` (when ``ratio`` is
    given and ``d2`` has two rows or more) and if ``best < max_distance`` (``<=`` with
    ``max_inclusive``). The front end's tracker uses ``ratio_floor=0, max_inclusive=True``.
    With ``return_distances`` also the (M,) distances of the kept matches (float64).

    The rule and the comparisons (float64, strict) are those of ``cv2.BFMatcher.knnMatch``/``match``
    and a Python loop over their results (the reference in ``tests/features/test_matching_bf.py``).
    """
    empty = np.zeros((0, 2), np.int64)
    n1, n2 = len(d1), len(d2)
    if n1 == 0 or n2 == 0:
        return (empty, np.zeros(0)) if return_distances else empty
    k = 2 if (ratio is not None and n2 > 1) else 1
    nn12, best, second, keep, _ = _nearest_two(d1, d2, k)
    rows = np.arange(n1)
    if k == 2:
        keep &= best < ratio * np.maximum(second, ratio_floor)
    if max_distance is not None:
        keep &= (best <= max_distance) if max_inclusive else (best < max_distance)
    m = np.stack([rows[keep], nn12[keep]], axis=1).astype(np.int64)
    return (m, best[keep]) if return_distances else m


def mutual_nn_match_symmetric(d1: np.ndarray, d2: np.ndarray, max_distance: float | None = None,
                              with_ratios: bool = True):
    """Mutual nearest neighbours with a ratio that does not depend on which side is which.

    Returns ``(matches (M, 2), distances (M,), ratios (M,))``: the one-to-one matches (mutual
    nearest neighbours, ``distance < max_distance`` when given), their distances and, per
    match, ``best / min(second best in its row, second best in its column)``, so a ratio test
    ``ratios < r`` asks the match to be distinctive in *both* images: swapping ``d1`` and
    ``d2`` gives the same matches (columns swapped) and the same ratios. A one-sided Lowe
    test (:func:`mutual_nn_match_bf` with ``ratio``) keeps a pair in one direction and drops
    it in the other. ``with_ratios=False``: no second-best search, ``ratios`` is None (cheaper).
    """
    empty = np.zeros((0, 2), np.int64)
    n1, n2 = len(d1), len(d2)
    if n1 == 0 or n2 == 0:
        return empty, np.zeros(0), (np.zeros(0) if with_ratios else None)
    ratios_wanted = n2 > 1 and with_ratios
    nn12, best, second12, keep, col_second = _nearest_two(d1, d2, 2 if ratios_wanted else 1,
                                                          column_second=with_ratios)
    rows = np.arange(n1)
    if max_distance is not None:
        keep &= best < max_distance
    i, j = rows[keep], nn12[keep]
    if not with_ratios:
        return np.stack([i, j], axis=1).astype(np.int64), best[keep], None
    if col_second is not None:  # float: from the same product
        second21 = col_second[j]
    elif n1 > 1 and len(j):
        _, _, second21, _, _ = _nearest_two(d2[j], d1, 2)  # second best of each matched column
    else:
        second21 = np.full(len(j), np.inf)
    s12 = second12[keep] if second12 is not None else np.full(len(i), np.inf)
    second = np.minimum(s12, second21)
    ratios = best[keep] / np.maximum(second, 1e-12)
    return np.stack([i, j], axis=1).astype(np.int64), best[keep], ratios
