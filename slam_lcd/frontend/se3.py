"""SE(3) algebra for the front end, in GTSAM's Pose3 conventions (numpy only).

A pose perturbation is on the right, ``T = T_hat @ Exp(xi)``, with ``xi = [omega, v]``
(rotation first), exactly like ``gtsam.Pose3``. Covariances therefore live in the body
frame of the pose they belong to, and relative motions compose with the adjoint
``Ad(T) = [[R, 0], [skew(t) R, R]]``.
"""
from __future__ import annotations

import numpy as np


def skew(w: np.ndarray) -> np.ndarray:
    x, y, z = np.asarray(w, dtype=np.float64).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def inv(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform."""
    R = T[:3, :3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def so3_exp(w: np.ndarray) -> np.ndarray:
    w = np.asarray(w, dtype=np.float64).reshape(3)
    th = np.linalg.norm(w)
    K = skew(w)
    if th < 1e-10:
        return np.eye(3) + K
    return np.eye(3) + np.sin(th) / th * K + (1 - np.cos(th)) / th**2 * (K @ K)


def so3_log(R: np.ndarray) -> np.ndarray:
    c = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    th = np.arccos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if th < 1e-8:
        return 0.5 * v
    if np.pi - th < 1e-4:  # near pi: use the symmetric part
        B = (R + np.eye(3)) / 2.0
        axis = np.sqrt(np.maximum(np.diag(B), 0.0))
        i = int(np.argmax(axis))
        axis = B[i] / max(axis[i], 1e-12)
        axis /= np.linalg.norm(axis)
        if axis @ v < 0:
            axis = -axis
        return axis * th
    return th / (2 * np.sin(th)) * v


def rotation_angle(R: np.ndarray) -> float:
    """Angle (rad) of a rotation matrix."""
    return float(np.arccos(np.clip((np.trace(R[:3, :3]) - 1.0) / 2.0, -1.0, 1.0)))


def adjoint(T: np.ndarray) -> np.ndarray:
    """6x6 adjoint of ``T`` in [rot, trans] order: ``T Exp(xi) T^-1 = Exp(Ad(T) xi)``."""
    R = T[:3, :3]
    A = np.zeros((6, 6))
    A[:3, :3] = R
    A[3:, 3:] = R
    A[3:, :3] = skew(T[:3, 3]) @ R
    return A


def compose_covariance(cov_ab: np.ndarray, T_bc: np.ndarray, cov_bc: np.ndarray) -> np.ndarray:
    """Covariance of ``T_ac = T_ab T_bc`` for independent right-perturbation noises.

    ``T_ab Exp(x) T_bc Exp(y) = T_ac Exp(Ad(T_bc^-1) x) Exp(y)``, so the first covariance
    is carried into the frame c by the adjoint of ``T_bc^-1`` and the second adds.
    """
    A = adjoint(inv(T_bc))
    out = A @ cov_ab @ A.T + cov_bc
    return 0.5 * (out + out.T)


def relative_covariance(T_wi: np.ndarray, cov_i: np.ndarray, T_wj: np.ndarray, cov_j: np.ndarray,
                        floor: np.ndarray | None = None) -> np.ndarray:
    """Covariance of the motion ``T_ij`` from two absolute (growing) pose covariances.

    Under the odometry model ``T_wj = T_wi T_ij`` with independent increments,
    ``cov_j = Ad(T_ij^-1) cov_i Ad(T_ij^-1)^T + cov_ij``; the difference is projected onto
    the positive semi-definite cone and a floor (a diagonal of variances) is added.
    """
    T_ij = inv(T_wi) @ T_wj
    A = adjoint(inv(T_ij))
    d = cov_j - A @ cov_i @ A.T
    d = 0.5 * (d + d.T)
    w, V = np.linalg.eigh(d)
    d = (V * np.maximum(w, 0.0)) @ V.T
    if floor is not None:
        d = d + np.diag(floor)
    return d


def ros_to_gtsam_covariance(cov_ros: np.ndarray, T_world_body: np.ndarray) -> np.ndarray:
    """ROS pose covariance ([x y z roll pitch yaw], about the parent frame's axes) to GTSAM order.

    ROS perturbs position and orientation in the parent (world) frame; GTSAM perturbs on
    the right, in the body frame: ``omega = R^T dtheta``, ``v = R^T dp``.
    """
    c = np.asarray(cov_ros, dtype=np.float64).reshape(6, 6)
    perm = [3, 4, 5, 0, 1, 2]
    c = c[np.ix_(perm, perm)]
    R = T_world_body[:3, :3]
    B = np.zeros((6, 6))
    B[:3, :3] = R.T
    B[3:, 3:] = R.T
    return B @ c @ B.T


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """``Exp([omega, v])`` as a 4x4 matrix (GTSAM Pose3::Expmap)."""
    xi = np.asarray(xi, dtype=np.float64).reshape(6)
    w, v = xi[:3], xi[3:]
    th = np.linalg.norm(w)
    K = skew(w)
    if th < 1e-10:
        V = np.eye(3) + 0.5 * K
    else:
        V = np.eye(3) + (1 - np.cos(th)) / th**2 * K + (th - np.sin(th)) / th**3 * (K @ K)
    T = np.eye(4)
    T[:3, :3] = so3_exp(w)
    T[:3, 3] = V @ v
    return T


def se3_log(T: np.ndarray) -> np.ndarray:
    """``Log(T)`` as ``[omega, v]`` (GTSAM Pose3::Logmap)."""
    w = so3_log(T[:3, :3])
    th = np.linalg.norm(w)
    K = skew(w)
    if th < 1e-10:
        Vinv = np.eye(3) - 0.5 * K
    else:
        Vinv = np.eye(3) - 0.5 * K + (1 / th**2) * (1 - (th * np.sin(th)) / (2 * (1 - np.cos(th)))) * (K @ K)
    return np.concatenate([w, Vinv @ T[:3, 3]])


def transform_covariance(cov_c: np.ndarray, T_b_c: np.ndarray) -> np.ndarray:
    """Covariance of a motion of frame c re-expressed for frame b rigidly attached by ``T_b_c``.

    ``T_b_c A Exp(xi) T_c_b = (T_b_c A T_c_b) Exp(Ad(T_b_c) xi)``.
    """
    A = adjoint(T_b_c)
    return A @ cov_c @ A.T
