"""Descriptor matching for tracking: mutual nearest neighbours with a ratio test.

ORB (uint8) descriptors go through OpenCV's brute-force Hamming matcher, which is far
faster than a numpy popcount matrix at ~1000 features a frame; float descriptors
(SuperPoint) use :func:`slam_lcd.features.matching.mutual_nn_match`.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..features.matching import mutual_nn_match

DEFAULT_MAX_DISTANCE = {"uint8": 64.0, "float": 0.9}


def match_descriptors(d1: np.ndarray, d2: np.ndarray, ratio: float | None = 0.85,
                      max_distance: float | None = None) -> np.ndarray:
    """One-to-one matches ``(M, 2)`` of rows ``[i1, i2]``."""
    if d1 is None or d2 is None or len(d1) == 0 or len(d2) == 0:
        return np.zeros((0, 2), np.int64)
    if d1.dtype != np.uint8:
        if max_distance is None:
            max_distance = DEFAULT_MAX_DISTANCE["float"]
        return mutual_nn_match(d1, d2, ratio=ratio, max_distance=max_distance)
    if max_distance is None:
        max_distance = DEFAULT_MAX_DISTANCE["uint8"]
    bf = cv2.BFMatcher(cv2.NORM_HAMMING)
    k = 2 if (ratio is not None and len(d2) > 1) else 1
    fwd = bf.knnMatch(d1, d2, k=k)
    back = bf.match(d2, d1)
    best_back = np.full(len(d2), -1, np.int64)
    for m in back:
        best_back[m.queryIdx] = m.trainIdx
    out = []
    for cand in fwd:
        if not cand:
            continue
        m = cand[0]
        if m.distance > max_distance:
            continue
        if k == 2 and len(cand) > 1 and m.distance >= ratio * cand[1].distance:
            continue
        if best_back[m.trainIdx] != m.queryIdx:
            continue
        out.append((m.queryIdx, m.trainIdx))
    return np.asarray(out, np.int64).reshape(-1, 2)


def geometric_inliers(pts1: np.ndarray, pts2: np.ndarray, threshold_px: float = 2.0) -> np.ndarray:
    """Boolean mask of matches consistent with one fundamental matrix (RANSAC)."""
    n = len(pts1)
    if n < 12:
        return np.zeros(n, bool)
    F, mask = cv2.findFundamentalMat(np.asarray(pts1, np.float64), np.asarray(pts2, np.float64),
                                     cv2.FM_RANSAC, threshold_px, 0.999)
    if F is None or mask is None:
        return np.zeros(n, bool)
    return mask.reshape(-1).astype(bool)
