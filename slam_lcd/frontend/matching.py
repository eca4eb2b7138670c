"""Descriptor matching for tracking: mutual nearest neighbours with a ratio test.

ORB (uint8) descriptors go through OpenCV's brute-force Hamming matcher
(:func:`slam_lcd.features.matching.mutual_nn_match_bf`), which is far faster than a numpy
popcount matrix at ~1000 features a frame; float descriptors (SuperPoint) use
:func:`slam_lcd.features.matching.mutual_nn_match`.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..features.matching import mutual_nn_match, mutual_nn_match_bf

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
    # the tracker's historical rule: keep best <= max_distance and best < ratio * second (no floor)
    return mutual_nn_match_bf(d1, d2, ratio=ratio, max_distance=max_distance, ratio_floor=0.0, max_inclusive=True)


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
