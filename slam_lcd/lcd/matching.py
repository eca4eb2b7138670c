"""One-to-one descriptor matching for loop verification (OpenCV brute force).

Same rule as :func:`slam_lcd.features.matching.mutual_nn_match` (mutual nearest neighbours,
optional Lowe ratio and distance bound; L2 for float descriptors, Hamming for uint8), but on
OpenCV's brute-force matcher, which is several times faster for the hundreds of candidate
pairs that an evaluation verifies.
"""
from __future__ import annotations

import cv2
import numpy as np


def match_mutual(d1: np.ndarray, d2: np.ndarray, ratio: float | None = None,
                 max_distance: float | None = None) -> np.ndarray:
    """Mutual nearest-neighbour matches ``(M, 2)`` of row indices ``[i1, i2]``."""
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
        if k == 2 and len(row) > 1 and not best.distance < ratio * max(row[1].distance, 1e-12):
            continue
        if max_distance is not None and not best.distance < max_distance:
            continue
        out.append((best.queryIdx, best.trainIdx))
    return np.asarray(out, dtype=np.int64).reshape(-1, 2)
