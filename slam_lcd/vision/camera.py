"""The camera model: checks, keypoint undistortion (the one in slam-lcd), distortion, a default pinhole.

(Decoding ``sensor_msgs/CameraInfo`` lives in :mod:`slam_lcd.sensors.messages`.)

Supported distortion models are the ones ROS drivers publish: ``plumb_bob`` (5 radtan
coefficients), ``rational_polynomial`` (8 coefficients, OpenCV's rational model) and
``equidistant`` (4 fisheye coefficients, OpenCV's fisheye model). An empty or all-zero
coefficient list is ``none``.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..errors import InputError, MessageEncodingError
from ..types import CameraModel

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


def _has_distortion(camera: CameraModel) -> bool:
    D = np.asarray(camera.D).reshape(-1)
    return camera.distortion_model not in ("none", "") and D.size > 0 and bool(np.any(D != 0))


def undistort_points(camera: CameraModel, pts: np.ndarray, normalized: bool = False) -> np.ndarray:
    """Undistorted keypoints ``(N, 2)``: pixels of the ideal pinhole ``camera.K`` (or normalised).

    With ``normalized=True`` the result is ``(x/z, y/z)`` on the unit-depth plane. Radtan
    models are inverted iteratively to 1e-10 (OpenCV's default of 5 iterations leaves
    ~0.01 px at the corners of a strongly distorted lens); without distortion the
    result is the pinhole's exactly.
    """
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
    if len(pts) == 0:
        return pts.copy()
    if not _has_distortion(camera):
        n: np.ndarray = np.column_stack([(pts[:, 0] - camera.cx) / camera.fx, (pts[:, 1] - camera.cy) / camera.fy])
    elif camera.distortion_model == "equidistant":
        n = cv2.fisheye.undistortPoints(pts.reshape(-1, 1, 2), camera.K,
                                        np.asarray(camera.D, np.float64)[:4]).reshape(-1, 2)
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


def default_camera(width: int, height: int, focal_factor: float) -> CameraModel:
    """A plausible pinhole for images that come without intrinsics: f = factor x width, centred."""
    f = float(focal_factor) * float(width)
    return CameraModel(width=int(width), height=int(height), fx=f, fy=f, cx=width / 2.0, cy=height / 2.0)
