"""ROS-side pose helpers (validation, covariance order) for the decoders, builders and the TF buffer.

The rotation/quaternion algebra itself lives in :mod:`slam_lcd.geometry`.

Quaternions are ROS order ``(x, y, z, w)``. Poses are 4x4 float64 ``T_a_b``. Covariances of
ROS messages are 6x6 in order ``[x y z rx ry rz]`` about the *parent* frame's axes; slam-lcd
uses GTSAM's Pose3 tangent order ``[rx ry rz tx ty tz]`` in the *body* frame (right
perturbation ``T * Exp(xi)``). :func:`ros_cov_to_gtsam` / :func:`gtsam_cov_to_ros` convert.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import InvalidPoseError
from ..geometry import ROS_TO_GTSAM_ORDER, quat_to_rot, ros_covariance_to_gtsam, rot_to_quat

_ROS_TO_GTSAM = ROS_TO_GTSAM_ORDER  # permutation from ROS [x y z rx ry rz] to GTSAM [rx ry rz tx ty tz]


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
    T[:3, :3] = quat_to_rot(checked_quat(float(q[0]), float(q[1]), float(q[2]), float(q[3]), f"{what} orientation"))
    T[0, 3], T[1, 3], T[2, 3] = tx, ty, tz
    return T


def tq_from_pose(
    T: np.ndarray, what: str = "pose"
) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """Translation and quaternion (x, y, z, w) of a 4x4 pose; refuses NaN/inf and non-rotations."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise InvalidPoseError(f"{what} must be a 4x4 matrix, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise InvalidPoseError(f"{what} has NaN/inf values")
    R = T[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-3 or np.linalg.det(R) < 0:
        raise InvalidPoseError(f"{what} rotation block is not a rotation matrix")
    qx, qy, qz, qw = (float(v) for v in rot_to_quat(R, w_nonnegative=True))
    return (float(T[0, 3]), float(T[1, 3]), float(T[2, 3])), (qx, qy, qz, qw)


def tq_from_poses(Ts: np.ndarray, what: str = "pose") -> tuple[np.ndarray, np.ndarray]:
    """:func:`tq_from_pose` of a stack (N, 4, 4) at once: translations (N, 3), quaternions (N, 4) x y z w.

    Same checks and the same numbers, vectorised: writing a log's worth of poses (tens of
    thousands) one matrix at a time costs seconds of Python per output file.
    """
    T = np.asarray(Ts, dtype=np.float64)
    if T.ndim != 3 or T.shape[1:] != (4, 4):
        raise InvalidPoseError(f"{what}s must be an (N, 4, 4) stack, got shape {T.shape}")
    if len(T) == 0:
        return np.zeros((0, 3)), np.zeros((0, 4))
    finite = np.isfinite(T).all(axis=(1, 2))
    if not finite.all():
        raise InvalidPoseError(f"{what} {int(np.flatnonzero(~finite)[0])} has NaN/inf values")
    R = T[:, :3, :3]
    err = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2))
    bad = (err > 1e-3) | (np.linalg.det(R) < 0)
    if bad.any():
        raise InvalidPoseError(f"{what} {int(np.flatnonzero(bad)[0])}: rotation block is not a rotation matrix")
    return T[:, :3, 3].copy(), rot_to_quat(R, w_nonnegative=True).reshape(-1, 4)


def ros_cov_to_gtsam(cov36, R: np.ndarray) -> np.ndarray | None:
    """ROS 6x6 pose covariance (parent axes, [x y z rx ry rz]) -> GTSAM tangent order in body frame.

    Returns None for the ROS "unknown" conventions (all zeros, or ``cov[0] == -1``); the public
    name is :func:`slam_lcd.geometry.ros_covariance_to_gtsam`.
    """
    return ros_covariance_to_gtsam(cov36, R, frame="parent")


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
