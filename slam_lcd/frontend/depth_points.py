"""3-D points (and their covariances) for keypoints, from a depth image or a stereo pair.

Shared by the visual odometry (tracking keyframes) and by loop verification, which needs
``Keyframe.landmarks``. Noise model: the keypoint's pixel noise spreads the point
laterally; depth noise runs along the ray, ``sigma_z = vo_depth_sigma_per_m2 * z^2`` for a
depth camera and ``z^2 / (f b) * sigma_disparity`` for stereo.
"""
from __future__ import annotations

import numpy as np

from ..types import CameraModel, Features, Keyframe
from ..vision.gray import to_gray_uint8
from ..vision.points import backproject, nearest_pixels, unit_rays
from .config import FrontendConfig, default_extractor
from .stereo import stereo_disparities


def _covariances(camera: CameraModel, rays: np.ndarray, z: np.ndarray, sz: np.ndarray, ok: np.ndarray,
                 conf: FrontendConfig) -> np.ndarray:
    f = 0.5 * (camera.fx + camera.fy)
    lat = (conf.vo_pixel_sigma / f) ** 2
    zz = np.where(ok, z, 1.0)
    s = np.where(ok, sz, 1.0)
    cov = (s**2)[:, None, None] * np.einsum("ni,nj->nij", rays, rays)
    cov[:, 0, 0] += lat * zz**2
    cov[:, 1, 1] += lat * zz**2
    cov[~ok] = np.eye(3)
    return cov


def _windows(depth: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The 3x3 neighbourhoods ``(N, 3, 3)`` (float64) of pixels ``(u, v)``, clamped to the image."""
    h, w = depth.shape[:2]
    offs = np.array([-1, 0, 1])
    rows = np.clip(v[:, None, None] + offs[None, :, None], 0, h - 1)
    cols = np.clip(u[:, None, None] + offs[None, None, :], 0, w - 1)
    return depth[rows, cols].astype(np.float64)


def depth_slope(depth: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Depth change per pixel (central differences) at ``(u, v)``: how far a keypoint's depth moves
    when its position is off by a pixel (large on a surface seen at a grazing angle)."""
    win = _windows(depth, u, v)
    return np.hypot(0.5 * (win[:, 1, 2] - win[:, 1, 0]), 0.5 * (win[:, 2, 1] - win[:, 0, 1]))


def depth_discontinuity(depth: np.ndarray, u: np.ndarray, v: np.ndarray, tolerance: np.ndarray) -> np.ndarray:
    """True where the 3x3 neighbourhood of pixel ``(u, v)`` is not one smooth surface.

    The test runs on inverse depth, which is affine in the pixel coordinates on any plane:
    the four second differences through the centre (row, column, both diagonals) are zero
    on a plane, however slanted and at any image resolution, and each must stay within
    ``tolerance`` (1/m, per keypoint). A neighbour without a reading (0, NaN) counts as a
    discontinuity. Every neighbour enters one of the differences, so a step anywhere in the
    window is found.
    """
    win = _windows(depth, u, v)
    with np.errstate(divide="ignore", invalid="ignore"):
        q = np.where(np.isfinite(win) & (win > 0), 1.0 / win, np.nan)
    centre = 2.0 * q[:, 1, 1]
    second = np.stack([q[:, 1, 0] + q[:, 1, 2] - centre, q[:, 0, 1] + q[:, 2, 1] - centre,
                       q[:, 0, 0] + q[:, 2, 2] - centre, q[:, 0, 2] + q[:, 2, 0] - centre], axis=1)
    with np.errstate(invalid="ignore"):
        smooth = np.all(np.abs(second) <= tolerance[:, None], axis=1)
    return ~smooth


def points_from_depth(camera: CameraModel, feats: Features, depth: np.ndarray,
                      conf: FrontendConfig | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(points (N,3), covariances (N,3,3))`` in the camera frame; NaN rows where depth is unusable.

    ``depth``: float metres or uint16 millimetres, registered to the image. Keypoints on a
    depth discontinuity are dropped (:func:`depth_discontinuity`). A point's depth noise is the
    sensor's and, on a slanted surface, the keypoint's pixel noise times the depth slope.
    """
    c = conf or FrontendConfig()
    d = np.asarray(depth)
    d = d.astype(np.float32) * (0.001 if d.dtype == np.uint16 else 1.0)
    n = len(feats)
    pts = np.full((n, 3), np.nan)
    if n == 0:
        return pts, np.zeros((0, 3, 3))
    kp = feats.keypoints
    u, v = nearest_pixels(d.shape, kp)
    z = d[v, u].astype(np.float64)
    with np.errstate(invalid="ignore"):
        sz = c.vo_depth_sigma_per_m2 * z**2 + 1e-3
        ok = np.isfinite(z) & (z > c.vo_min_depth) & (z < c.vo_max_depth)
        zz = np.where(ok, z, 1.0)
    # 3 sigma of a second difference of four noisy samples (sqrt(6) sigma), plus 1 % of the depth, in inverse depth
    ok &= ~depth_discontinuity(d, u, v, (3.0 * np.sqrt(6.0) * np.where(ok, sz, 1.0) + 0.01 * zz) / zz**2)
    slope = np.where(ok, depth_slope(d, u, v), 0.0)
    sz = np.hypot(sz, c.vo_pixel_sigma * slope)
    rays = unit_rays(camera, kp)
    return backproject(rays, z, ok), _covariances(camera, rays, z, sz, ok, c)


def points_from_stereo(camera: CameraModel, baseline: float, feats: Features, left: np.ndarray,
                       right: np.ndarray, extractor, conf: FrontendConfig | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Like :func:`points_from_depth`, with depth ``f b / disparity`` from a rectified pair."""
    c = conf or FrontendConfig()
    n = len(feats)
    pts = np.full((n, 3), np.nan)
    if n == 0:
        return pts, np.zeros((0, 3, 3))
    disp = stereo_disparities(feats, left, right, extractor, c)
    fx = camera.fx
    with np.errstate(invalid="ignore", divide="ignore"):
        z = fx * baseline / disp
        ok = np.isfinite(z) & (z > c.vo_min_depth) & (z < c.vo_max_depth)
        sz = z**2 / (fx * baseline) * c.vo_disparity_sigma_px
    rays = unit_rays(camera, feats.keypoints)
    return backproject(rays, z, ok), _covariances(camera, rays, z, sz, ok, c)


def landmarks_from_sensor(kf: Keyframe, conf: FrontendConfig | None = None, extractor=None) -> np.ndarray:
    """Fill ``kf.landmarks`` from the keyframe's own depth image or right image.

    RGB-D and stereo keyframes need no neighbours for loop verification's 3-D points; a
    monocular keyframe uses :func:`slam_lcd.frontend.triangulate_landmarks` instead.
    """
    if kf.features is None or kf.camera is None:
        raise ValueError("landmarks_from_sensor needs a keyframe with features and a camera model")
    if kf.depth is not None:
        pts, _ = points_from_depth(kf.camera, kf.features, kf.depth, conf)
    elif kf.right_image is not None and kf.image is not None:
        if not kf.camera.baseline:
            raise ValueError("stereo keyframe without a baseline in its camera model")
        if extractor is None:
            extractor = default_extractor(conf or FrontendConfig())
        pts, _ = points_from_stereo(kf.camera, kf.camera.baseline, kf.features, to_gray_uint8(kf.image),
                                    to_gray_uint8(kf.right_image), extractor, conf)
    else:
        raise ValueError("keyframe has neither a depth image nor a right image")
    kf.landmarks = pts
    return pts
