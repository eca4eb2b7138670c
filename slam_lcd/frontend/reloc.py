"""Relocalisation of the visual odometry after frame-to-keyframe tracking fails.

Three parts, used by :mod:`slam_lcd.frontend.vo` before it declares a frame lost:

- the motion prior: constant velocity from the last two tracked poses (:class:`MotionPrior`),
  extrapolated to the new frame's stamp on SE(3);
- guided matching (:func:`guided_matches`): a keyframe's 3-D points are projected with the
  predicted pose and each is matched only to the frame's features within a search radius,
  so a frame that moved too far or through too repetitive a texture for plain ratio-test
  matching still finds its correspondences;
- the gate (:func:`within_gate`): a PnP pose farther from the prediction than the
  configured translation and rotation is rejected, so a wrong PnP solution (a look-alike
  place, a degenerate point set) never continues the trajectory.
"""
from __future__ import annotations

import numpy as np

from ..features.matching import descriptor_distances
from ..geometry import inv, rotation_angle, se3_exp, se3_log
from .matching import DEFAULT_MAX_DISTANCE


class MotionPrior:
    """Constant-velocity prediction of the camera pose from the last two tracked poses."""

    def __init__(self) -> None:
        self.poses: list[tuple[int, np.ndarray]] = []  # (stamp_ns, T_world_cam), newest last, at most two

    def add(self, stamp_ns: int, T_world_cam: np.ndarray) -> None:
        self.poses = (self.poses + [(int(stamp_ns), np.asarray(T_world_cam, np.float64))])[-2:]

    def reset(self) -> None:
        self.poses = []

    def seconds_since_last(self, stamp_ns: int) -> float:
        return float("inf") if not self.poses else (int(stamp_ns) - self.poses[-1][0]) * 1e-9

    def predict(self, stamp_ns: int) -> np.ndarray | None:
        """``T_world_cam`` at ``stamp_ns``: the last pose moved on at the last velocity (the last pose
        itself with one pose known; None with none)."""
        if not self.poses:
            return None
        s1, T1 = self.poses[-1]
        if len(self.poses) < 2 or self.poses[0][0] >= s1:
            return T1.copy()
        s0, T0 = self.poses[0]
        step = se3_log(inv(T0) @ T1)
        return T1 @ se3_exp(step * ((int(stamp_ns) - s1) / (s1 - s0)))


def pose_difference(T_a: np.ndarray, T_b: np.ndarray) -> tuple[float, float]:
    """``(translation m, rotation deg)`` between two poses."""
    D = inv(T_a) @ T_b
    return float(np.linalg.norm(D[:3, 3])), float(np.degrees(rotation_angle(D[:3, :3])))


def within_gate(T_predicted: np.ndarray, T_estimated: np.ndarray, max_translation: float,
                max_rotation_deg: float) -> bool:
    """True when ``T_estimated`` lies within the gate around the motion prior's prediction."""
    dt, dr = pose_difference(T_predicted, T_estimated)
    return dt <= max_translation and dr <= max_rotation_deg


def guided_matches(points: np.ndarray, descriptors: np.ndarray, T_ref_cur: np.ndarray, K: np.ndarray,
                   uv: np.ndarray, cur_descriptors: np.ndarray, radius_px: float,
                   ratio: float | None = 0.9) -> np.ndarray:
    """Matches ``(M, 2)`` of rows ``[i_point, i_feature]`` found near the predicted projections.

    ``points`` (N,3) in the reference camera, ``T_ref_cur`` the predicted current camera in
    it, ``uv`` (M,2) the frame's undistorted keypoints. Each point takes the nearest
    descriptor among the features within ``radius_px`` of its projection (bounded as in
    tracking, :data:`slam_lcd.frontend.matching.DEFAULT_MAX_DISTANCE`), with a ratio test
    against the second-nearest in that window; each feature keeps its best point only.
    """
    empty = np.zeros((0, 2), np.int64)
    if len(points) == 0 or len(uv) == 0:
        return empty
    Tc = inv(T_ref_cur)
    p = points @ Tc[:3, :3].T + Tc[:3, 3]
    front = p[:, 2] > 1e-3
    z = np.where(front, p[:, 2], 1.0)
    proj = np.column_stack([K[0, 0] * p[:, 0] / z + K[0, 2], K[1, 1] * p[:, 1] / z + K[1, 2]])
    near = np.sum((proj[:, None, :] - uv[None, :, :]) ** 2, axis=2) <= radius_px**2
    near &= front[:, None]
    if not near.any():
        return empty
    dist = np.where(near, descriptor_distances(descriptors, cur_descriptors), np.inf)
    dmax = DEFAULT_MAX_DISTANCE["uint8" if descriptors.dtype == np.uint8 else "float"]
    best = dist.argmin(1)
    rows = np.arange(len(points))
    d1 = dist[rows, best]
    keep = np.isfinite(d1) & (d1 <= dmax)
    if ratio is not None and dist.shape[1] > 1:
        d2 = np.partition(dist, 1, axis=1)[:, 1]
        keep &= ~np.isfinite(d2) | (d1 < ratio * d2)
    keep &= dist.argmin(0)[best] == rows  # one point per feature: the feature's own nearest point
    i = np.flatnonzero(keep)
    return np.column_stack([i, best[i]]).astype(np.int64)
