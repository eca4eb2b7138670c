"""Small SE(3) helpers on numpy 4x4 matrices, in GTSAM's conventions.

Tangent vectors and covariances are ordered ``[rx ry rz tx ty tz]`` and perturbations are
on the right (``T * Exp(xi)``), exactly as ``gtsam.Pose3`` does, so a covariance computed
here can be handed to a GTSAM noise model unchanged.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

import gtsam


def skew(v: np.ndarray) -> np.ndarray:
    x, y, z = v
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def inverse(T: np.ndarray) -> np.ndarray:
    """Inverse of one 4x4 or a stack (..., 4, 4) of rigid transforms."""
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    out = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, t)
    out[..., 3, 3] = 1.0
    return out


def adjoint(T: np.ndarray) -> np.ndarray:
    """Adjoint of one 4x4 or a stack (..., 4, 4), GTSAM order: ``[[R, 0], [t^ R, R]]``."""
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    tx = np.zeros(T.shape[:-2] + (3, 3))
    tx[..., 0, 1], tx[..., 0, 2] = -t[..., 2], t[..., 1]
    tx[..., 1, 0], tx[..., 1, 2] = t[..., 2], -t[..., 0]
    tx[..., 2, 0], tx[..., 2, 1] = -t[..., 1], t[..., 0]
    A = np.zeros(T.shape[:-2] + (6, 6))
    A[..., :3, :3] = R
    A[..., 3:, 3:] = R
    A[..., 3:, :3] = tx @ R
    return A


def log(T: np.ndarray) -> np.ndarray:
    """SE(3) logarithm ``[w, v]`` of one 4x4 (gtsam.Pose3.Logmap)."""
    return np.asarray(gtsam.Pose3.Logmap(gtsam.Pose3(np.asarray(T, dtype=np.float64))))


def exp(xi: np.ndarray) -> np.ndarray:
    """SE(3) exponential of one 6-vector ``[w, v]`` (gtsam.Pose3.Expmap)."""
    return gtsam.Pose3.Expmap(np.asarray(xi, dtype=np.float64)).matrix()


def make_pose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def quat_xyzw_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a quaternion given as (qx, qy, qz, qw); normalised first."""
    q = np.asarray(q, dtype=np.float64)
    return Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()


def matrix_to_quat_xyzw(R: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(R).as_quat()


def project_to_se3(T: np.ndarray) -> np.ndarray:
    """Nearest proper rigid transform (re-orthonormalises the rotation block)."""
    U, _, Vt = np.linalg.svd(T[:3, :3])
    R = U @ Vt
    if np.linalg.det(R) < 0:
        U[:, -1] *= -1
        R = U @ Vt
    return make_pose(R, T[:3, 3])
