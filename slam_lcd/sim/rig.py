"""The simulated robot's sensor rig: camera intrinsics and the camera mounting on the body.

Body frame (REP 103): x forward, y left, z up, on the floor. Camera optical frame
(REP 103 ``_optical``): z forward, x right, y down, 1.1 m above the floor, 0.2 m ahead of
the body origin, pitched 5 degrees down so the floor in front is in view.
"""
from __future__ import annotations

import numpy as np

from ..types import CameraModel

CAMERA_HEIGHT = 1.1
CAMERA_FORWARD = 0.2
CAMERA_PITCH_DEG = 5.0
STEREO_BASELINE = 0.12  # metres between the rectified left and right cameras

BODY_FRAME = "base_link"
ODOM_FRAME = "odom"
WORLD_FRAME = "world"
CAMERA_FRAME = "camera_optical_frame"
RIGHT_CAMERA_FRAME = "camera_right_optical_frame"


def demo_camera(
    width: int = 640, height: int = 480, hfov_deg: float = 70.0, baseline: float | None = None
) -> CameraModel:
    """Pinhole camera without distortion; focal length from the horizontal field of view.

    At 640x480 and 70 degrees: fx = fy = 457.0, principal point at the image centre.
    """
    f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2.0)
    f = float(np.round(f, 3))
    return CameraModel(width=int(width), height=int(height), fx=f, fy=f,
                       cx=(width - 1) / 2.0, cy=(height - 1) / 2.0, baseline=baseline)


def T_body_camera(pitch_deg: float = CAMERA_PITCH_DEG) -> np.ndarray:
    """Mounting of the (left) camera optical frame on the body."""
    # columns: camera x (right) = -body y, camera y (down) = -body z, camera z (forward) = body x
    R_base = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    p = np.radians(pitch_deg)
    Ry = np.array([[np.cos(p), 0.0, np.sin(p)], [0.0, 1.0, 0.0], [-np.sin(p), 0.0, np.cos(p)]])
    T = np.eye(4)
    T[:3, :3] = Ry @ R_base
    T[:3, 3] = (CAMERA_FORWARD, 0.0, CAMERA_HEIGHT)
    return T


def T_left_right(baseline: float = STEREO_BASELINE) -> np.ndarray:
    """Right camera in the left camera's optical frame (rectified pair: pure x shift)."""
    T = np.eye(4)
    T[0, 3] = baseline
    return T
