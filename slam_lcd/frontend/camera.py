"""Camera model checks, keypoint undistortion, camera mounting.

(Decoding ``sensor_msgs/CameraInfo`` lives in :mod:`slam_lcd.sensors.messages`.)

Supported distortion models are the ones ROS drivers publish: ``plumb_bob`` (5 radtan
coefficients), ``rational_polynomial`` (8 coefficients, OpenCV's rational model) and
``equidistant`` (4 fisheye coefficients, OpenCV's fisheye model). An empty or all-zero
coefficient list is ``none``.
"""
from __future__ import annotations

import logging

import cv2
import numpy as np

from ..errors import ConfigError, InputError, MessageEncodingError, SlamLcdError
from ..geometry import quat_to_rot
from ..types import CameraModel

log = logging.getLogger(__name__)

RADTAN_MODELS = ("plumb_bob", "rational_polynomial", "radtan")
FISHEYE_MODELS = ("equidistant", "fisheye", "kannala_brandt")


def normalise_camera(cam: CameraModel) -> CameraModel:
    """Check the model name and coefficient count; all-zero coefficients become ``none``."""
    model = (cam.distortion_model or "none").lower()
    D = np.asarray(cam.D, dtype=np.float64).reshape(-1)
    if cam.fx <= 0 or cam.fy <= 0:
        raise InputError(f"camera with non-positive focal length fx={cam.fx} fy={cam.fy}")
    if D.size == 0 or not np.any(D):
        model, D = "none", np.zeros(0)
    elif model in RADTAN_MODELS:
        if D.size not in (4, 5, 8, 12, 14):
            raise MessageEncodingError(f"distortion model {model!r} with {D.size} coefficients")
        model = "plumb_bob" if D.size <= 5 else "rational_polynomial"
    elif model in FISHEYE_MODELS:
        if D.size < 4:
            raise MessageEncodingError(f"equidistant distortion needs 4 coefficients, got {D.size}")
        model, D = "equidistant", D[:4]
    elif model == "none":
        pass
    else:
        raise MessageEncodingError(f"unsupported distortion model {cam.distortion_model!r}")
    cam.distortion_model = model
    cam.D = D
    return cam


def undistort_points(camera: CameraModel, pts: np.ndarray, normalized: bool = False) -> np.ndarray:
    """Undistorted keypoints ``(N, 2)``: pixels of the ideal pinhole ``camera.K`` (or normalised).

    With ``normalized=True`` the result is ``(x/z, y/z)`` on the unit-depth plane.
    """
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return pts.copy()
    model = camera.distortion_model
    if model == "none" or np.asarray(camera.D).size == 0:
        n = np.column_stack([(pts[:, 0] - camera.cx) / camera.fx, (pts[:, 1] - camera.cy) / camera.fy])
    elif model == "equidistant":
        n = cv2.fisheye.undistortPoints(pts.reshape(-1, 1, 2), camera.K, np.asarray(camera.D, np.float64)[:4]).reshape(-1, 2)
    else:
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 1e-10)
        n = cv2.undistortPoints(pts.reshape(-1, 1, 2), camera.K, np.asarray(camera.D, np.float64),
                                None, None, None, crit).reshape(-1, 2)
    if normalized:
        return n
    return np.column_stack([n[:, 0] * camera.fx + camera.cx, n[:, 1] * camera.fy + camera.cy])


def distort_points(camera: CameraModel, normalized_pts: np.ndarray) -> np.ndarray:
    """Pixels of normalised image-plane points through the distortion model (inverse of the above)."""
    n = np.asarray(normalized_pts, dtype=np.float64).reshape(-1, 2)
    obj = np.column_stack([n, np.ones(len(n))]).reshape(-1, 1, 3)
    if camera.distortion_model == "equidistant":
        out, _ = cv2.fisheye.projectPoints(obj, np.zeros(3), np.zeros(3), camera.K, np.asarray(camera.D)[:4])
    else:
        D = np.asarray(camera.D, np.float64) if camera.distortion_model != "none" else np.zeros(5)
        out, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), camera.K, D)
    return out.reshape(-1, 2)


def pose_from_list(values, where: str = "frontend.T_body_camera") -> np.ndarray:
    """A 4x4 pose from 16 row-major numbers or 7 numbers ``x y z qx qy qz qw``."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if v.size == 16:
        T = v.reshape(4, 4)
        if not np.allclose(T[3], [0, 0, 0, 1]) or not np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-6):
            raise ConfigError(f"{where}: 16 numbers must form a rigid transform (row-major 4x4)")
        return T
    if v.size == 7:
        q = v[3:]
        if np.linalg.norm(q) < 1e-9:
            raise ConfigError(f"{where}: zero quaternion")
        T = np.eye(4)
        T[:3, :3] = quat_to_rot(q)
        T[:3, 3] = v[:3]
        return T
    raise ConfigError(f"{where}: expected 16 numbers (4x4 row-major) or 7 (x y z qx qy qz qw), got {v.size}")


def camera_mounting(conf, tf_buffer=None, camera_frame: str | None = None, stamp_ns: int = 0,
                    body_frame: str | None = None) -> np.ndarray:
    """``T_body_camera``: from the config when set, else from ``/tf_static``, else identity.

    The one camera-mounting rule of slam-lcd (the visual-odometry pass and the main pass
    both use it). ``tf_buffer`` is anything with
    ``lookup(parent, child, stamp_ns)`` (a :mod:`slam_lcd.io.tf` buffer); the body frame is ``body_frame`` (the odometry's
    child frame, when there is an odometry topic), else ``conf.body_frame``; the camera
    frame is ``conf.camera_frame``, else ``camera_frame`` (the CameraInfo header's).
    """
    if conf.T_body_camera is not None:
        return pose_from_list(conf.T_body_camera)
    body = body_frame or conf.body_frame
    frame = conf.camera_frame or camera_frame
    if tf_buffer is not None and frame:
        try:
            return np.asarray(tf_buffer.lookup(body, frame, stamp_ns), dtype=np.float64)
        except (SlamLcdError, LookupError, ValueError) as e:  # no such frame: identity is the documented fallback
            log.warning("no transform %s -> %s in /tf_static (%s); using identity camera mounting",
                        body, frame, e)
    return np.eye(4)
