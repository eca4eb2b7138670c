"""Geometric verification (essential matrix) and the metric relative pose of a loop.

Why two steps: the essential matrix checks that the matches are explained by one rigid
camera motion using only pixel coordinates and intrinsics (no scale), which works for any
camera. A pose-graph edge needs metric scale, so the relative pose itself comes from 3-D
points of the match keyframe (depth image, stereo disparity or triangulated landmarks)
seen by the query's keypoints: PnP-RANSAC, then a Gauss-Newton refinement on the inliers
whose Jacobian gives the information matrix handed to the back end.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..geometry import adjoint, inv, se3_exp
from ..types import CameraModel, Keyframe
from .config import LcdConfig
from .information import loop_information


# ----------------------------------------------------------------------------- cameras


def default_camera(width: int, height: int, focal_factor: float) -> CameraModel:
    """A plausible pinhole for images that come without intrinsics: f = factor x width, centred."""
    f = float(focal_factor) * float(width)
    return CameraModel(width=int(width), height=int(height), fx=f, fy=f, cx=width / 2.0, cy=height / 2.0)


def normalized_points(camera: CameraModel, pts: np.ndarray) -> np.ndarray:
    """Pixel coordinates -> undistorted normalised image coordinates (x/z, y/z)."""
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 1, 2)
    if len(pts) == 0:
        return np.zeros((0, 2))
    D = np.asarray(camera.D, dtype=np.float64).reshape(-1)
    if camera.distortion_model == "equidistant" and D.size >= 4:
        out = cv2.fisheye.undistortPoints(pts, camera.K, D[:4])
    elif camera.distortion_model not in ("none", "") and D.size and np.any(D != 0):
        out = cv2.undistortPoints(pts, camera.K, D)
    else:
        out = (pts - [camera.cx, camera.cy]) / [camera.fx, camera.fy]
    return out.reshape(-1, 2)


# ----------------------------------------------------------------------------- essential matrix


@dataclass
class EpipolarVerdict:
    """Outcome of essential-matrix RANSAC; ``mask`` marks the inlier rows of the matches."""

    accepted: bool
    inliers: int
    n_matches: int
    reason: str
    mask: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    R_query_match: np.ndarray | None = None  # rotation from the essential matrix (camera frames)

    def evidence(self) -> dict:
        return {
            "ransac_accepted": self.accepted,
            "ransac_inliers": int(self.inliers),
            "ransac_matches": int(self.n_matches),
            "ransac_reason": self.reason,
        }


def verify_epipolar(
    kpts_q: np.ndarray,
    kpts_m: np.ndarray,
    matches: np.ndarray,
    cam_q: CameraModel,
    cam_m: CameraModel,
    conf: LcdConfig | None = None,
) -> EpipolarVerdict:
    """Essential-matrix RANSAC on normalised coordinates (both cameras' intrinsics applied)."""
    conf = conf or LcdConfig()
    matches = np.asarray(matches, dtype=np.int64).reshape(-1, 2)
    n = len(matches)
    if n < max(conf.ransac_min_inliers, 5):
        return EpipolarVerdict(False, 0, n, "too_few_matches", np.zeros(n, bool))
    xq = normalized_points(cam_q, np.asarray(kpts_q)[matches[:, 0]])
    xm = normalized_points(cam_m, np.asarray(kpts_m)[matches[:, 1]])
    focal = 0.25 * (cam_q.fx + cam_q.fy + cam_m.fx + cam_m.fy)
    thr = conf.ransac_threshold_px / focal
    E, mask = cv2.findEssentialMat(xm, xq, np.eye(3), method=cv2.USAC_DEFAULT, prob=conf.ransac_confidence, threshold=thr)
    if E is None or mask is None or E.shape[0] < 3:
        return EpipolarVerdict(False, 0, n, "ransac_failed", np.zeros(n, bool))
    E = E[:3]
    mask = mask.reshape(-1).astype(bool)
    # recoverPose's cheirality check removes inliers that lie behind a camera
    _, R, _, pose_mask = cv2.recoverPose(E, xm[mask], xq[mask], np.eye(3))
    inl = np.flatnonzero(mask)
    good = pose_mask.reshape(-1) > 0
    mask = np.zeros(n, bool)
    mask[inl[good]] = True
    k = int(mask.sum())
    if k < conf.ransac_min_inliers:
        return EpipolarVerdict(False, k, n, "too_few_inliers", mask, R)
    if k < conf.ransac_min_inlier_ratio * n:
        return EpipolarVerdict(False, k, n, "low_inlier_ratio", mask, R)
    return EpipolarVerdict(True, k, n, "ok", mask, R)


# ----------------------------------------------------------------------------- 3-D points of a keyframe


def keyframe_points3d(kf: Keyframe, conf: LcdConfig | None = None) -> tuple[np.ndarray | None, str]:
    """Camera-frame 3-D point per keypoint of ``kf`` (NaN where unknown) and where it came from.

    Sources, first available wins: the depth image ('rgbd'), a rectified stereo partner
    ('stereo'), ``kf.landmarks`` triangulated by the front end ('landmarks').
    """
    conf = conf or LcdConfig()
    feats = kf.features
    if feats is None or kf.camera is None:
        return None, "none"
    kp = np.asarray(feats.keypoints, dtype=np.float64).reshape(-1, 2)
    cam = kf.camera
    if kf.depth is not None:
        z = _sample_nearest(np.asarray(kf.depth, dtype=np.float64), kp)
        return _backproject(cam, kp, z, conf), "rgbd"
    if kf.right_image is not None and cam.baseline:
        disp = _disparity(kf.image, kf.right_image)
        if disp is not None:
            d = _sample_nearest(disp, kp)
            with np.errstate(divide="ignore", invalid="ignore"):
                z = np.where(d > 0.5, cam.fx * cam.baseline / d, np.nan)
            return _backproject(cam, kp, z, conf), "stereo"
    if kf.landmarks is not None:
        lm = np.asarray(kf.landmarks, dtype=np.float64).reshape(-1, 3)
        if len(lm) == len(kp):
            return lm.copy(), "landmarks"
    return None, "none"


def _sample_nearest(img: np.ndarray, kp: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    u = np.clip(np.round(kp[:, 0]).astype(int), 0, w - 1)
    v = np.clip(np.round(kp[:, 1]).astype(int), 0, h - 1)
    return img[v, u].astype(np.float64)


def _backproject(cam: CameraModel, kp: np.ndarray, z: np.ndarray, conf: LcdConfig) -> np.ndarray:
    xn = normalized_points(cam, kp)
    valid = np.isfinite(z) & (z >= conf.min_depth_m) & (z <= conf.max_depth_m)
    pts = np.full((len(kp), 3), np.nan)
    pts[valid, 0] = xn[valid, 0] * z[valid]
    pts[valid, 1] = xn[valid, 1] * z[valid]
    pts[valid, 2] = z[valid]
    return pts


def _disparity(left, right) -> np.ndarray | None:
    if left is None or right is None:
        return None
    from ..features.extract import to_gray_uint8

    L, R = to_gray_uint8(left), to_gray_uint8(right)
    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=128, blockSize=5, P1=8 * 25, P2=32 * 25,
                                 uniquenessRatio=10, speckleWindowSize=100, speckleRange=2)
    return sgbm.compute(L, R).astype(np.float64) / 16.0


# ----------------------------------------------------------------------------- metric pose


@dataclass
class PoseVerdict:
    """Metric relative pose of a loop; ``T_match_query`` maps query-body points into the match body frame."""

    ok: bool
    T_match_query: np.ndarray | None
    information: np.ndarray | None  # 6x6, GTSAM order [rx ry rz tx ty tz], of T_match_query
    inliers: int
    rms: float
    reason: str
    source: str = "none"  # 'rgbd' | 'stereo' | 'landmarks' | 'none'
    inlier_mask: np.ndarray | None = None

    def evidence(self) -> dict:
        return {
            "pose_ok": self.ok,
            "pose_inliers": int(self.inliers),
            "pose_rms_px": round(float(self.rms), 4) if np.isfinite(self.rms) else None,
            "pose_source": self.source,
            "pose_reason": self.reason,
        }


def estimate_loop_pose(
    kf_q: Keyframe,
    kf_m: Keyframe,
    matches: np.ndarray,
    conf: LcdConfig | None = None,
    points3d_m: np.ndarray | None = None,
    source: str | None = None,
) -> PoseVerdict:
    """``T_match_query`` (body frames) from query keypoints seen against the match's 3-D points.

    ``points3d_m`` (per keypoint of ``kf_m``, camera frame) may be given when already known
    (the detector caches them); otherwise they are computed with :func:`keyframe_points3d`.
    When the match has no 3-D points but the query does, the problem is solved the other way
    round and inverted.
    """
    conf = conf or LcdConfig()
    matches = np.asarray(matches, dtype=np.int64).reshape(-1, 2)
    if kf_q.features is None or kf_m.features is None or kf_q.camera is None or kf_m.camera is None:
        return PoseVerdict(False, None, None, 0, float("nan"), "no_camera_or_features")
    if points3d_m is None:
        points3d_m, source = keyframe_points3d(kf_m, conf)
    swapped = False
    if points3d_m is None:
        # try the query's own 3-D points, then invert
        pts_q, src_q = keyframe_points3d(kf_q, conf)
        if pts_q is None:
            return PoseVerdict(False, None, None, 0, float("nan"), "no_3d_points")
        kf_q, kf_m = kf_m, kf_q
        matches = matches[:, ::-1]
        points3d_m, source = pts_q, src_q
        swapped = True
    X = points3d_m[matches[:, 1]]
    uv = np.asarray(kf_q.features.keypoints, dtype=np.float64)[matches[:, 0]]
    valid = np.all(np.isfinite(X), axis=1)
    if valid.sum() < max(conf.pnp_min_inliers, 6):
        return PoseVerdict(False, None, None, int(valid.sum()), float("nan"), "too_few_3d_points", source)
    idx = np.flatnonzero(valid)
    xn = normalized_points(kf_q.camera, uv[idx])  # undistorted: PnP on an ideal pinhole
    f = 0.5 * (kf_q.camera.fx + kf_q.camera.fy)
    ok, rvec, tvec, inl = cv2.solvePnPRansac(
        X[idx].reshape(-1, 1, 3), xn.reshape(-1, 1, 2), np.eye(3), None,
        iterationsCount=500, reprojectionError=conf.pnp_threshold_px / f, confidence=0.999,
        flags=cv2.SOLVEPNP_EPNP,
    )
    if not ok or inl is None or len(inl) < conf.pnp_min_inliers:
        n_inl = 0 if inl is None else len(inl)
        return PoseVerdict(False, None, None, n_inl, float("nan"), "pnp_failed", source)
    inl = inl.reshape(-1)
    R, _ = cv2.Rodrigues(rvec)
    T_cq_cm = np.eye(4)
    T_cq_cm[:3, :3] = R
    T_cq_cm[:3, 3] = tvec.reshape(3)
    T_cm_cq, info_cam, rms, keep = refine_pose(inv(T_cq_cm), X[idx], xn, f, inl, conf)
    info_cam = loop_information(T_cm_cq, X[idx][keep], xn[keep], f, source, kf_m.camera, kf_q.camera,
                                min_pixel_sigma=conf.pixel_sigma_px)  # per-point noise: lcd/information.py
    n_inl = int(keep.sum())
    mask = np.zeros(len(matches), bool)
    mask[idx[keep]] = True
    if n_inl < conf.pnp_min_inliers:
        return PoseVerdict(False, None, None, n_inl, rms, "too_few_pnp_inliers", source, mask)
    if rms > conf.pnp_max_rms_px:
        return PoseVerdict(False, None, None, n_inl, rms, "high_reprojection_rms", source, mask)
    # camera frames -> body frames: T_mq = B_m X B_q^-1 and xi_body = Ad_{B_q} xi_cam
    B_q, B_m = np.asarray(kf_q.T_body_camera, float), np.asarray(kf_m.T_body_camera, float)
    T_mq = B_m @ T_cm_cq @ inv(B_q)
    A_inv = np.linalg.inv(adjoint(B_q))
    info = A_inv.T @ info_cam @ A_inv
    if swapped:
        # pose of the other direction: T_qm^-1; xi' = -Ad_{T} xi for T^-1 with right perturbation
        A = adjoint(T_mq)
        A_inv = np.linalg.inv(A)
        info = A_inv.T @ info @ A_inv
        T_mq = inv(T_mq)
    info = 0.5 * (info + info.T)
    return PoseVerdict(True, T_mq, info, n_inl, rms, "ok", source, mask)


def refine_pose(
    T_cm_cq: np.ndarray,
    X_m: np.ndarray,
    xn_q: np.ndarray,
    focal: float,
    inliers: np.ndarray,
    conf: LcdConfig,
    iterations: int = 10,
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Gauss-Newton on the reprojection error of the match's points in the query image.

    State ``X = T_cm_cq`` with right perturbation ``X Exp(xi)``; residuals in pixels
    (normalised error x focal). Returns the refined pose, the information matrix of ``xi``
    (``J^T J / sigma^2`` with ``sigma = max(rms, pixel_sigma_px)``), the RMS in pixels and
    the final inlier mask (points within the PnP threshold after refinement).
    """
    X = T_cm_cq.copy()
    keep = np.zeros(len(X_m), bool)
    keep[inliers] = True
    thr = conf.pnp_threshold_px
    H = np.eye(6)
    rms = float("nan")
    for it in range(iterations):
        P, J, r = _residuals_and_jacobian(X, X_m[keep], xn_q[keep], focal)
        if len(r) < 6:
            break
        H = J.T @ J
        g = J.T @ r
        try:
            dx = -np.linalg.solve(H + 1e-9 * np.eye(6), g)
        except np.linalg.LinAlgError:
            break
        X = X @ se3_exp(dx)
        if np.linalg.norm(dx) < 1e-10:
            break
    # re-select inliers with the refined pose, then a final linearisation for the information
    err = _reprojection_errors(X, X_m, xn_q, focal)
    keep = np.isfinite(err) & (err < thr)
    P, J, r = _residuals_and_jacobian(X, X_m[keep], xn_q[keep], focal)
    if len(r) == 0:
        return X, np.zeros((6, 6)), float("nan"), keep
    rms = float(np.sqrt(np.mean(r.reshape(-1, 2) ** 2) * 2.0))  # RMS of 2-D pixel error
    sigma = max(rms / np.sqrt(2.0), conf.pixel_sigma_px)  # per-axis pixel noise
    info = (J.T @ J) / sigma**2
    return X, info, rms, keep


def _reprojection_errors(T_cm_cq: np.ndarray, X_m: np.ndarray, xn_q: np.ndarray, focal: float) -> np.ndarray:
    T = inv(T_cm_cq)
    P = X_m @ T[:3, :3].T + T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        proj = P[:, :2] / P[:, 2:3]
    err = np.linalg.norm(proj - xn_q, axis=1) * focal
    err[~(P[:, 2] > 1e-6)] = np.inf
    return err


def _residuals_and_jacobian(T_cm_cq: np.ndarray, X_m: np.ndarray, xn_q: np.ndarray, focal: float):
    """Stacked residuals (2N,) in pixels and their Jacobian (2N, 6) w.r.t. the right perturbation."""
    T = inv(T_cm_cq)
    P = X_m @ T[:3, :3].T + T[:3, 3]  # points in the query camera
    front = P[:, 2] > 1e-6
    P, xn = P[front], xn_q[front]
    if len(P) == 0:
        return P, np.zeros((0, 6)), np.zeros(0)
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    r = np.stack([x / z - xn[:, 0], y / z - xn[:, 1]], axis=1) * focal
    # d proj / d P
    Jp = np.zeros((len(P), 2, 3))
    Jp[:, 0, 0] = 1 / z
    Jp[:, 0, 2] = -x / z**2
    Jp[:, 1, 1] = 1 / z
    Jp[:, 1, 2] = -y / z**2
    # P = Exp(-xi) P0  ->  dP/dxi = [ [P]x , -I ]
    JP = np.zeros((len(P), 3, 6))
    JP[:, 0, 1], JP[:, 0, 2] = -z, y
    JP[:, 1, 0], JP[:, 1, 2] = z, -x
    JP[:, 2, 0], JP[:, 2, 1] = -y, x
    JP[:, :, 3:] = -np.eye(3)
    J = (Jp @ JP) * focal
    return P, J.reshape(-1, 6), r.reshape(-1)
