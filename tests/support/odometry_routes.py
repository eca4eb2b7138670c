"""An open route driven by the project's odometry simulator, cut into keyframes (tests of covariances).

The same route as ``tools/odometry_model_nees.py``: 65 m at 1 m/s, ``y = 4 sin(x / 10)``.
"""
from __future__ import annotations

import numpy as np

from slam_lcd.frontend.config import FrontendConfig
from slam_lcd.frontend.keyframes import keyframes_from_trajectory
from slam_lcd.geometry import inv
from slam_lcd.map.joint_types import SessionPoses
from slam_lcd.sim.odometry import open_route as sim_route
from slam_lcd.sim.odometry import simulate_odometry
from slam_lcd.types import Keyframe, Trajectory


def open_route(rate_hz: float, length_m: float = 65.0, speed: float = 1.0, lateral: float = 0.0) -> Trajectory:
    """The simulator's open route (:func:`slam_lcd.sim.odometry.open_route`), starting at the identity."""
    gt = sim_route(rate_hz, length_m, speed, lateral)
    return Trajectory(gt.stamps, inv(gt.poses[0]) @ gt.poses)


def drive(gt: Trajectory, seed: int, covariances: str) -> list[Keyframe]:
    """Keyframes (0.5 m) of the simulator's odometry along ``gt``; ``covariances``: 'given' (the
    simulator's, absolute), 'zero' (a driver publishing all-zero covariances) or 'model'."""
    odo = simulate_odometry(gt, seed=seed, start_at_identity=True)
    if covariances == "zero":
        odo = Trajectory(odo.stamps, odo.poses, np.zeros_like(odo.covariances))
    conf = FrontendConfig(kf_max_interval_s=0, kf_min_overlap=0,
                          odom_covariance="model" if covariances == "model" else "absolute")
    return keyframes_from_trajectory(odo, conf)


def session_of(name: str, kfs: list[Keyframe], first_id: int) -> SessionPoses:
    """The keyframes as the map's joint graph takes a session (its own estimate: the odometry)."""
    T = np.array([k.T_world_body for k in kfs])
    cov = np.array([np.full((6, 6), np.nan) if k.covariance_since_last is None else k.covariance_since_last
                    for k in kfs])
    return SessionPoses(name, np.arange(first_id, first_id + len(kfs)), T, cov, T.copy(),
                        cov_modelled=np.array([k.covariance_source == "model" for k in kfs]))


def true_poses(gt: Trajectory, kfs: list[Keyframe]) -> np.ndarray:
    """Ground truth at the keyframes' stamps."""
    return gt.poses[np.searchsorted(gt.stamps, [k.stamp for k in kfs])]
