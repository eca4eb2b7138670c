"""Left and right images of a stereo log paired for the main pass, so loop poses get stereo points.

Loop verification takes a keyframe's 3-D points from a rectified stereo partner when the
keyframe has no depth (:func:`slam_lcd.lcd.geometry.keyframe_points3d`: SGBM disparity,
``camera.baseline``, the stereo point-noise model of the loop information). So a stereo log
without depth hands the pipeline each left image together with its right image: the
detector computes the disparity once per keyframe, never for the frames in between (the
pipeline drops a frame's right image unless the frame becomes a keyframe).

A pair described by ``CameraInfo`` (KITTI, ROS ``image_proc`` output) is taken as
rectified; a raw calibrated pair (EuRoC) is rectified here with the same
:class:`~slam_lcd.sensors.rectify.StereoRectifier` as the stereo VO, and the main pass then
sees the rectified left camera (``rectifier.camera``, mounted at ``T_body_cam0 @ T_cam0_rect``).
"""
from __future__ import annotations

import numpy as np

from .log_vo import PAIR_TOLERANCE_NS, camera_info_topic_of  # the VO pass pairs its images within the same tolerance
from .messages import camera_from_camera_info


def right_camera_info_baseline(reader, right_topic: str) -> float | None:
    """The baseline a rectified right camera's ``CameraInfo`` states (``P[0,3] = -fx * b``), or None."""
    info = camera_info_topic_of(right_topic)
    if info not in reader.topics:
        return None
    for m in reader.messages([info]):
        return camera_from_camera_info(m.msg).baseline or None
    return None


class StereoFrames:
    """Left images paired with the right image of the same stamp (within ``tolerance_ns``), in order.

    Each left image comes out once, as ``(stamp, left, right | None)`` (None: its right image
    is missing); with a ``rectifier`` both come out rectified. ``baseline`` is the rectified
    pair's (the main pass's camera carries it).
    """

    def __init__(self, right_topic: str, *, baseline: float, rectifier=None, tolerance_ns: int = PAIR_TOLERANCE_NS):
        self.right_topic = right_topic
        self.baseline = float(baseline)
        self.rectifier = rectifier
        self.tolerance_ns = int(tolerance_ns)
        self._lefts: list[tuple[int, np.ndarray]] = []
        self._rights: dict[int, np.ndarray] = {}
        self.unpaired = 0

    def add_left(self, stamp: int, image: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray | None]]:
        self._lefts.append((int(stamp), image))
        return self._pairs()

    def add_right(self, stamp: int, image: np.ndarray) -> list[tuple[int, np.ndarray, np.ndarray | None]]:
        self._rights[int(stamp)] = image
        return self._pairs()

    def flush(self) -> list[tuple[int, np.ndarray, np.ndarray | None]]:
        """The left images still waiting (the log ended): each with its pair if it came, else alone."""
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
            right = None
            if self.rectifier is not None:  # the main pass sees the rectified camera: warp the lone left image too
                img, _ = self.rectifier.rectify(img, img)
            return stamp, img, right
        right = self._rights.pop(partner)
        if self.rectifier is not None:
            img, right = self.rectifier.rectify(img, right)
        return stamp, img, right

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
                self._rights.pop(s)  # older than every waiting left image: no partner any more
        return out
