"""Camera pose from 3-D points of a keyframe and their 2-D observations in a new frame.

PnP-RANSAC (OpenCV) finds the inliers and a first pose; a motion-only Gauss-Newton then
refines it while weighting every residual by its full uncertainty: the keypoint's pixel
noise plus the keyframe point's 3-D uncertainty (depth or disparity noise) projected into
the image. The inverse of the final normal matrix, scaled by the reduced chi-square when
the residuals are larger than the noise model says, is the pose covariance: it grows
when points are few, far, badly spread or noisier than assumed.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..geometry import inv, se3_exp

CHI2_2DOF_95 = 5.991


@dataclass
class PnpResult:
    ok: bool
    T_ref_cur: np.ndarray  # pose of the current camera in the reference camera frame
    covariance: np.ndarray  # 6x6, GTSAM order, right perturbation of T_ref_cur
    inliers: np.ndarray  # indices into the correspondences
    rms_px: float
    chi2_per_dof: float
    reason: str = ""


def _fail(reason: str) -> PnpResult:
    return PnpResult(False, np.eye(4), np.eye(6) * 1e6, np.zeros(0, np.int64), float("nan"), float("nan"), reason)


def _linearize(T, X, cov_X, uv, K, s2):
    """Whitened normal equations at ``T``: ``(H, g, m2, r)`` with Huber weights."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    Tc = inv(T)
    R = Tc[:3, :3]
    p = X @ R.T + Tc[:3, 3]
    z = np.maximum(p[:, 2], 1e-6)
    r = np.column_stack([fx * p[:, 0] / z + cx, fy * p[:, 1] / z + cy]) - uv
    Jp = np.zeros((len(X), 2, 3))
    Jp[:, 0, 0] = fx / z
    Jp[:, 0, 2] = -fx * p[:, 0] / z**2
    Jp[:, 1, 1] = fy / z
    Jp[:, 1, 2] = -fy * p[:, 1] / z**2
    dp = np.zeros((len(X), 3, 6))  # d p / d xi for T = T_hat Exp(xi): [skew(p), -I]
    dp[:, 0, 1], dp[:, 0, 2] = -p[:, 2], p[:, 1]
    dp[:, 1, 0], dp[:, 1, 2] = p[:, 2], -p[:, 0]
    dp[:, 2, 0], dp[:, 2, 1] = -p[:, 1], p[:, 0]
    dp[:, :, 3:] = -np.eye(3)
    J = Jp @ dp  # (N,2,6)
    JR = Jp @ R
    S = s2 * np.eye(2) + JR @ cov_X @ np.swapaxes(JR, 1, 2)
    W = np.linalg.inv(S)
    m2 = np.einsum("ni,nij,nj->n", r, W, r)
    k = np.sqrt(CHI2_2DOF_95)
    w = np.where(m2 <= k * k, 1.0, k / np.sqrt(np.maximum(m2, 1e-12)))
    Ww = W * w[:, None, None]
    Jt = np.swapaxes(J, 1, 2)
    H = np.einsum("nij,njk,nkl->il", Jt, Ww, J)
    g = np.einsum("nij,njk,nk->i", Jt, Ww, r)
    return H, g, m2, r


def refine_pose(T_ref_cur: np.ndarray, X: np.ndarray, cov_X: np.ndarray, uv: np.ndarray, K: np.ndarray,
                pixel_sigma: float = 1.0, iterations: int = 10):
    """Motion-only Gauss-Newton with Huber weights on the Mahalanobis residual.

    ``X`` (N,3) points in the reference camera, ``cov_X`` (N,3,3) their covariances, ``uv``
    (N,2) undistorted pixel observations in the current camera. Returns
    ``(T_ref_cur, H, m2, residuals)``: ``H`` the information (6x6) at the solution and
    ``m2`` each point's squared Mahalanobis residual.
    """
    T = T_ref_cur.copy()
    s2 = pixel_sigma**2
    for _ in range(iterations):
        H, g, _, _ = _linearize(T, X, cov_X, uv, K, s2)
        try:
            xi = -np.linalg.solve(H, g)
        except np.linalg.LinAlgError:
            break
        T = T @ se3_exp(xi)
        if np.linalg.norm(xi) < 1e-9:
            break
    H, _, m2, r = _linearize(T, X, cov_X, uv, K, s2)
    return T, H, m2, r


def solve_pnp(X: np.ndarray, cov_X: np.ndarray, uv: np.ndarray, K: np.ndarray, *,
              reprojection_px: float = 2.0, iterations: int = 200, min_inliers: int = 20,
              pixel_sigma: float = 1.0, T_guess: np.ndarray | None = None) -> PnpResult:
    """Robust pose of the current camera relative to the reference (see module doc)."""
    n = len(X)
    if n < max(6, min_inliers):
        return _fail(f"only {n} 2D-3D correspondences")
    obj = np.ascontiguousarray(X, np.float64).reshape(-1, 1, 3)
    img = np.ascontiguousarray(uv, np.float64).reshape(-1, 1, 2)
    ok, rvec, tvec, inl = cv2.solvePnPRansac(obj, img, K, None, iterationsCount=iterations,
                                             reprojectionError=reprojection_px, confidence=0.999,
                                             flags=cv2.SOLVEPNP_SQPNP)
    if not ok or inl is None or len(inl) < min_inliers:
        return _fail(f"PnP-RANSAC found {0 if inl is None else len(inl)} inliers of {n}")
    inl = inl.reshape(-1)
    T_cur_ref = np.eye(4)
    T_cur_ref[:3, :3] = cv2.Rodrigues(rvec)[0]
    T_cur_ref[:3, 3] = tvec.reshape(3)
    T0 = inv(T_cur_ref)
    T, H, m2, r = refine_pose(T0, X[inl], cov_X[inl], uv[inl], K, pixel_sigma)
    # re-select inliers with the refined pose over all correspondences, refine once more
    _, _, m2_all, r_all = refine_pose(T, X, cov_X, uv, K, pixel_sigma, iterations=0)
    inl2 = np.flatnonzero((m2_all < CHI2_2DOF_95 * 2.0) & (np.linalg.norm(r_all, axis=1) < 2.0 * reprojection_px))
    if len(inl2) < min_inliers:
        return _fail(f"only {len(inl2)} inliers after refinement")
    T, H, m2, r = refine_pose(T, X[inl2], cov_X[inl2], uv[inl2], K, pixel_sigma)
    dof = max(2 * len(inl2) - 6, 1)
    chi2 = float(np.sum(m2) / dof)
    try:
        cov = np.linalg.inv(H) * max(1.0, chi2)
    except np.linalg.LinAlgError:
        return _fail("degenerate point configuration (singular information)")
    cov = 0.5 * (cov + cov.T)
    rms = float(np.sqrt(np.mean(np.sum(r * r, axis=1))))
    return PnpResult(True, T, cov, inl2, rms, chi2)
