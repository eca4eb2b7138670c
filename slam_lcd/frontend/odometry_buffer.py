"""The odometry samples a pipeline has received, in stamp order, and the pose at any stamp.

Why its own module: keyframes take their pose (and the covariance of the step) from the
odometry at the image's stamp, which rarely has a sample of its own; the full-rate output
and the reports read the same samples back.
"""
from __future__ import annotations

import bisect

import numpy as np

from ..errors import InvalidPoseError, UnsortedStampsError
from ..geometry import interpolate_poses
from ..types import Trajectory


class OdometryBuffer:
    """Stamps (int ns), 4x4 poses and optional 6x6 covariances of the odometry, checked on the way in."""

    def __init__(self):
        self.stamps: list[int] = []
        self.poses: list[np.ndarray] = []
        self.covariances: list[np.ndarray | None] = []

    def __len__(self) -> int:
        return len(self.stamps)

    def add(self, stamp_ns: int, T_world_body: np.ndarray, covariance: np.ndarray | None = None) -> None:
        T = np.asarray(T_world_body, dtype=np.float64).reshape(4, 4)
        if not np.all(np.isfinite(T)):
            raise InvalidPoseError(f"odometry pose at stamp {stamp_ns} has NaN/inf values")
        if self.stamps and stamp_ns < self.stamps[-1]:
            raise UnsortedStampsError(f"odometry stamp {stamp_ns} is earlier than the previous one ({self.stamps[-1]})")
        self.stamps.append(int(stamp_ns))
        self.poses.append(T)
        self.covariances.append(None if covariance is None else np.asarray(covariance, float).reshape(6, 6))

    def at(self, stamp: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Pose interpolated at ``stamp`` from its two neighbours (clamped at the ends), and the
        covariance of the first sample at or after it."""
        st = self.stamps
        j = bisect.bisect_left(st, stamp)
        if j >= len(st):  # after the last sample: clamp to it
            j = len(st) - 1
            i = j
        else:
            i = max(j - 1, 0)  # st[i] < stamp <= st[j]
        T = interpolate_poses(np.array(st[i:j + 1], np.int64), np.array(self.poses[i:j + 1]),
                              np.array([stamp], np.int64))[0]
        return T, self.covariances[j]

    def trajectory(self) -> Trajectory:
        return Trajectory(np.asarray(self.stamps, np.int64), np.asarray(self.poses).reshape(-1, 4, 4))
