"""Camera pose from 3-D points and their 2-D observations: PnP-RANSAC, then Gauss-Newton.

One PnP (:func:`pnp_ransac`, OpenCV) and one refinement: a motion-only Gauss-Newton on
SE(3) with the right perturbation ``T Exp(xi)`` (:func:`gauss_newton`) and the one
Jacobian of a pinhole projection (:func:`projection_jacobian`). Two residual models use
them:

- :func:`refine_pose` / :func:`solve_pnp` (visual odometry) weight every residual by its
  full uncertainty: the keypoint's pixel noise plus the keyframe point's 3-D uncertainty
  (depth or disparity noise) projected into the image, with Huber weights. The inverse of
  the final normal matrix, scaled by the reduced chi-square when the residuals are larger
  than the noise model says, is the pose covariance: it grows when points are few, far,
  badly spread or noisier than assumed.
- :func:`refine_pose_reprojection` (loop verification) minimises the plain reprojection
  error in pixels on normalised coordinates and returns ``J^T J / sigma^2`` as the
  information of the loop's relative pose.
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


# ----------------------------------------------------------------------------- shared parts


def pnp_ransac(X: np.ndarray, uv: np.ndarray, K: np.ndarray, *, threshold: float, iterations: int, flags: int,
               confidence: float = 0.999) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``(T_cam_points or None, inlier indices or None)``: OpenCV's PnP-RANSAC on points ``X``
    (N,3) seen at ``uv`` (N,2) through ``K`` (the identity for normalised coordinates)."""
    obj = np.ascontiguousarray(X, np.float64).reshape(-1, 1, 3)
    img = np.ascontiguousarray(uv, np.float64).reshape(-1, 1, 2)
    ok, rvec, tvec, inl = cv2.solvePnPRansac(obj, img, K, None, iterationsCount=iterations,
                                             reprojectionError=threshold, confidence=confidence, flags=flags)
    inl = None if inl is None else inl.reshape(-1)
    if not ok or inl is None:
        return None, inl
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.reshape(3)
    return T, inl


def projection_jacobians(
    p: np.ndarray, z: np.ndarray, fx: float = 1.0, fy: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of the pinhole projection of ``p`` (points in the camera, ``p = T^-1 X``, at
    depths ``z`` as the projection uses them): ``(N, 2, 6)`` with respect to ``xi`` for
    ``T = T_hat Exp(xi)``, and ``(N, 2, 3)`` with respect to the point."""
    Jp = np.zeros((len(p), 2, 3))
    Jp[:, 0, 0] = fx / z
    Jp[:, 0, 2] = -fx * p[:, 0] / z**2
    Jp[:, 1, 1] = fy / z
    Jp[:, 1, 2] = -fy * p[:, 1] / z**2
    dp = np.zeros((len(p), 3, 6))  # d p / d xi for T = T_hat Exp(xi): [skew(p), -I]
    dp[:, 0, 1], dp[:, 0, 2] = -p[:, 2], p[:, 1]
    dp[:, 1, 0], dp[:, 1, 2] = p[:, 2], -p[:, 0]
    dp[:, 2, 0], dp[:, 2, 1] = -p[:, 1], p[:, 0]
    dp[:, :, 3:] = -np.eye(3)
    return Jp @ dp, Jp


def gauss_newton(T: np.ndarray, normal_equations, iterations: int, *, tol: float, damping: float = 0.0) -> np.ndarray:
    """Gauss-Newton on SE(3) with the right perturbation: ``T <- T Exp(-H^-1 g)``.

    ``normal_equations(T) -> (H, g)`` (or None to stop: too few residuals); stops after
    ``iterations``, on a singular system, or once the step is shorter than ``tol``.
    """
    for _ in range(iterations):
        Hg = normal_equations(T)
        if Hg is None:
            break
        H, g = Hg
        try:
            xi = -np.linalg.solve(H + damping * np.eye(6) if damping else H, g)
        except np.linalg.LinAlgError:
            break
        T = T @ se3_exp(xi)
        if np.linalg.norm(xi) < tol:
            break
    return T


# ----------------------------------------------------------------------------- visual odometry


def _linearize(T, X, cov_X, uv, K, s2):
    """Whitened normal equations at ``T``: ``(H, g, m2, r)`` with Huber weights."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    Tc = inv(T)
    R = Tc[:3, :3]
    p = X @ R.T + Tc[:3, 3]
    z = np.maximum(p[:, 2], 1e-6)
    r = np.column_stack([fx * p[:, 0] / z + cx, fy * p[:, 1] / z + cy]) - uv
    J, Jp = projection_jacobians(p, z, fx, fy)  # (N,2,6), (N,2,3)
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
    s2 = pixel_sigma**2
    T = gauss_newton(T_ref_cur.copy(), lambda T: _linearize(T, X, cov_X, uv, K, s2)[:2], iterations, tol=1e-9)
    H, _, m2, r = _linearize(T, X, cov_X, uv, K, s2)
    return T, H, m2, r


def solve_pnp(X: np.ndarray, cov_X: np.ndarray, uv: np.ndarray, K: np.ndarray, *,
              reprojection_px: float = 2.0, iterations: int = 200, min_inliers: int = 20,
              pixel_sigma: float = 1.0, T_guess: np.ndarray | None = None) -> PnpResult:
    """Robust pose of the current camera relative to the reference (see module doc)."""
    n = len(X)
    if n < max(6, min_inliers):
        return _fail(f"only {n} 2D-3D correspondences")
    T_cur_ref, inl = pnp_ransac(X, uv, K, threshold=reprojection_px, iterations=iterations, flags=cv2.SOLVEPNP_SQPNP)
    if T_cur_ref is None or inl is None or len(inl) < min_inliers:
        return _fail(f"PnP-RANSAC found {0 if inl is None else len(inl)} inliers of {n}")
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


# ----------------------------------------------------------------------------- loop verification


def refine_pose_reprojection(
    T_cm_cq: np.ndarray,
    X_m: np.ndarray,
    xn_q: np.ndarray,
    focal: float,
    inliers: np.ndarray,
    threshold_px: float,
    pixel_sigma_px: float,
    iterations: int = 10,
) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Gauss-Newton on the reprojection error of the match's points in the query image.

    State ``X = T_cm_cq`` with right perturbation ``X Exp(xi)``; residuals in pixels
    (normalised error x focal). Returns the refined pose, the information matrix of ``xi``
    (``J^T J / sigma^2`` with ``sigma = max(rms, pixel_sigma_px)``), the RMS in pixels and
    the final inlier mask (points within ``threshold_px`` after refinement).
    """
    keep = np.zeros(len(X_m), bool)
    keep[inliers] = True
    thr = threshold_px

    def normal_equations(T):
        _, J, r = _residuals_and_jacobian(T, X_m[keep], xn_q[keep], focal)
        return None if len(r) < 6 else (J.T @ J, J.T @ r)

    X = gauss_newton(T_cm_cq.copy(), normal_equations, iterations, tol=1e-10, damping=1e-9)
    # re-select inliers with the refined pose, then a final linearisation for the information
    err = _reprojection_errors(X, X_m, xn_q, focal)
    keep = np.isfinite(err) & (err < thr)
    P, J, r = _residuals_and_jacobian(X, X_m[keep], xn_q[keep], focal)
    if len(r) == 0:
        return X, np.zeros((6, 6)), float("nan"), keep
    rms = float(np.sqrt(np.mean(r.reshape(-1, 2) ** 2) * 2.0))  # RMS of 2-D pixel error
    sigma = max(rms / np.sqrt(2.0), pixel_sigma_px)  # per-axis pixel noise
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
    J = projection_jacobians(P, z)[0] * focal
    return P, J.reshape(-1, 6), r.reshape(-1)
