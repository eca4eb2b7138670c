"""Landmarks for a monocular keyframe from its neighbours and the odometry baseline.

With one camera and external odometry (wheel, lidar) the metric baseline between two
keyframes is known, so matched keypoints can be triangulated at metric scale. Loop
verification needs these 3-D points to estimate a metric loop pose. Each point must
lie in front of both cameras, be seen under enough parallax and reproject within a few
pixels in both views; of several neighbours the triangulation with the largest parallax
wins.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..geometry import inv
from ..types import Keyframe
from ..vision.camera import undistort_points
from ..vision.gray import to_gray_uint8
from .config import FrontendConfig
from .matching import match_descriptors
from .two_view import refine_matches_klt


def _camera_pose(kf: Keyframe) -> np.ndarray:
    return kf.T_world_body @ kf.T_body_camera


def triangulate_pair(kf: Keyframe, other: Keyframe, conf: FrontendConfig | None = None):
    """Points for ``kf``'s keypoints from one neighbour: ``(points (N,3), parallax_deg (N,))``.

    Points are in ``kf``'s camera frame; NaN where no valid triangulation exists.
    """
    conf = conf or FrontendConfig()
    assert kf.features is not None and kf.camera is not None  # triangulate_landmarks checked both
    n = len(kf.features)
    pts = np.full((n, 3), np.nan)
    par = np.zeros(n)
    if other.features is None or len(other.features) == 0 or n == 0:
        return pts, par
    m = match_descriptors(kf.features.descriptors, other.features.descriptors, ratio=0.85)
    if len(m) < 8:
        return pts, par
    cam1, cam2 = kf.camera, other.camera or kf.camera
    T_21 = inv(_camera_pose(other)) @ _camera_pose(kf)  # kf camera -> other camera
    if np.linalg.norm(T_21[:3, 3]) < 1e-6:
        return pts, par  # no baseline, no depth
    p1 = kf.features.keypoints[m[:, 0]].astype(np.float64)
    p2 = other.features.keypoints[m[:, 1]].astype(np.float64)
    if kf.image is not None and other.image is not None:  # sub-pixel correspondences
        p2, _ = refine_matches_klt(to_gray_uint8(kf.image), to_gray_uint8(other.image), p1, p2)
    n1 = undistort_points(cam1, p1, normalized=True)
    n2 = undistort_points(cam2, p2, normalized=True)
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = T_21[:3, :]
    Xh = cv2.triangulatePoints(P1, P2, n1.T, n2.T)
    w = Xh[3]
    with np.errstate(divide="ignore", invalid="ignore"):
        X = (Xh[:3] / w).T
    X2 = X @ T_21[:3, :3].T + T_21[:3, 3]
    ok = np.isfinite(X).all(1) & (np.abs(w) > 1e-12) & (X[:, 2] > 0) & (X2[:, 2] > 0)
    # parallax: angle between the two viewing rays at the point
    c2_in_1 = inv(T_21)[:3, 3]
    r1 = X
    r2 = X - c2_in_1
    cosang = np.sum(r1 * r2, 1) / np.maximum(np.linalg.norm(r1, axis=1) * np.linalg.norm(r2, axis=1), 1e-12)
    ang = np.degrees(np.arccos(np.clip(cosang, -1, 1)))
    ok &= ang >= conf.tri_min_parallax_deg
    # reprojection in pixels, both views (on the undistorted pinhole)
    with np.errstate(divide="ignore", invalid="ignore"):
        e1 = np.linalg.norm((X[:, :2] / X[:, 2:3] - n1) * [cam1.fx, cam1.fy], axis=1)
        e2 = np.linalg.norm((X2[:, :2] / X2[:, 2:3] - n2) * [cam2.fx, cam2.fy], axis=1)
    ok &= (e1 <= conf.tri_max_reprojection_px) & (e2 <= conf.tri_max_reprojection_px)
    idx = m[ok, 0]
    pts[idx] = X[ok]
    par[idx] = ang[ok]
    return pts, par


def triangulate_landmarks(kf: Keyframe, neighbour_kfs, conf: FrontendConfig | None = None) -> np.ndarray:
    """Fill and return ``kf.landmarks`` (N,3) in ``kf``'s camera frame (NaN where unknown).

    ``neighbour_kfs``: keyframes with features, camera and odometry pose (usually the
    previous and next ones); at most ``conf.tri_max_neighbours`` are used, nearest first.
    """
    conf = conf or FrontendConfig()
    if kf.features is None or kf.camera is None:
        raise ValueError("triangulate_landmarks needs a keyframe with features and a camera model")
    n = len(kf.features)
    best = np.full((n, 3), np.nan)
    best_par = np.zeros(n)
    nbs = sorted(neighbour_kfs, key=lambda o: abs(int(o.stamp) - int(kf.stamp)))[: max(conf.tri_max_neighbours, 0)]
    for other in nbs:
        pts, par = triangulate_pair(kf, other, conf)
        better = par > best_par
        best[better] = pts[better]
        best_par[better] = par[better]
    kf.landmarks = best
    return best
