"""slam_lcd.frontend: keyframe selection, the built-in RGB-D / stereo visual odometry, monocular landmarks.
May import: vision, features and the base modules; never io or sensors (frames come in as arrays).

- :class:`KeyframeSelector` / :func:`select_keyframes`: keyframes from odometry thresholds
  and image overlap, with the odometry covariance accumulated between keyframes.
- :class:`RgbdOdometry`, :class:`StereoOdometry`: frame-to-keyframe PnP odometry with
  covariances and explicit tracking-loss segments.
- :func:`two_view_geometry`: relative rotation/translation direction of two frames.
- :func:`triangulate_landmarks`: metric 3-D points for a monocular keyframe;
  :func:`landmarks_from_sensor` for RGB-D / stereo keyframes.
"""
from .config import FrontendConfig
from .depth_points import landmarks_from_sensor, points_from_depth, points_from_stereo
from .keyframes import KeyframeSelector, keyframes_from_trajectory, select_keyframes
from .triangulation import triangulate_landmarks
from .two_view import TwoViewResult, two_view_geometry
from .vo import RgbdOdometry, StereoOdometry, VoFrame, VoResult, run_rgbd_odometry, run_stereo_odometry

__all__ = [
    "FrontendConfig",
    "KeyframeSelector",
    "RgbdOdometry",
    "StereoOdometry",
    "TwoViewResult",
    "VoFrame",
    "VoResult",
    "keyframes_from_trajectory",
    "landmarks_from_sensor",
    "points_from_depth",
    "points_from_stereo",
    "run_rgbd_odometry",
    "run_stereo_odometry",
    "select_keyframes",
    "triangulate_landmarks",
    "two_view_geometry",
]
