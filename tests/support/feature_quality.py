"""Feature quality under known geometry (used by the tests and tools/bench_features.py).

- Homography warps of a real image give exact ground-truth correspondences: keypoint
  repeatability (the SuperPoint paper's definition: a keypoint counts as repeated if the
  other image has a keypoint within ``thr`` pixels of its warped position, both directions,
  only points seen in both images counted) and mutual-nearest-neighbour matching precision
  (fraction of mutual-NN matches whose warped position is within ``thr`` pixels).
- Two real consecutive frames: the inlier ratio of a RANSAC fundamental matrix fitted to
  the mutual-NN matches.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from slam_lcd.features.matching import mutual_nn_match
from slam_lcd.types import Features


def homography_about_centre(w: int, h: int, angle_deg: float = 0.0, scale: float = 1.0,
                            shift=(0.0, 0.0), perspective=(0.0, 0.0)) -> np.ndarray:
    """A homography that rotates/scales about the image centre, shifts (pixels) and tilts."""
    c = np.array([[1, 0, -w / 2], [0, 1, -h / 2], [0, 0, 1]], float)
    a = np.deg2rad(angle_deg)
    rs = np.array([[scale * np.cos(a), -scale * np.sin(a), 0], [scale * np.sin(a), scale * np.cos(a), 0], [0, 0, 1]])
    p = np.array([[1, 0, 0], [0, 1, 0], [perspective[0], perspective[1], 1]], float)
    t = np.array([[1, 0, w / 2 + shift[0]], [0, 1, h / 2 + shift[1]], [0, 0, 1]], float)
    return t @ p @ rs @ c


def random_homography(rng: np.random.Generator, w: int, h: int, strength: float = 1.0) -> np.ndarray:
    """A moderate random viewpoint change: rotation up to 15 deg, scale 0.8-1.25, tilt, shift."""
    s = strength
    return homography_about_centre(
        w, h,
        angle_deg=rng.uniform(-15, 15) * s,
        scale=float(np.exp(rng.uniform(-0.22, 0.22) * s)),
        shift=(rng.uniform(-0.05, 0.05) * w * s, rng.uniform(-0.05, 0.05) * h * s),
        perspective=(rng.uniform(-1, 1) * 2e-4 * s * 640 / w, rng.uniform(-1, 1) * 2e-4 * s * 480 / h),
    )


def warp_image(image: np.ndarray, H: np.ndarray) -> np.ndarray:
    h, w = image.shape[:2]
    return cv2.warpPerspective(image, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


def warp_points(pts: np.ndarray, H: np.ndarray) -> np.ndarray:
    if len(pts) == 0:
        return np.zeros((0, 2), np.float64)
    p = np.concatenate([pts.astype(np.float64), np.ones((len(pts), 1))], axis=1) @ H.T
    return p[:, :2] / p[:, 2:3]


def _inside(pts: np.ndarray, size, margin: float = 0.0) -> np.ndarray:
    w, h = size
    return (pts[:, 0] >= margin) & (pts[:, 1] >= margin) & (pts[:, 0] <= w - 1 - margin) & (pts[:, 1] <= h - 1 - margin)


@dataclass
class HomographyScores:
    repeatability: float
    precision: float  # correct mutual-NN matches / mutual-NN matches
    n_matches: int
    n_correct: int
    n_keypoints: tuple[int, int]


def homography_scores(
    f1: Features, f2: Features, H: np.ndarray, thr: float = 3.0, border: float = 4.0
) -> HomographyScores:
    """Repeatability and mutual-NN precision of ``f1`` (image) vs ``f2`` (image warped by ``H``)."""
    Hinv = np.linalg.inv(H)
    k1, k2 = f1.keypoints.astype(np.float64), f2.keypoints.astype(np.float64)
    w12 = warp_points(k1, H)
    w21 = warp_points(k2, Hinv)
    # only points whose correspondence lies in the other image (away from the warp's border)
    v1 = _inside(w12, f2.image_size, border)
    v2 = _inside(w21, f1.image_size, border)
    a, b = w12[v1], k2[v2]
    if len(a) and len(b):
        d = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=2)
        c1 = int((d.min(1) <= thr).sum())
        c2 = int((d.min(0) <= thr).sum())
        rep = (c1 + c2) / (len(a) + len(b))
    else:
        rep = 0.0
    m = mutual_nn_match(f1.descriptors, f2.descriptors)
    if len(m):
        err = np.linalg.norm(w12[m[:, 0]] - k2[m[:, 1]], axis=1)
        n_correct = int((err <= thr).sum())
        prec = n_correct / len(m)
    else:
        n_correct, prec = 0, 0.0
    return HomographyScores(float(rep), float(prec), int(len(m)), n_correct, (len(k1), len(k2)))


@dataclass
class EpipolarScores:
    n_matches: int
    n_inliers: int
    inlier_ratio: float
    F: np.ndarray | None


def fundamental_inliers(f1: Features, f2: Features, thr_px: float = 1.0, seed: int = 0) -> EpipolarScores:
    """Fit a fundamental matrix to the mutual-NN matches with RANSAC (fixed seed)."""
    m = mutual_nn_match(f1.descriptors, f2.descriptors)
    if len(m) < 8:
        return EpipolarScores(len(m), 0, 0.0, None)
    p1 = f1.keypoints[m[:, 0]].astype(np.float64)
    p2 = f2.keypoints[m[:, 1]].astype(np.float64)
    cv2.setRNGSeed(seed)
    F, mask = cv2.findFundamentalMat(p1, p2, cv2.FM_RANSAC, thr_px, 0.999, 10000)
    if F is None or mask is None:
        return EpipolarScores(len(m), 0, 0.0, None)
    n_in = int(mask.ravel().astype(bool).sum())
    return EpipolarScores(len(m), n_in, n_in / len(m), F[:3])
