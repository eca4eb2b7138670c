"""Small SE(3) helpers on 4x4 numpy matrices (no gtsam here: this is used by every stage)."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


def inv(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (or a stack of them)."""
    T = np.asarray(T, dtype=np.float64)
    out = np.zeros_like(T)
    R = T[..., :3, :3]
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3:4])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def make_T(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle of a rotation matrix in degrees (robust to rounding)."""
    c = (np.trace(R[:3, :3]) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def interpolate_poses(stamps: np.ndarray, poses: np.ndarray, query: np.ndarray) -> np.ndarray:
    """SE(3) interpolation (slerp rotation, linear translation) of ``poses`` at ``query`` stamps.

    Query stamps outside the range are clamped to the first/last pose.
    """
    stamps = np.asarray(stamps, dtype=np.int64)
    query = np.asarray(query, dtype=np.int64)
    if len(stamps) == 1:
        return np.repeat(poses[:1], len(query), axis=0)
    t0 = stamps[0]
    x = (stamps - t0).astype(np.float64)
    q = np.clip((query - t0).astype(np.float64), x[0], x[-1])
    rots = Rotation.from_matrix(poses[:, :3, :3])
    out = np.repeat(np.eye(4)[None], len(query), axis=0)
    out[:, :3, :3] = Slerp(x, rots)(q).as_matrix()
    for k in range(3):
        out[:, k, 3] = np.interp(q, x, poses[:, k, 3])
    return out
