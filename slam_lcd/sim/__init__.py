"""slam_lcd.sim: the built-in demo world: rendered scenes, trajectories with loops, simulated odometry, demo logs.
May import: io (writers), vision, features (the demo keyframes' cache), eval (on demand, the NEES of the
demo's loops) and the base modules; only the CLI, the demo and tests import it.

A rendered indoor environment with loops, drifting odometry and exact ground truth,
written as real log files. Public API:

- :func:`build_world` / :class:`DemoWorld`: textured planes (corridors around two blocks), in an
  appearance state (``day``, ``night``, ``moved``, ``renovated``: :mod:`slam_lcd.sim.appearance`);
- :func:`render` (in :mod:`.renderer`): pinhole view -> (uint8 image, float32 metric depth);
- :func:`demo_camera`, :func:`T_body_camera`: the sensor rig;
- :func:`make_trajectory` / :func:`make_path`: laps around block A or a figure eight;
- :func:`simulate_odometry`: drifting odometry with honest covariance;
- :func:`gt_loop_pairs`, :func:`write_loop_pairs`: ground-truth loop pairs;
  :func:`gt_cross_pairs`, :func:`shared_place_fraction`: the same between two recordings;
- :data:`SESSIONS` / :func:`session_preset`: the world recorded as several sessions;
- :func:`make_demo_log`: everything written as MCAP / rosbag2 / ROS1 bag / folder;
- :func:`world_surfaces` / :func:`demo_surfaces`: the world's planes as rectangles (the map cloud's truth).

Names are imported on first use (PEP 562), as in the other packages: the command line reads the
session presets (:mod:`.sessions`) without loading the renderer, OpenCV, numpy or scipy.
"""
from __future__ import annotations

from ..runtime.lazy_names import lazy_getattr

_LAZY = {
    "DemoLogInfo": ".demo_info",
    "loops_path_for": ".demo_log",
    "make_demo_log": ".demo_log",
    "gt_cross_pairs": ".loops",
    "gt_loop_pairs": ".loops",
    "keyframe_indices": ".loops",
    "read_loop_pairs": ".loops",
    "shared_place_fraction": ".loops",
    "write_loop_pairs": ".loops",
    "end_drift": ".odometry",
    "OdometryNoise": ".odometry",
    "simulate_odometry": ".odometry",
    "render": ".renderer",
    "demo_camera": ".rig",
    "T_body_camera": ".rig",
    "T_left_right": ".rig",
    "session_preset": ".sessions",
    "session_start_ns": ".sessions",
    "SessionPreset": ".sessions",
    "SESSIONS": ".sessions",
    "world_frame": ".sessions",
    "demo_surfaces": ".surfaces",
    "world_surfaces": ".surfaces",
    "DemoPath": ".trajectory",
    "make_path": ".trajectory",
    "make_trajectory": ".trajectory",
    "build_world": ".world",
    "DemoWorld": ".world",
    "Plane": ".world",
}

__all__ = [*_LAZY]

__getattr__ = lazy_getattr(__name__, _LAZY, globals())
