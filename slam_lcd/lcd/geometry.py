"""Geometric verification (essential matrix) and the metric relative pose of a loop.

Why two steps: the essential matrix checks that the matches are explained by one rigid
camera motion using only pixel coordinates and intrinsics (no scale), which works for any
camera. A pose-graph edge needs metric scale, so the relative pose itself comes from 3-D
points of the match keyframe (depth image, stereo disparity or triangulated landmarks)
seen by the query's keypoints: PnP-RANSAC, then a Gauss-Newton refinement on the inliers
whose Jacobian gives the information matrix handed to the back end (both in
:mod:`slam_lcd.vision.pnp`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..geometry import adjoint, inv
from ..types import CameraModel, Keyframe
from ..vision.camera import undistort_points
from ..vision.epipolar import cheirality_mask, choose_decomposition, essential_ransac
from ..vision.pnp import pnp_ransac, refine_pose_reprojection
from ..vision.points import backproject, dense_disparity, sample_nearest, unit_rays
from .config import LcdConfig
from .information import loop_information

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
    xq = undistort_points(cam_q, np.asarray(kpts_q)[matches[:, 0]], normalized=True)
    xm = undistort_points(cam_m, np.asarray(kpts_m)[matches[:, 1]], normalized=True)
    focal = 0.25 * (cam_q.fx + cam_q.fy + cam_m.fx + cam_m.fy)
    thr = conf.ransac_threshold_px / focal
    E, mask = essential_ransac(xm, xq, thr, conf.ransac_confidence, cv2.USAC_DEFAULT)
    if E is None:
        return EpipolarVerdict(False, 0, n, "ransac_failed", np.zeros(n, bool))
    # cheirality: inliers clearly behind a camera go, points too far to tell stay (cv2.recoverPose
    # drops every point beyond 50 baselines, which emptied small-baseline revisits: docs/lcd_pose.md)
    R, t, _ = choose_decomposition(E, xm[mask], xq[mask])
    good = cheirality_mask(R, t, xm[mask], xq[mask])
    inl = np.flatnonzero(mask)
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
        z = sample_nearest(np.asarray(kf.depth, dtype=np.float64), kp)
        return _backproject(cam, kp, z, conf), "rgbd"
    if kf.right_image is not None and cam.baseline:
        disp = dense_disparity(kf.image, kf.right_image)
        if disp is not None:
            d = sample_nearest(disp, kp)
            with np.errstate(divide="ignore", invalid="ignore"):
                z = np.where(d > 0.5, cam.fx * cam.baseline / d, np.nan)
            return _backproject(cam, kp, z, conf), "stereo"
    if kf.landmarks is not None:
        lm = np.asarray(kf.landmarks, dtype=np.float64).reshape(-1, 3)
        if len(lm) == len(kp):
            return lm.copy(), "landmarks"
    return None, "none"


def _backproject(cam: CameraModel, kp: np.ndarray, z: np.ndarray, conf: LcdConfig) -> np.ndarray:
    valid = np.isfinite(z) & (z >= conf.min_depth_m) & (z <= conf.max_depth_m)
    return backproject(unit_rays(cam, kp), z, valid)


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
    tight: bool = False  # accepted on the tight-pose rule (fewer inliers than pnp_min_inliers)
    odometry: dict = field(default_factory=dict)  # agreement with odometry (tight poses: lcd/odometry_check.py)

    def evidence(self) -> dict:
        return {
            "pose_ok": self.ok,
            "pose_inliers": int(self.inliers),
            "pose_rms_px": round(float(self.rms), 4) if np.isfinite(self.rms) else None,
            "pose_source": self.source,
            "pose_reason": self.reason,
            "pose_tight": self.tight,
            **self.odometry,
        }


def estimate_loop_pose(
    kf_q: Keyframe,
    kf_m: Keyframe,
    matches: np.ndarray,
    conf: LcdConfig | None = None,
    points3d_m: np.ndarray | None = None,
    source: str = "none",
) -> PoseVerdict:
    """``T_match_query`` (body frames) from query keypoints seen against the match's 3-D points.

    ``points3d_m`` (per keypoint of ``kf_m``, camera frame) may be given when already known
    (the detector caches them), with their ``source``; otherwise they are computed with :func:`keyframe_points3d`.
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
    assert kf_q.features is not None and kf_q.camera is not None and kf_m.camera is not None  # checked on entry
    X = points3d_m[matches[:, 1]]
    uv = np.asarray(kf_q.features.keypoints, dtype=np.float64)[matches[:, 0]]
    valid = np.all(np.isfinite(X), axis=1)
    min_inliers = min_pnp_inliers(conf)
    if valid.sum() < max(min_inliers, 6):
        return PoseVerdict(False, None, None, int(valid.sum()), float("nan"), "too_few_3d_points", source)
    idx = np.flatnonzero(valid)
    xn = undistort_points(kf_q.camera, uv[idx], normalized=True)  # undistorted: PnP on an ideal pinhole
    f = 0.5 * (kf_q.camera.fx + kf_q.camera.fy)
    T_cq_cm, inl = pnp_ransac(X[idx], xn, np.eye(3), threshold=conf.pnp_threshold_px / f, iterations=500,
                              flags=cv2.SOLVEPNP_EPNP)
    if T_cq_cm is None or inl is None or len(inl) < min_inliers:
        n_inl = 0 if inl is None else len(inl)
        return PoseVerdict(False, None, None, n_inl, float("nan"), "pnp_failed", source)
    T_cm_cq, info_cam, rms, keep = refine_pose_reprojection(inv(T_cq_cm), X[idx], xn, f, inl, conf.pnp_threshold_px,
                                                            conf.pixel_sigma_px)
    info_cam = loop_information(T_cm_cq, X[idx][keep], xn[keep], f, source, kf_m.camera, kf_q.camera,
                                min_pixel_sigma=conf.pixel_sigma_px)  # per-point noise: lcd/information.py
    n_inl = int(keep.sum())
    mask = np.zeros(len(matches), bool)
    mask[idx[keep]] = True
    if n_inl < min_inliers:
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
    if n_inl < conf.pnp_min_inliers:
        # fewer points than the plain rule wants: accepted only when the pose itself is tight
        reason = tight_pose_reason(info, n_inl, int(valid.sum()), conf)
        if reason:
            return PoseVerdict(False, None, None, n_inl, rms, reason, source, mask)
    return PoseVerdict(True, T_mq, info, n_inl, rms, "ok", source, mask, tight=n_inl < conf.pnp_min_inliers)


def min_pnp_inliers(conf: LcdConfig) -> int:
    """The fewest PnP inliers any rule accepts (``pnp_min_inliers``, or the tight-pose minimum when on)."""
    if conf.pnp_min_inliers_tight > 0:
        return min(conf.pnp_min_inliers, conf.pnp_min_inliers_tight)
    return conf.pnp_min_inliers


def pose_sigmas(info: np.ndarray) -> tuple[float, float]:
    """(translation m, rotation deg) 1-sigma of a pose: sqrt of the trace of each covariance block (GTSAM order)."""
    try:
        cov = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return float("inf"), float("inf")
    tr_r, tr_t = float(np.trace(cov[:3, :3])), float(np.trace(cov[3:, 3:]))
    if not (np.isfinite(tr_r) and np.isfinite(tr_t)) or tr_r < 0 or tr_t < 0:
        return float("inf"), float("inf")
    return float(np.sqrt(tr_t)), float(np.degrees(np.sqrt(tr_r)))


def tight_pose_reason(info: np.ndarray, n_inliers: int, n_points: int, conf: LcdConfig) -> str:
    """Why a pose with fewer than ``pnp_min_inliers`` inliers is not tight enough ('' when it is).

    Why: few inliers are what ORB-SLAM's 40-point rule guards against (a pose resting on a few
    points, or a look-alike place); a wide-baseline revisit also has few, yet its pose can be
    as well determined. The information matrix says how well (NEES-calibrated, docs/plugin.md),
    and a large inlier share says the matched 3-D points agree with one pose.
    """
    if conf.pnp_min_inliers_tight <= 0 or n_inliers < conf.pnp_min_inliers_tight:
        return "too_few_pnp_inliers"
    if n_inliers < conf.pnp_tight_min_share * max(n_points, 1):
        return "few_inliers_low_share"
    sigma_t, sigma_r = pose_sigmas(info)
    if sigma_t > conf.pnp_tight_max_sigma_m or sigma_r > conf.pnp_tight_max_sigma_deg:
        return "few_inliers_loose_pose"
    return ""
