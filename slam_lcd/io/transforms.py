"""Small rigid-transform helpers shared by the decoders, builders and the TF buffer.

Quaternions are ROS order ``(x, y, z, w)``. Poses are 4x4 float64 ``T_a_b``. Covariances of
ROS messages are 6x6 in order ``[x y z rx ry rz]`` about the *parent* frame's axes; slam-lcd
uses GTSAM's Pose3 tangent order ``[rx ry rz tx ty tz]`` in the *body* frame (right
perturbation ``T * Exp(xi)``). :func:`ros_cov_to_gtsam` / :func:`gtsam_cov_to_ros` convert.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import InvalidPoseError

# permutation from ROS [x y z rx ry rz] to GTSAM [rx ry rz tx ty tz]
_ROS_TO_GTSAM = np.array([3, 4, 5, 0, 1, 2])


def quat_to_rot(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Rotation matrix of a unit quaternion (x, y, z, w)."""
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return np.array(
        [
            [1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)],
            [2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)],
            [2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)],
        ]
    )


def rot_to_quat(R: np.ndarray) -> tuple[float, float, float, float]:
    """Unit quaternion (x, y, z, w) with w >= 0 of a rotation matrix (Shepperd's method)."""
    m = np.asarray(R, dtype=np.float64)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s
    n = math.sqrt(x * x + y * y + z * z + w * w)
    q = (x / n, y / n, z / n, w / n)
    return q if q[3] >= 0 else (-q[0], -q[1], -q[2], -q[3])


def checked_quat(x: float, y: float, z: float, w: float, what: str = "quaternion") -> tuple[float, float, float, float]:
    """Normalise a quaternion that is close to unit length; refuse NaN/inf/zero/far-off ones."""
    n2 = x * x + y * y + z * z + w * w
    if not math.isfinite(n2):
        raise InvalidPoseError(f"{what} has NaN/inf values ({x}, {y}, {z}, {w})")
    n = math.sqrt(n2)
    if abs(n - 1.0) > 0.1:
        raise InvalidPoseError(f"{what} ({x}, {y}, {z}, {w}) is not a rotation (norm {n:.3g})")
    return x / n, y / n, z / n, w / n


def pose_from_tq(t, q, what: str = "pose") -> np.ndarray:
    """4x4 pose from translation (x, y, z) and quaternion (x, y, z, w); checks for NaN."""
    tx, ty, tz = float(t[0]), float(t[1]), float(t[2])
    if not (math.isfinite(tx) and math.isfinite(ty) and math.isfinite(tz)):
        raise InvalidPoseError(f"{what} has NaN/inf translation ({tx}, {ty}, {tz})")
    T = np.eye(4)
    T[:3, :3] = quat_to_rot(*checked_quat(float(q[0]), float(q[1]), float(q[2]), float(q[3]), f"{what} orientation"))
    T[0, 3], T[1, 3], T[2, 3] = tx, ty, tz
    return T


def tq_from_pose(T: np.ndarray, what: str = "pose") -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """Translation and quaternion (x, y, z, w) of a 4x4 pose; refuses NaN/inf and non-rotations."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise InvalidPoseError(f"{what} must be a 4x4 matrix, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise InvalidPoseError(f"{what} has NaN/inf values")
    R = T[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-3 or np.linalg.det(R) < 0:
        raise InvalidPoseError(f"{what} rotation block is not a rotation matrix")
    return (float(T[0, 3]), float(T[1, 3]), float(T[2, 3])), rot_to_quat(R)


def ros_cov_to_gtsam(cov36, R: np.ndarray) -> np.ndarray | None:
    """ROS 6x6 pose covariance (parent axes, [x y z rx ry rz]) -> GTSAM tangent order in body frame.

    Returns None for the ROS "unknown" conventions (all zeros, or ``cov[0] == -1``).
    """
    c = np.asarray(cov36, dtype=np.float64).reshape(6, 6)
    if not c.any() or c[0, 0] == -1:
        return None
    if not np.all(np.isfinite(c)):
        raise InvalidPoseError("covariance has NaN/inf values")
    c = c[np.ix_(_ROS_TO_GTSAM, _ROS_TO_GTSAM)]
    J = np.zeros((6, 6))
    J[:3, :3] = R.T
    J[3:, 3:] = R.T
    return J @ c @ J.T


def gtsam_cov_to_ros(cov: np.ndarray | None, R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`ros_cov_to_gtsam`; None becomes the all-zero "unknown" covariance."""
    if cov is None:
        return np.zeros(36)
    c = np.asarray(cov, dtype=np.float64).reshape(6, 6)
    if not np.all(np.isfinite(c)):
        raise InvalidPoseError("covariance has NaN/inf values")
    J = np.zeros((6, 6))
    J[:3, :3] = R
    J[3:, 3:] = R
    c = J @ c @ J.T
    inv = np.argsort(_ROS_TO_GTSAM)
    return c[np.ix_(inv, inv)].reshape(36)


def slerp(q0: np.ndarray, q1: np.ndarray, a: float) -> np.ndarray:
    """Spherical interpolation between unit quaternions (x, y, z, w), shortest arc."""
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + a * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(min(1.0, d))
    s = math.sin(th)
    return (math.sin((1 - a) * th) / s) * q0 + (math.sin(a * th) / s) * q1


def inverse(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform."""
    Ti = np.eye(4)
    R = T[:3, :3]
    Ti[:3, :3] = R.T
    Ti[:3, 3] = -R.T @ T[:3, 3]
    return Ti
