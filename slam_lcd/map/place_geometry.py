"""Would the view a place keeps localise the view it stands for? The loop chain's pose stage on the pair.

:mod:`slam_lcd.map.places` drops a view (redundant) or replaces a kept one (richer) when one of the
two holds a large share of the other's descriptors as mutual nearest neighbours. A share alone does
not say that the view that stays would localise the one that goes: night descriptors are less
distinctive, so a night view a metre off its place's only night view still shares a third of its
descriptors with it, many of them look-alikes that no single pose explains; a log passing there
finds matches but no pose. So before a view goes, the view that stays must give it a pose the way
a localiser would: the mutual matches of the two views, the staying view's 3-D points (its camera
frame) against the going view's keypoints (undistorted with its session's camera), through the
loop chain's own pose stage (:func:`slam_lcd.lcd.geometry.estimate_loop_pose`: PnP-RANSAC, the
refinement, ``lcd.pnp_min_inliers`` or the tight-pose rule, ``lcd.pnp_max_rms_px``). Why that stage
and no threshold of its own: "would localise" is exactly what it decides when a log is localised
against the map or a loop is closed, with the same ``lcd`` settings.

Where either view has no 3-D points (a monocular map, or a session recorded without a camera
model) there is nothing to solve a pose from, and the share rule decides alone (:meth:`Localises.check`
gives None).
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..lcd.config import LcdConfig
from ..lcd.geometry import estimate_loop_pose
from ..types import CameraModel, Features, Keyframe

Pairs = Callable[[], tuple[np.ndarray, np.ndarray]]  # rows of the going view, of the staying view: mutual matches


@dataclass
class View:
    """What the check needs of a view: its keypoints (pixels as detected), the 3-D point of each
    (its camera frame, NaN where unknown) and where they come from, and its session's camera."""

    keypoints: np.ndarray
    points3d: np.ndarray
    source: str
    camera: CameraModel | None

    def has_points(self) -> bool:
        """Any 3-D point in front of the camera (a session file without points holds NaN or zeros)."""
        P = np.asarray(self.points3d, float).reshape(-1, 3)
        return self.camera is not None and bool(np.any(np.all(np.isfinite(P), axis=1) & (P[:, 2] > 0)))

    def keyframe(self, kf_id: int) -> Keyframe:
        cam = self.camera
        size = (cam.width, cam.height) if cam is not None else (0, 0)
        feats = Features(np.asarray(self.keypoints, np.float32).reshape(-1, 2), np.zeros(0, np.float32),
                         np.zeros((0, 1), np.float32), size)
        return Keyframe(id=kf_id, stamp=0, T_world_body=np.eye(4), camera=cam, features=feats)


@dataclass
class Check:
    """The pose stage's verdict on a pair: whether the staying view localises the going one, and why not."""

    ok: bool
    inliers: int
    matches: int
    reason: str


class Localises:
    """The pose check of a pair of views, each pair solved once (:func:`slam_lcd.map.places.judge` meets a
    pair once; :func:`slam_lcd.map.places.prune` may meet it again after a richer view took a place)."""

    def __init__(self, conf: LcdConfig | None = None) -> None:
        self.conf = conf or LcdConfig()
        self._done: dict[tuple[int, int], Check | None] = {}

    def check(self, stays: int, stays_view: Callable[[], View | None] | None, goes: int,
              goes_view: Callable[[], View | None] | None, pairs: Pairs) -> Check | None:
        """Whether view ``stays`` (its 3-D points) localises view ``goes`` (its keypoints) from ``pairs``, the
        mutual nearest neighbours of their descriptors (asked for only when both views have 3-D points);
        None where either has none (or no camera): the share rule decides alone."""
        key = (stays, goes)
        if key not in self._done:
            self._done[key] = self._solve(stays, stays_view, goes, goes_view, pairs)
        return self._done[key]

    def _solve(self, stays: int, stays_view: Callable[[], View | None] | None, goes: int,
               goes_view: Callable[[], View | None] | None, pairs: Pairs) -> Check | None:
        vs = stays_view() if stays_view is not None else None
        vg = goes_view() if goes_view is not None else None
        if vs is None or vg is None or not vs.has_points() or not vg.has_points():
            return None
        ig, is_ = pairs()
        matches = np.column_stack([ig, is_]).astype(np.int64)
        pose = estimate_loop_pose(vg.keyframe(goes), vs.keyframe(stays), matches, self.conf,
                                  points3d_m=np.asarray(vs.points3d, float), source=vs.source)
        return Check(bool(pose.ok), int(pose.inliers), len(matches), pose.reason)


def stored_view(keypoints: np.ndarray, points3d: np.ndarray, source: str,
                camera: CameraModel | None) -> Callable[[], View]:
    """A view of a keyframe's stored arrays, built when the check asks for it."""
    return lambda: View(keypoints, points3d, source, camera)
