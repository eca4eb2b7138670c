"""slam_lcd.frontend: keyframe selection, the built-in RGB-D / stereo visual odometry, monocular landmarks.
May import: vision, features and the base modules; never io or sensors (frames come in as arrays).

- :class:`KeyframeSelector` / :func:`select_keyframes`: keyframes from odometry thresholds
  and image overlap, with the odometry covariance accumulated between keyframes.
- :class:`RgbdOdometry`, :class:`StereoOdometry`: frame-to-keyframe PnP odometry with
  covariances and explicit tracking-loss segments.
- :func:`two_view_geometry`: relative rotation/translation direction of two frames.
- :func:`triangulate_landmarks`: metric 3-D points for a monocular keyframe;
  :func:`landmarks_from_sensor` for RGB-D / stereo keyframes.

Names are imported on first use (PEP 562): the configuration imports this package, and a
command that needs none of these must not pay numpy, scipy or OpenCV for them.
"""
from __future__ import annotations

from ..runtime.lazy_names import lazy_getattr
from .config import FrontendConfig

_LAZY = {
    "landmarks_from_sensor": ".depth_points",
    "points_from_depth": ".depth_points",
    "points_from_stereo": ".depth_points",
    "KeyframeSelector": ".keyframes",
    "keyframes_from_trajectory": ".keyframes",
    "select_keyframes": ".keyframes",
    "triangulate_landmarks": ".triangulation",
    "TwoViewResult": ".two_view",
    "two_view_geometry": ".two_view",
    "RgbdOdometry": ".vo",
    "StereoOdometry": ".vo",
    "VoFrame": ".vo",
    "VoResult": ".vo",
    "run_rgbd_odometry": ".vo",
    "run_stereo_odometry": ".vo",
}

__all__ = ["FrontendConfig", *_LAZY]

__getattr__ = lazy_getattr(__name__, _LAZY, globals())
