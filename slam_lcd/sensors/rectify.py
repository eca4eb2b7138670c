"""Rectify a raw calibrated stereo pair (EuRoC's cam0/cam1) for the stereo visual odometry.

The stereo VO matches features along image rows, so it needs a rectified pair. A pair
described by a calibration file (:mod:`slam_lcd.sensors.calibration`) with distortion, a
relative rotation or a vertical offset is rectified here with OpenCV (``stereoRectify``,
``initUndistortRectifyMap``; the ``fisheye`` variants for equidistant lenses), zero
disparity at infinity and no black border cropped away (``alpha=0``). The VO then sees a
distortion-free pinhole camera whose frame is turned by ``R1`` from cam0's: its mounting
is ``T_body_cam0 @ T_cam0_rect``, so the VO's poses stay poses of the body.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import CalibrationError
from ..types import CameraModel


@dataclass
class StereoRectifier:
    camera: CameraModel  # the rectified left camera (no distortion, with the baseline)
    T_cam0_rect: np.ndarray  # maps points of the rectified left frame into cam0
    maps: tuple  # (left map x, left map y, right map x, right map y)

    def rectify(self, left: np.ndarray, right: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lx, ly, rx, ry = self.maps
        return (cv2.remap(left, lx, ly, cv2.INTER_LINEAR), cv2.remap(right, rx, ry, cv2.INTER_LINEAR))


def is_rectified(cam0: CameraModel, cam1: CameraModel, T_c1_c0: np.ndarray) -> bool:
    """No distortion, no relative rotation and a purely horizontal baseline (1 %)."""
    distorted = any(c.distortion_model != "none" for c in (cam0, cam1))
    rotated = np.linalg.norm(T_c1_c0[:3, :3] - np.eye(3)) > 1e-3
    off_row = abs(T_c1_c0[1, 3]) + abs(T_c1_c0[2, 3]) > 1e-2 * abs(T_c1_c0[0, 3])
    same_k = np.allclose(cam0.K, cam1.K, rtol=1e-4)
    return not (distorted or rotated or off_row or not same_k)


def stereo_rectifier(cam0: CameraModel, cam1: CameraModel, T_c1_c0: np.ndarray, source=None) -> StereoRectifier:
    """The rectification of the pair (``T_c1_c0`` maps cam0 points into cam1)."""
    if (cam0.width, cam0.height) != (cam1.width, cam1.height):
        raise CalibrationError(f"stereo cameras of different resolutions ({cam0.width}x{cam0.height} and "
                               f"{cam1.width}x{cam1.height}) cannot be rectified together", source)
    fisheye = {cam0.distortion_model, cam1.distortion_model} & {"equidistant"}
    if fisheye and {cam0.distortion_model, cam1.distortion_model} - {"equidistant", "none"}:
        raise CalibrationError("a stereo pair of one equidistant and one radtan lens is not supported", source)
    size = (int(cam0.width), int(cam0.height))
    R = np.ascontiguousarray(T_c1_c0[:3, :3], np.float64)
    t = np.ascontiguousarray(T_c1_c0[:3, 3], np.float64).reshape(3, 1)
    if fisheye:
        D0 = _coeffs(cam0, 4)
        D1 = _coeffs(cam1, 4)
        R1, R2, P1, P2, _ = cv2.fisheye.stereoRectify(cam0.K, D0, cam1.K, D1, size, R, t, cv2.CALIB_ZERO_DISPARITY,
                                                      newImageSize=size, balance=0.0, fov_scale=1.0)
        lx, ly = cv2.fisheye.initUndistortRectifyMap(cam0.K, D0, R1, P1, size, cv2.CV_32FC1)
        rx, ry = cv2.fisheye.initUndistortRectifyMap(cam1.K, D1, R2, P2, size, cv2.CV_32FC1)
    else:
        D0, D1 = _coeffs(cam0, 5), _coeffs(cam1, 5)
        R1, R2, P1, P2, *_ = cv2.stereoRectify(cam0.K, D0, cam1.K, D1, size, R, t, flags=cv2.CALIB_ZERO_DISPARITY,
                                               alpha=0)
        lx, ly = cv2.initUndistortRectifyMap(cam0.K, D0, R1, P1, size, cv2.CV_32FC1)
        rx, ry = cv2.initUndistortRectifyMap(cam1.K, D1, R2, P2, size, cv2.CV_32FC1)
    baseline = float(-P2[0, 3] / P2[0, 0])
    if not np.isfinite(baseline) or baseline <= 0:
        raise CalibrationError(f"the stereo extrinsic puts the second camera to the left of the first "
                               f"(rectified baseline {baseline:.4f} m): give the left camera first", source)
    cam = CameraModel(width=size[0], height=size[1], fx=float(P1[0, 0]), fy=float(P1[1, 1]), cx=float(P1[0, 2]),
                      cy=float(P1[1, 2]), baseline=baseline)
    T = np.eye(4)
    T[:3, :3] = np.asarray(R1).T  # X_rect = R1 X_cam0
    return StereoRectifier(cam, T, (lx, ly, rx, ry))


def _coeffs(cam: CameraModel, n: int) -> np.ndarray:
    D = np.zeros(n)
    if cam.distortion_model != "none":
        d = np.asarray(cam.D, np.float64).reshape(-1)[:n]
        D[: d.size] = d
    return D
