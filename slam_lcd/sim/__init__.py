"""slam_lcd.sim: the built-in demo world: rendered scenes, trajectories with loops, simulated odometry, demo logs.
May import: io (writers), vision.gray and the base modules; only the CLI, the demo and tests import it.

A rendered indoor environment with loops, drifting odometry and exact ground truth,
written as real log files. Public API:

- :func:`build_world` / :class:`DemoWorld`: textured planes (corridors around two blocks), in an
  appearance state (``day``, ``night``, ``moved``, ``renovated``: :mod:`slam_lcd.sim.appearance`);
- :func:`render`: pinhole view -> (uint8 image, float32 metric depth);
- :func:`demo_camera`, :func:`T_body_camera`: the sensor rig;
- :func:`make_trajectory` / :func:`make_path`: laps around block A or a figure eight;
- :func:`simulate_odometry`: drifting odometry with honest covariance;
- :func:`gt_loop_pairs`, :func:`write_loop_pairs`: ground-truth loop pairs;
  :func:`gt_cross_pairs`, :func:`shared_place_fraction`: the same between two recordings;
- :data:`SESSIONS` / :func:`session_preset`: the world recorded as several sessions;
- :func:`make_demo_log`: everything written as MCAP / rosbag2 / ROS1 bag / folder;
- :func:`world_surfaces` / :func:`demo_surfaces`: the world's planes as rectangles (the map cloud's truth).
"""
from .demo_log import DemoLogInfo, loops_path_for, make_demo_log
from .loops import (
    gt_cross_pairs,
    gt_loop_pairs,
    keyframe_indices,
    read_loop_pairs,
    shared_place_fraction,
    write_loop_pairs,
)
from .odometry import OdometryNoise, end_drift, simulate_odometry
from .renderer import render
from .rig import T_body_camera, T_left_right, demo_camera
from .sessions import SESSIONS, SessionPreset, session_preset, session_start_ns, world_frame
from .surfaces import demo_surfaces, world_surfaces
from .trajectory import DemoPath, make_path, make_trajectory
from .world import DemoWorld, Plane, build_world

__all__ = [
    "DemoLogInfo", "DemoPath", "DemoWorld", "OdometryNoise", "Plane", "SESSIONS", "SessionPreset", "T_body_camera",
    "demo_surfaces", "world_surfaces",
    "T_left_right", "build_world", "demo_camera", "end_drift", "gt_cross_pairs", "gt_loop_pairs", "keyframe_indices",
    "loops_path_for", "make_demo_log", "make_path", "make_trajectory", "read_loop_pairs", "render",
    "session_preset", "session_start_ns", "shared_place_fraction", "simulate_odometry", "world_frame",
    "write_loop_pairs",
]
