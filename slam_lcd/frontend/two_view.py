"""Two-view geometry between two frames of one calibrated camera: matching, sub-pixel refinement, relative pose.

The geometry itself (essential-matrix RANSAC, decomposition with a cheirality check,
Sampson refinement) is :func:`slam_lcd.vision.epipolar.relative_pose_from_points`.
Translation is known up to scale.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..types import CameraModel, Features
from ..vision.camera import undistort_points
from ..vision.epipolar import relative_pose_from_points
from .matching import match_descriptors


@dataclass
class TwoViewResult:
    """``R, t``: motion ``x2 = R x1 + t`` of points from camera 1 into camera 2 (``T_cam2_cam1``), |t| = 1."""

    ok: bool
    R: np.ndarray
    t: np.ndarray
    matches: np.ndarray  # (M, 2) indices into (features1, features2)
    inliers: np.ndarray  # (M,) bool, RANSAC + cheirality inliers
    reason: str = ""
    parallax_deg: float = 0.0  # median rotation-compensated ray angle of the inliers

    @property
    def well_conditioned(self) -> bool:
        """Enough parallax (>= 1 deg) for the rotation not to trade off against the translation."""
        return self.ok and self.parallax_deg >= 1.0

    @property
    def T_cam2_cam1(self) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = self.R
        T[:3, 3] = self.t
        return T


def refine_matches_klt(img1: np.ndarray, img2: np.ndarray, pts1: np.ndarray, pts2: np.ndarray,
                       max_shift_px: float = 3.0, fb_max_px: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """Sub-pixel positions in image 2 of the image-1 keypoints (pyramidal Lucas-Kanade).

    Detectors such as ORB place keypoints of coarse pyramid levels on a coarse grid; Lucas-
    Kanade started at the matched position aligns the image-1 patch to sub-pixel
    precision. Returns the refined image-2 points and a mask of refinements that
    converged within ``max_shift_px`` of the descriptor match and track back to within
    ``fb_max_px`` of the image-1 keypoint (others keep their descriptor-match position).
    """
    if len(pts1) == 0:
        return pts2, np.zeros(0, bool)
    p1 = np.asarray(pts1, np.float32).reshape(-1, 1, 2)
    p2 = np.asarray(pts2, np.float32).reshape(-1, 1, 2).copy()
    out, st, _ = cv2.calcOpticalFlowPyrLK(img1, img2, p1, p2, winSize=(15, 15), maxLevel=1,
                                          criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01),
                                          flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
    out = out.reshape(-1, 2)
    # forward-backward check: tracking the refined point back must land on the image-1 keypoint
    back, st2, _ = cv2.calcOpticalFlowPyrLK(img2, img1, out.reshape(-1, 1, 2).astype(np.float32), p1.copy(),
                                            winSize=(15, 15), maxLevel=1,
                                            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.01),
                                            flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
    fb = np.linalg.norm(back.reshape(-1, 2) - pts1, axis=1)
    ok = ((st.reshape(-1) == 1) & (st2.reshape(-1) == 1) & (fb < fb_max_px)
          & (np.linalg.norm(out - pts2, axis=1) <= max_shift_px))
    res = np.where(ok[:, None], out, pts2)
    return res.astype(np.float64), ok


def two_view_geometry(camera: CameraModel, f1: Features, f2: Features, ratio: float = 0.85,
                      threshold_px: float = 1.0, min_inliers: int = 15,
                      images: tuple[np.ndarray, np.ndarray] | None = None) -> TwoViewResult:
    """Match two feature sets and estimate the relative pose of their cameras.

    With ``images`` (the two uint8 grayscale frames) the matched image-2 positions are
    refined to sub-pixel precision by Lucas-Kanade before the geometry is estimated.
    """
    m = match_descriptors(f1.descriptors, f2.descriptors, ratio=ratio)
    if len(m) < 8:
        return TwoViewResult(False, np.eye(3), np.zeros(3), m, np.zeros(len(m), bool), f"only {len(m)} matches")
    p1 = f1.keypoints[m[:, 0]].astype(np.float64)
    p2 = f2.keypoints[m[:, 1]].astype(np.float64)
    if images is not None:
        p2, _ = refine_matches_klt(images[0], images[1], p1, p2)
    R, t, inl = relative_pose_from_points(camera, p1, p2, threshold_px)
    if R is None:
        return TwoViewResult(False, np.eye(3), np.zeros(3), m, inl, "essential matrix estimation failed")
    par = median_parallax_deg(camera, R, p1[inl], p2[inl])
    if inl.sum() < min_inliers:
        return TwoViewResult(False, R, t, m, inl, f"only {int(inl.sum())} inliers", par)
    return TwoViewResult(True, R, t, m, inl, "", par)


def median_parallax_deg(camera: CameraModel, R: np.ndarray, pts1: np.ndarray, pts2: np.ndarray) -> float:
    """Median angle between the rays of image 2 and the rotated rays of image 1 (degrees)."""
    if len(pts1) == 0:
        return 0.0
    b1 = np.column_stack([undistort_points(camera, pts1, normalized=True), np.ones(len(pts1))])
    b2 = np.column_stack([undistort_points(camera, pts2, normalized=True), np.ones(len(pts2))])
    b1 = b1 @ R.T
    c = np.sum(b1 * b2, 1) / (np.linalg.norm(b1, axis=1) * np.linalg.norm(b2, axis=1))
    return float(np.degrees(np.median(np.arccos(np.clip(c, -1.0, 1.0)))))
