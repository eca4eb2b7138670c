"""3-D points of keypoints: depth sampled at the nearest pixel, rays of the unit-depth plane, dense stereo.

Shared by the front end (tracking keyframes, with its noise model in
:mod:`slam_lcd.frontend.depth_points`) and loop verification (the match keyframe's
points, :func:`slam_lcd.lcd.geometry.keyframe_points3d`).
"""
from __future__ import annotations

import cv2
import numpy as np

from ..types import CameraModel
from .camera import undistort_points
from .gray import to_gray_uint8


def nearest_pixels(shape, kp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column and row of the pixel nearest to each keypoint, clamped to the image."""
    h, w = shape[:2]
    u = np.clip(np.round(kp[:, 0]).astype(int), 0, w - 1)
    v = np.clip(np.round(kp[:, 1]).astype(int), 0, h - 1)
    return u, v


def sample_nearest(img: np.ndarray, kp: np.ndarray) -> np.ndarray:
    """Values (float64) of ``img`` at the pixel nearest to each keypoint."""
    u, v = nearest_pixels(img.shape, kp)
    return img[v, u].astype(np.float64)


def unit_rays(camera: CameraModel, kp: np.ndarray) -> np.ndarray:
    """``(N, 3)`` rays ``(x/z, y/z, 1)`` of undistorted keypoints."""
    return np.column_stack([undistort_points(camera, kp, normalized=True), np.ones(len(kp))])


def backproject(rays: np.ndarray, z: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Camera-frame points ``ray * z`` where ``valid``, NaN rows elsewhere."""
    pts = np.full((len(rays), 3), np.nan)
    pts[valid] = rays[valid] * z[valid, None]
    return pts


def dense_disparity(left, right) -> np.ndarray | None:
    """Disparity (pixels, float64) of every left pixel of a rectified pair by semi-global matching."""
    if left is None or right is None:
        return None
    L, R = to_gray_uint8(left), to_gray_uint8(right)
    # OpenCV's stubs leave this factory out
    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=128, blockSize=5, P1=8 * 25, P2=32 * 25,  # type: ignore[attr-defined]
                                 uniquenessRatio=10, speckleWindowSize=100, speckleRange=2)
    return sgbm.compute(L, R).astype(np.float64) / 16.0
