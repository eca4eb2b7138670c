"""Carry the keyframe correction to every odometry stamp (full-rate corrected trajectory).

Choice (documented in docs/backend.md): re-chain the odometry from the preceding corrected
keyframe, and spread the mismatch that re-chaining leaves at the next keyframe over the
interval. For a stamp t with keyframes k0 <= t < k1 (odometry O, corrected X):

    C0 = X_k0 O_k0^-1                       (world-frame correction at k0)
    M  = (C0 O_k1)^-1 X_k1                  (small body-frame mismatch at k1)
    X(t) = C0 O(t) * Interp(M, s),  s = (t - t_k0) / (t_k1 - t_k0)

``Interp`` scales M's rotation vector and translation by s (decoupled SO(3) x R^3, exact
at s = 0 and 1). The result equals the corrected keyframes at keyframe stamps, keeps the
odometry's local shape between them and has no jump at keyframes. Before the first
keyframe the first correction is applied rigidly, after the last keyframe the last one.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError, UnsortedStampsError
from ..geometry import inv
from ..types import Trajectory


def _interp_batch(M: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Exp of s * (rotvec, translation) of M for each stamp: (N, 4, 4)."""
    rv = Rotation.from_matrix(M[:, :3, :3]).as_rotvec()
    out = np.tile(np.eye(4), (len(s), 1, 1))
    out[:, :3, :3] = Rotation.from_rotvec(rv * s[:, None]).as_matrix()
    out[:, :3, 3] = M[:, :3, 3] * s[:, None]
    return out


def correct_full_rate(
    odometry: Trajectory,
    kf_stamps,
    kf_odom_poses,
    kf_corrected_poses,
) -> Trajectory:
    """A corrected pose for every odometry stamp, from keyframe odometry/corrected poses.

    ``kf_odom_poses`` are the keyframes' odometry poses (the ones given to the pose graph),
    ``kf_corrected_poses`` the optimised ones; both (K, 4, 4) aligned with ``kf_stamps``.
    """
    ks = np.asarray(kf_stamps, dtype=np.int64).reshape(-1)
    odo = np.asarray(kf_odom_poses, dtype=np.float64).reshape(-1, 4, 4)
    X = np.asarray(kf_corrected_poses, dtype=np.float64).reshape(-1, 4, 4)
    if not (len(ks) == len(odo) == len(X)):
        raise InputError(f"keyframe arrays differ in length: {len(ks)} stamps, {len(odo)} odometry, {len(X)} corrected")
    if len(ks) == 0:
        raise InputError("full-rate correction needs at least one keyframe")
    if np.any(np.diff(ks) <= 0):
        raise UnsortedStampsError("keyframe stamps must be strictly increasing")
    t = odometry.stamps
    if len(t) and np.any(np.diff(t) < 0):
        raise UnsortedStampsError("odometry stamps go backwards")
    C = X @ inv(odo)  # world-frame corrections per keyframe
    # Segment of each stamp: k0 = last keyframe with stamp <= t (clipped to the ends).
    seg = np.searchsorted(ks, t, side="right") - 1
    before = seg < 0
    after = seg >= len(ks) - 1
    k0 = np.clip(seg, 0, len(ks) - 1)
    out = C[k0] @ odometry.poses
    inside = ~(before | after)
    if np.any(inside) and len(ks) > 1:
        M = inv(C[:-1] @ odo[1:]) @ X[1:]  # (K-1) mismatches
        k = k0[inside]
        s = (t[inside] - ks[k]).astype(np.float64) / (ks[k + 1] - ks[k]).astype(np.float64)
        out[inside] = out[inside] @ _interp_batch(M[k], s)
    # Stamps exactly at the last keyframe (seg == K-1) already get C_last O(t) = X_last.
    return Trajectory(
        t.copy(), out, None, frame_id=odometry.frame_id, child_frame_id=odometry.child_frame_id
    )
