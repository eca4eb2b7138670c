"""Two-view geometry between two frames of one calibrated camera.

Keypoints are undistorted to the unit-depth plane first, so one pixel threshold works for
every distortion model; the essential matrix is estimated with RANSAC and decomposed
with a cheirality check (``cv2.recoverPose``). Translation is known up to scale.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..types import CameraModel, Features
from .camera import undistort_points
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


def _triangulate_depths(R, t, n1, n2):
    """Depths of each correspondence in both cameras (midpoint-free linear DLT on normalised points)."""
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = np.hstack([R, t.reshape(3, 1)])
    X = cv2.triangulatePoints(P1, P2, n1.T.astype(np.float64), n2.T.astype(np.float64))
    X = X[:3] / np.where(np.abs(X[3]) < 1e-12, 1e-12, X[3])
    z1 = X[2]
    z2 = (R @ X + t.reshape(3, 1))[2]
    return z1, z2


def _choose_decomposition(E, n1, n2):
    """The (R, t) of the four E decompositions with most points in front of both cameras."""
    R1, R2, t = cv2.decomposeEssentialMat(E)
    t = t.reshape(3)
    best = None
    for R in (R1, R2):
        for tt in (t, -t):
            z1, z2 = _triangulate_depths(R, tt, n1, n2)
            good = (z1 > 0) & (z2 > 0)
            if best is None or good.sum() > best[2].sum():
                best = (R, tt, good)
    return best


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

    from ..geometry import so3_exp

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
    E, mask = cv2.findEssentialMat(n1, n2, np.eye(3), method=cv2.USAC_ACCURATE, prob=confidence,
                                   threshold=threshold_px / f)
    if E is None or mask is None or E.shape != (3, 3):
        if E is not None and E.shape[0] > 3:
            E = E[:3]
        else:
            return None, None, np.zeros(len(n1), bool)
    inl = mask.reshape(-1) > 0
    R, t, front = _choose_decomposition(E, n1[inl], n2[inl])
    if refine and inl.sum() >= 8:
        R, t = refine_relative_pose(R, t, n1[inl], n2[inl], scale=f / threshold_px)
        err = np.abs(sampson_errors(R, t, n1, n2)) * f
        inl = err < threshold_px
    z1, z2 = _triangulate_depths(R, t, n1, n2)
    inl &= (z1 > 0) & (z2 > 0) | ~np.isfinite(z1)
    return R, t, inl


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
