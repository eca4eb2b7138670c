"""Epipolar geometry of two calibrated views: essential-matrix RANSAC and the relative pose.

Points are undistorted to the unit-depth plane first, so one pixel threshold (divided by
the focal length) works for every distortion model. :func:`essential_ransac` is the one
essential-matrix RANSAC of slam-lcd (loop verification and the front end's two-view
geometry call it, each with its own OpenCV USAC variant).
"""
from __future__ import annotations

import cv2
import numpy as np

from ..types import CameraModel
from .camera import undistort_points


def essential_ransac(x1: np.ndarray, x2: np.ndarray, threshold: float, confidence: float,
                     method: int) -> tuple[np.ndarray | None, np.ndarray]:
    """``(E or None, inlier mask)`` for normalised points with ``x2^T E x1 = 0``.

    ``threshold`` is in normalised-plane units; ``method`` an OpenCV USAC flag. When OpenCV
    returns several solutions the first is kept.
    """
    E, mask = cv2.findEssentialMat(x1, x2, np.eye(3), method=method, prob=confidence, threshold=threshold)
    if E is None or mask is None or E.shape[0] < 3:
        return None, np.zeros(len(x1), bool)
    return E[:3], mask.reshape(-1) > 0


def triangulate_depths(R, t, n1, n2):
    """Depths of each correspondence in both cameras (midpoint-free linear DLT on normalised points)."""
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = np.hstack([R, t.reshape(3, 1)])
    X = cv2.triangulatePoints(P1, P2, n1.T.astype(np.float64), n2.T.astype(np.float64))
    X = X[:3] / np.where(np.abs(X[3]) < 1e-12, 1e-12, X[3])
    z1 = X[2]
    z2 = (R @ X + t.reshape(3, 1))[2]
    return z1, z2


def choose_decomposition(E, n1, n2):
    """``(R, t, in_front)``: of the four E decompositions the one with most points in front of both cameras.

    No far-point cut-off (unlike ``cv2.recoverPose``, which drops points farther than 50
    baselines and so empties the inlier set of a small-baseline pair: a revisit seen from
    nearly the same pose, or a loop candidate under a guessed focal length).
    """
    R1, R2, t = cv2.decomposeEssentialMat(E)
    t = t.reshape(3)
    best = None
    for R in (R1, R2):
        for tt in (t, -t):
            z1, z2 = triangulate_depths(R, tt, n1, n2)
            good = (z1 > 0) & (z2 > 0)
            if best is None or good.sum() > best[2].sum():
                best = (R, tt, good)
    return best


def cheirality_mask(R, t, n1, n2, far_baselines: float = 50.0) -> np.ndarray:
    """Correspondences not contradicting ``(R, t)``: in front of both cameras, or too far to tell.

    A point triangulated beyond ``far_baselines`` (unit baseline) has under ~1 deg of parallax:
    noise decides the sign of its depth, so it is kept rather than counted as behind (the
    opposite of ``cv2.recoverPose``, which drops every far point).
    """
    z1, z2 = triangulate_depths(R, t, n1, n2)
    front = (z1 > 0) & (z2 > 0)
    far = ~np.isfinite(z1) | (np.abs(z1) > far_baselines) | (np.abs(z2) > far_baselines)
    return front | far


def sampson_errors(R, t, n1, n2):
    """Sampson distances (normalised-plane units) of correspondences to ``E = [t]x R``."""
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    E = tx @ R
    x1 = np.column_stack([n1, np.ones(len(n1))])
    x2 = np.column_stack([n2, np.ones(len(n2))])
    Ex1 = x1 @ E.T
    Etx2 = x2 @ E
    num = np.sum(x2 * Ex1, axis=1)
    den = Ex1[:, 0] ** 2 + Ex1[:, 1] ** 2 + Etx2[:, 0] ** 2 + Etx2[:, 1] ** 2
    return num / np.sqrt(np.maximum(den, 1e-30))


def refine_relative_pose(R, t, n1, n2, scale: float):
    """Minimise the robust (Huber) Sampson error over rotation and translation direction."""
    from scipy.optimize import least_squares

    from ..geometry import so3_exp  # lazy: scipy

    t = t / np.linalg.norm(t)
    # tangent basis of the unit sphere at t
    a = np.array([1.0, 0, 0]) if abs(t[0]) < 0.9 else np.array([0, 1.0, 0])
    b1 = np.cross(t, a)
    b1 /= np.linalg.norm(b1)
    b2 = np.cross(t, b1)

    def unpack(x):
        Rn = so3_exp(x[:3]) @ R
        tn = t + x[3] * b1 + x[4] * b2
        return Rn, tn / np.linalg.norm(tn)

    def fun(x):
        Rn, tn = unpack(x)
        return sampson_errors(Rn, tn, n1, n2) * scale

    res = least_squares(fun, np.zeros(5), loss="huber", f_scale=1.0, method="trf")
    return unpack(res.x)


def relative_pose_from_points(camera: CameraModel, pts1: np.ndarray, pts2: np.ndarray,
                              threshold_px: float = 1.0, confidence: float = 0.9999,
                              camera2: CameraModel | None = None, refine: bool = True):
    """``(R, t, inlier_mask)`` from matched pixel coordinates (distorted, as detected).

    RANSAC on the essential matrix (OpenCV USAC with local optimisation), the decomposition
    with most points in front of both cameras (no far-point cut-off, so small baselines
    keep their inliers), then a robust Sampson-error refinement of the rotation and the
    translation direction over the inliers.
    """
    n1 = undistort_points(camera, pts1, normalized=True)
    n2 = undistort_points(camera2 or camera, pts2, normalized=True)
    f = 0.5 * (camera.fx + camera.fy)
    if len(n1) < 8:
        return None, None, np.zeros(len(n1), bool)
    E, inl = essential_ransac(n1, n2, threshold_px / f, confidence, cv2.USAC_ACCURATE)
    if E is None:
        return None, None, np.zeros(len(n1), bool)
    R, t, front = choose_decomposition(E, n1[inl], n2[inl])
    if refine and inl.sum() >= 8:
        R, t = refine_relative_pose(R, t, n1[inl], n2[inl], scale=f / threshold_px)
        err = np.abs(sampson_errors(R, t, n1, n2)) * f
        inl = err < threshold_px
    z1, z2 = triangulate_depths(R, t, n1, n2)
    inl &= (z1 > 0) & (z2 > 0) | ~np.isfinite(z1)
    return R, t, inl
