"""Honest information matrix of a loop's metric pose (PnP on the match keyframe's 3-D points).

Why: the information handed to the back end decides its chi-square gate, PCM and GNC, and
is what a user's own graph will trust. ``J^T J / sigma^2`` with one pixel sigma counts
only the query's keypoint noise and treats every inlier as exact in 3-D; loops then claim
more certainty than they have. Here each inlier's reprojection residual gets its own 2x2
covariance

    C_i = s^2 I + J_X,i Sigma_X,i J_X,i^T

- ``s``: the keypoint noise (query and match keypoints alike), estimated from the inlier
  residuals by moment matching: their summed squares (with the ``2N / (2N - 6)``
  degrees-of-freedom correction) = the sum of ``tr(C_i)``, so the part the depth noise
  explains is not counted twice; floored so that a residual axis has at least
  ``pixel_sigma_px``;
- ``Sigma_X,i``: the 3-D point's covariance in the match camera: depth noise along the ray
  (RGB-D: ``max(depth_floor_m, depth_rel * z)``; stereo: disparity noise
  ``z^2 sigma_d / (f b)`` with the same floor; triangulated landmarks: ``landmark_rel * z``)
  plus the match keypoint's own pixel noise across the ray; ``J_X`` is the residual's
  Jacobian with respect to the point;

and, because the pose comes from *unweighted* Gauss-Newton, the sandwich information
``Info = H M^-1 H / k`` with ``H = sum J_i^T J_i`` and ``M = sum J_i^T C_i J_i``, where ``k >= 1`` inflates for
few inliers (``1 + few_inliers_ref / N``) and for inliers clustered in a small part of the image
(coverage = the inliers' spread against a uniform spread over the image; below
``cluster_coverage`` ``k`` grows as ``(coverage / cluster_coverage)^-1/2``, at most
``max_cluster_inflation``). The constants below were calibrated
on the demo world's loops against exact ground truth (NEES, ``tools/bench_nees.py``;
figures in docs/plugin.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import inv
from ..types import CameraModel


@dataclass
class InformationModel:
    """Noise model of a PnP loop pose (see the module docstring); units: pixels, metres."""

    pixel_sigma_px: float = 1.0  # floor of the keypoint noise
    depth_floor_m: float = 0.005  # floor of a depth / stereo point's noise along the ray
    depth_rel: float = 0.003  # RGB-D depth noise per metre of depth
    disparity_sigma_px: float = 0.5  # stereo disparity noise
    landmark_rel: float = 0.02  # triangulated landmark depth noise per metre
    few_inliers_ref: float = 10.0  # inflation 1 + ref / N
    cluster_coverage: float = 0.25  # inliers spread less than this (1 = uniform over the image) are clustered
    max_cluster_inflation: float = 4.0


def _point_sigma_z(z: np.ndarray, source: str, cam: CameraModel, m: InformationModel) -> np.ndarray:
    if source == "stereo" and cam.baseline:
        s = z**2 * m.disparity_sigma_px / (cam.fx * cam.baseline)
    elif source == "landmarks":
        s = m.landmark_rel * z
    else:
        s = m.depth_rel * z
    return np.maximum(s, m.depth_floor_m)


def coverage(xn: np.ndarray, cam: CameraModel) -> float:
    """Spread of points (normalised coordinates) against a uniform spread over the image: 1 = uniform."""
    if len(xn) < 3:
        return 0.0
    w, h = cam.width / cam.fx, cam.height / cam.fy  # image extent in normalised coordinates
    sx, sy = np.std(xn[:, 0]), np.std(xn[:, 1])
    return float(min(1.0, (sx * sy) / (w * h / 12.0)))


def loop_information(T_cm_cq: np.ndarray, X_m: np.ndarray, xn_q: np.ndarray, focal: float, source: str,
                     cam_m: CameraModel, cam_q: CameraModel, model: InformationModel | None = None,
                     min_pixel_sigma: float | None = None) -> np.ndarray:
    """6x6 information of the right perturbation of ``T_cm_cq`` (camera frames, ``[rx ry rz tx ty tz]``).

    ``X_m``: inlier 3-D points in the match camera; ``xn_q``: their undistorted normalised
    observations in the query image; ``focal`` the query's focal length (pixels).
    """
    m = model or InformationModel()
    floor = m.pixel_sigma_px if min_pixel_sigma is None else float(min_pixel_sigma)
    X_m = np.asarray(X_m, float).reshape(-1, 3)
    xn_q = np.asarray(xn_q, float).reshape(-1, 2)
    T = inv(np.asarray(T_cm_cq, float))  # query <- match
    R = T[:3, :3]
    P = X_m @ R.T + T[:3, 3]
    front = P[:, 2] > 1e-6
    P, X_m, xn_q = P[front], X_m[front], xn_q[front]
    n = len(P)
    if n < 6:
        return np.zeros((6, 6))
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    r = np.stack([x / z - xn_q[:, 0], y / z - xn_q[:, 1]], axis=1) * focal
    Jp = np.zeros((n, 2, 3))
    Jp[:, 0, 0], Jp[:, 0, 2] = 1 / z, -x / z**2
    Jp[:, 1, 1], Jp[:, 1, 2] = 1 / z, -y / z**2
    Jp *= focal
    # pose: P = Exp(-xi) P0 -> dP/dxi = [[P]x, -I]
    JP = np.zeros((n, 3, 6))
    JP[:, 0, 1], JP[:, 0, 2] = -z, y
    JP[:, 1, 0], JP[:, 1, 2] = z, -x
    JP[:, 2, 0], JP[:, 2, 1] = -y, x
    JP[:, :, 3:] = -np.eye(3)
    J = Jp @ JP  # (n, 2, 6)
    # 3-D point covariance in the match camera: depth noise along the ray (D) and the match
    # keypoint's noise across it (L, per unit keypoint variance)
    zm = X_m[:, 2]
    d = X_m / zm[:, None]  # ray with unit z
    sz = _point_sigma_z(zm, source, cam_m, m)
    D = sz[:, None, None] ** 2 * (d[:, :, None] * d[:, None, :])
    L = np.zeros((n, 3, 3))
    L[:, 0, 0] = L[:, 1, 1] = (zm / cam_m.fx) ** 2
    JX = Jp @ R  # (n, 2, 3) residual w.r.t. the point in the match camera
    JXt = np.transpose(JX, (0, 2, 1))
    CD, CL = JX @ D @ JXt, JX @ L @ JXt
    # keypoint noise s (both images) by moment matching: sum |r_i|^2 (dof-corrected) =
    # sum (2 s^2 + s^2 tr(CL_i) + tr(CD_i)); floored at pixel_sigma_px per residual axis
    r2 = float(np.sum(r**2)) * (2 * n) / max(2 * n - 6, 1)
    s2 = (r2 - np.trace(CD, axis1=1, axis2=2).sum()) / (2 * n + np.trace(CL, axis1=1, axis2=2).sum())
    s2 = max(s2, 0.5 * floor**2)
    C = s2 * (np.eye(2) + CL) + CD
    # the refinement is unweighted least squares, so its covariance is the sandwich
    # H^-1 (sum J^T C J) H^-1 (H = sum J^T J), not (sum J^T C^-1 J)^-1: it would be that only
    # for a solver weighting each residual by C_i^-1
    H = np.einsum("nai,naj->ij", J, J)
    M = np.einsum("nai,nab,nbj->ij", J, C, J)
    info = H @ np.linalg.solve(M, H)
    cov_ratio = max(coverage(xn_q, cam_q), 1e-6) / m.cluster_coverage
    k = (1.0 + m.few_inliers_ref / n) * min(m.max_cluster_inflation, max(1.0, 1.0 / np.sqrt(cov_ratio)))
    info = info / k
    return 0.5 * (info + info.T)
