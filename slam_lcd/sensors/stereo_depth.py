"""Depth of the left camera from a stereo pair, for the loop poses of a stereo log without depth.

Loop verification takes a keyframe's 3-D points from its depth image
(:func:`slam_lcd.lcd.geometry.keyframe_points3d`), so a stereo log hands the pipeline a
:class:`StereoDepth` as each frame's depth: the pair, turned into a depth image aligned with
the left image the first time it is read (``np.asarray``). Only keyframes are read, so the
semi-global matching (:func:`slam_lcd.vision.points.dense_disparity`) runs once per
keyframe, never for the frames in between.

The depth is ``z`` of the left camera as the main pass sees it: for a rectified pair
(``CameraInfo`` pairs, KITTI) ``fx * baseline / disparity`` pixel by pixel; for a raw
calibrated pair (EuRoC) the pair is rectified first (:mod:`slam_lcd.sensors.rectify`),
the disparity found on the rectified grid, and each raw left pixel given the ``z`` in the
raw camera frame of the point seen along its ray (so back-projecting the raw keypoint
through the raw camera with its distortion gives that point).
"""
from __future__ import annotations

import cv2
import numpy as np

from ..types import CameraModel
from ..vision.points import dense_disparity

MIN_DISPARITY_PX = 0.5  # below this a disparity is no depth (SGBM marks unmatched pixels negative)


class StereoDepthMap:
    """How a pair becomes depth of the left camera: rectified as given, or through a rectifier."""

    def __init__(self, camera: CameraModel, baseline: float | None = None, rectifier=None):
        self.rectifier = rectifier
        if rectifier is None:
            b = baseline if baseline else camera.baseline
            if not b or b <= 0:
                raise ValueError("a rectified stereo pair needs a positive baseline")
            self.fx_b = float(camera.fx) * float(b)
            self._raw_to_rect = None
            return
        rc = rectifier.camera
        self.fx_b = float(rc.fx) * float(rc.baseline)
        # where each raw left pixel lies on the rectified grid, and the ray's z in the raw frame per unit rectified z
        R1 = np.asarray(rectifier.T_cam0_rect[:3, :3]).T  # X_rect = R1 X_cam0
        u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
        grid = np.stack([u.ravel(), v.ravel()], 1).reshape(-1, 1, 2)
        D = np.zeros(5) if camera.distortion_model == "none" else np.asarray(camera.D, np.float64).reshape(-1)
        if camera.distortion_model == "equidistant":
            q = cv2.fisheye.undistortPoints(grid, camera.K, D[:4], R=R1, P=rc.K)
        else:
            q = cv2.undistortPoints(grid, camera.K, D, R=R1, P=rc.K)
        q = q.reshape(camera.height, camera.width, 2)
        rays_rect = np.dstack([(q[..., 0] - rc.cx) / rc.fx, (q[..., 1] - rc.cy) / rc.fy, np.ones(q.shape[:2])])
        self._z_scale = (rays_rect @ R1)[..., 2]  # (R1^T ray_rect).z: raw-frame z of the point at rectified z = 1
        self._raw_to_rect = (q[..., 0].astype(np.float32), q[..., 1].astype(np.float32))

    def depth(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Depth (metres, float32, NaN where unknown) of every left pixel."""
        if self.rectifier is not None:
            left, right = self.rectifier.rectify(left, right)
        disp = dense_disparity(left, right)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(disp > MIN_DISPARITY_PX, self.fx_b / disp, np.nan)
        if self._raw_to_rect is None:
            return z.astype(np.float32)
        z_rect = cv2.remap(z.astype(np.float32), *self._raw_to_rect, cv2.INTER_NEAREST,
                           borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
        return (z_rect * self._z_scale).astype(np.float32)


class StereoDepth:
    """A frame's depth from its stereo pair, computed when first read (``np.asarray``) and kept."""

    __slots__ = ("_map", "_left", "_right", "_depth")

    def __init__(self, depth_map: StereoDepthMap, left: np.ndarray, right: np.ndarray):
        self._map, self._left, self._right, self._depth = depth_map, left, right, None

    def __array__(self, dtype=None, copy=None):
        if self._depth is None:
            self._depth = self._map.depth(self._left, self._right)
            self._left = self._right = None  # the pair is not needed any more
        return self._depth if dtype is None else self._depth.astype(dtype)

    @property
    def shape(self):
        return np.shape(self._left) if self._depth is None else self._depth.shape


def right_camera_info_baseline(reader, right_topic: str) -> float | None:
    """The baseline a rectified right camera's ``CameraInfo`` states (``P[0,3] = -fx * b``), or None."""
    from .log_vo import camera_info_topic_of
    from .messages import camera_from_camera_info

    info = camera_info_topic_of(right_topic)
    if info not in reader.topics:
        return None
    for m in reader.messages([info]):
        return camera_from_camera_info(m.msg).baseline or None
    return None


class StereoFrames:
    """Left images paired with the right image of the same stamp (within ``tolerance_ns``).

    Each left image comes out once, in order, with a :class:`StereoDepth` of its pair (None
    when its right image is missing or the camera is not known yet). ``camera`` is the main
    pass's left camera (set once known); ``rectifier`` makes a raw calibrated pair rectified.
    """

    def __init__(self, right_topic: str, *, camera: CameraModel | None = None, baseline: float | None = None,
                 rectifier=None, tolerance_ns: int = 5_000_000):
        self.right_topic = right_topic
        self.camera = camera
        self.baseline = baseline
        self.rectifier = rectifier
        self.tolerance_ns = int(tolerance_ns)
        self._map: StereoDepthMap | None = None
        self._lefts: list[tuple[int, np.ndarray]] = []
        self._rights: dict[int, np.ndarray] = {}
        self.unpaired = 0

    def _depth_map(self) -> StereoDepthMap | None:
        if self._map is None and self.camera is not None:
            self._map = StereoDepthMap(self.camera, self.baseline, self.rectifier)
        return self._map

    def add_left(self, stamp: int, image: np.ndarray) -> list[tuple[int, np.ndarray, StereoDepth | None]]:
        self._lefts.append((int(stamp), image))
        return self._pairs()

    def add_right(self, stamp: int, image: np.ndarray) -> list[tuple[int, np.ndarray, StereoDepth | None]]:
        self._rights[int(stamp)] = image
        return self._pairs()

    def flush(self) -> list[tuple[int, np.ndarray, StereoDepth | None]]:
        """The left images still waiting (the log ended): each with its pair if it came, else without depth."""
        out = self._pairs()
        for stamp, img in self._lefts:
            out.append(self._with_partner(stamp, img, self._partner(stamp)))
        self._lefts.clear()
        return out

    def _partner(self, stamp: int) -> int | None:
        near = [s for s in self._rights if abs(s - stamp) <= self.tolerance_ns]
        return min(near, key=lambda s: abs(s - stamp)) if near else None

    def _with_partner(self, stamp, img, partner):
        if partner is None:
            self.unpaired += 1
            return stamp, img, None
        right = self._rights.pop(partner)
        m = self._depth_map()
        return stamp, img, (StereoDepth(m, img, right) if m is not None else None)

    def _pairs(self):
        out = []
        while self._lefts:
            stamp, img = self._lefts[0]
            partner = self._partner(stamp)
            later = any(s > stamp + self.tolerance_ns for s in self._rights)
            if partner is None and not later:
                break  # its right image may still come
            self._lefts.pop(0)
            out.append(self._with_partner(stamp, img, partner))
            for s in [s for s in self._rights if s < stamp - self.tolerance_ns]:
                self._rights.pop(s)  # right images older than every waiting left one: no partner any more
        return out
