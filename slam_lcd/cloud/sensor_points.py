"""A keyframe's points in its camera frame, with colour: depth back-projected, or stereo disparity.

Why a pixel grid and not the keypoints: the loop detector's points are a few hundred per
keyframe, where a wall needs thousands to be seen as a wall. Every ``pixel_step``-th pixel of
the depth image is back-projected through the undistorted ray of its pixel (rays are cached
per camera and step: a keyframe costs a multiply). Stereo keyframes (a rectified pair) get
semi-global matching on the pair scaled down by ``pixel_step`` (1/step^2 of the cost of the
full images; the voxel merges points closer than that anyway). Colour comes from the colour
image where the log has one, the grey image otherwise.

Bad input is a :class:`~slam_lcd.errors.InputError` (a depth image of another size than the
camera's): the caller skips the keyframe and says so once per topic.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import InputError
from ..types import CameraModel
from ..vision.camera import undistort_points
from ..vision.gray import to_gray_uint8


@dataclass
class SensorPoints:
    """Camera-frame points (N, 3) float32 and colours (N, 3) uint8 of one keyframe."""

    points: np.ndarray
    colours: np.ndarray

    def __len__(self) -> int:
        return len(self.points)


_RAYS: dict = {}  # (camera intrinsics, step) -> rays of the pixel grid (a few cameras per process)


def _grid(shape, step: int) -> tuple[np.ndarray, np.ndarray]:
    h, w = shape
    v, u = np.mgrid[step // 2:h:step, step // 2:w:step]
    return u.ravel(), v.ravel()


def pixel_rays(camera: CameraModel, step: int) -> np.ndarray:
    """``(H/step * W/step, 3)`` rays ``(x/z, y/z, 1)`` of the pixel grid, row by row."""
    key = (camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy, camera.distortion_model,
           tuple(np.asarray(camera.D, float).ravel()), step)
    rays = _RAYS.get(key)
    if rays is None:
        u, v = _grid((camera.height, camera.width), step)
        xy = undistort_points(camera, np.column_stack([u, v]).astype(np.float64), normalized=True)
        rays = np.column_stack([xy, np.ones(len(xy))]).astype(np.float32)
        if len(_RAYS) > 8:
            _RAYS.clear()
        _RAYS[key] = rays
    return rays


def _check_size(img: np.ndarray, camera: CameraModel, what: str) -> None:
    if img.shape[:2] != (camera.height, camera.width):
        raise InputError(f"{what} of {img.shape[1]}x{img.shape[0]} pixels, the camera's are "
                         f"{camera.width}x{camera.height}")


def _colours_at(image: np.ndarray | None, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    if image is None:
        return np.full((len(u), 3), 128, np.uint8)
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] >= 3 and img.dtype == np.uint8:
        return img[v, u, :3]
    g = to_gray_uint8(img)[v, u]
    return np.repeat(g[:, None], 3, axis=1)


def depth_points(camera: CameraModel, depth: np.ndarray, image: np.ndarray | None, *, step: int = 2,
                 min_depth: float = 0.3, max_depth: float = 5.0) -> SensorPoints:
    """Every ``step``-th pixel of ``depth`` (metres, float) within ``[min_depth, max_depth]``, back-projected."""
    d = np.asarray(depth)
    _check_size(d, camera, "depth image")
    if image is not None:
        _check_size(np.asarray(image), camera, "image")
    step = max(1, int(step))
    u, v = _grid(d.shape[:2], step)
    z = d[v, u].astype(np.float32) * (np.float32(0.001) if d.dtype == np.uint16 else np.float32(1.0))
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(z) & (z >= min_depth) & (z <= max_depth)
    pts = pixel_rays(camera, step)[ok] * z[ok, None]
    return SensorPoints(pts.astype(np.float32), _colours_at(image, u[ok], v[ok]))


def _drop_disparity_jumps(disp: np.ndarray, max_jump: float) -> None:
    """Zero (in place) the disparities whose 3x3 neighbourhood spreads over more than ``max_jump`` (units of
    ``disp``): at an object's edge the matching window straddles foreground and background and gives
    depths between the two (points floating in free space, seen by no other keyframe in the same place)."""
    valid = disp > 0.5
    k = np.ones((3, 3), np.uint8)
    hi = cv2.dilate(np.where(valid, disp, np.float32(0)), k)
    lo = cv2.erode(np.where(valid, disp, np.float32(np.inf)), k)
    disp[(hi - lo) > max_jump] = 0


def stereo_points(camera: CameraModel, left: np.ndarray, right: np.ndarray, image: np.ndarray | None = None, *,
                  step: int = 2, min_depth: float = 0.3, max_depth: float = 5.0, match_step: int = 2,
                  max_jump: float = 0.0) -> SensorPoints:
    """Points of a rectified pair (``camera.baseline`` m apart) by semi-global matching on the pair scaled down
    by ``match_step``, every ``step``-th pixel kept; ``max_jump`` > 0: disparities at a jump of more than that
    many pixels of the matched image are dropped (:func:`_drop_disparity_jumps`)."""
    if not camera.baseline:
        raise InputError("stereo pair without a baseline")
    L, R = to_gray_uint8(np.asarray(left)), to_gray_uint8(np.asarray(right))
    _check_size(L, camera, "left image")
    _check_size(R, camera, "right image")
    step, ms = max(1, int(step)), max(1, int(match_step))
    h, w = L.shape
    if ms > 1:
        size = ((w + ms - 1) // ms, (h + ms - 1) // ms)
        L, R = cv2.resize(L, size, interpolation=cv2.INTER_AREA), cv2.resize(R, size, interpolation=cv2.INTER_AREA)
    # disparities up to the one of min_depth, in the scaled image (a multiple of 16, as SGBM wants)
    need = camera.fx * abs(camera.baseline) / max(min_depth, 1e-3) / ms
    n_disp = int(min(max(16, 16 * np.ceil(need / 16)), 16 * max(1, (L.shape[1] // 2) // 16)))
    # OpenCV's stubs leave this factory out
    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=n_disp, blockSize=5, P1=8 * 25, P2=32 * 25,  # type: ignore[attr-defined]
                                 uniquenessRatio=10, speckleWindowSize=100, speckleRange=2,
                                 mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    disp = sgbm.compute(L, R).astype(np.float32) / 16.0  # pixels of the matched image
    if max_jump > 0:
        _drop_disparity_jumps(disp, max_jump)
    u, v = _grid((h, w), step)
    d = disp[np.minimum(v // ms, disp.shape[0] - 1), np.minimum(u // ms, disp.shape[1] - 1)] * ms  # full resolution
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(d > 0.5, np.float32(camera.fx * abs(camera.baseline)) / d, np.nan)
        ok = np.isfinite(z) & (z >= min_depth) & (z <= max_depth)
    pts = pixel_rays(camera, step)[ok] * z[ok, None]
    return SensorPoints(pts.astype(np.float32), _colours_at(image if image is not None else left, u[ok], v[ok]))
