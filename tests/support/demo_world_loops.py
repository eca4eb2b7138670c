"""Loop detection over keyframes rendered from the demo world (exact ground truth), shared by the
demo-world loop tests."""
from __future__ import annotations

import numpy as np


def relative_error(T: np.ndarray, T_gt: np.ndarray) -> tuple[float, float]:
    """(translation m, rotation deg) of ``T`` against ``T_gt``."""
    D = np.linalg.inv(T_gt) @ T
    ang = np.degrees(np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1, 1)))
    return float(np.linalg.norm(D[:3, 3])), float(ang)


def detect_on_rendered_keyframes(weights, trajectory: str, laps: float, **gt_pairs):
    """Render ``trajectory`` at 1 Hz (320x240 RGB-D), run the loop detector (SuperPoint on the CPU,
    graph+ransac, 20 s excluded); returns (detector, trajectory, GT loop pairs, T_body_camera).

    The keyframes carry the demo's simulated wheel odometry (2-4.5 % drift), not the ground truth,
    so the detector's odometry check of tight-rule loops (lcd/odometry_check.py) sees real drift."""
    from slam_lcd import sim
    from slam_lcd.features import FeaturesConfig, load_extractor
    from slam_lcd.lcd import LcdConfig, LoopDetector
    from slam_lcd.sim.odometry import simulate_odometry
    from slam_lcd.types import Keyframe

    world = sim.build_world(0)
    traj = sim.make_trajectory(trajectory, laps=laps, rate_hz=1.0)  # keyframes ~1.1 m apart
    odom = simulate_odometry(traj, seed=0)
    cam = sim.demo_camera(320, 240)
    T_bc = sim.T_body_camera()
    ex = load_extractor(FeaturesConfig(kind="superpoint", feature_cache=False), weights=weights, device="cpu")
    det = LoopDetector(LcdConfig(verify="graph+ransac", exclude_recent_s=20.0, exclude_recent_n=0), extractor=ex)
    for k in range(len(traj)):
        img, depth = sim.render(world, cam, traj.poses[k] @ T_bc)
        det.add(Keyframe(k, int(traj.stamps[k]), odom.poses[k], image=img, camera=cam, T_body_camera=T_bc,
                         depth=depth))
    return det, traj, sim.gt_loop_pairs(traj, T_body_camera=T_bc, **gt_pairs), T_bc
