"""Camera frames waiting for the odometry to reach their stamp, and for their depth image.

Why its own module: a frame can only become a keyframe once the odometry covers its stamp
(its pose is interpolated there), and on an RGB-D log its depth image may come before or
after it: message order at equal stamps differs between log formats, and the result must
not. The :class:`~slam_lcd.run.pipeline.Pipeline` asks this queue which frames are ready and
processes them; a frame it could not finish (an interrupt) goes back to the front.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EARLY_DEPTH_KEPT = 8  # depth images kept for frames not seen yet (only the newest: their images may never come)


@dataclass
class WaitingFrame:
    """A camera frame (and its depth, right or colour image) until the odometry reaches its stamp.

    Not :class:`slam_lcd.io.image_folder.Frame`, which is a named image read from a folder or topic."""

    stamp: int
    image: np.ndarray
    depth: np.ndarray | None = None
    right_image: np.ndarray | None = None
    colour: np.ndarray | None = None


class FrameQueue:
    """Frames in arrival order, and depth images that arrived before their frame."""

    def __init__(self):
        self.pending: list[WaitingFrame] = []
        self._early_depth: dict[int, np.ndarray] = {}  # depth that arrived before its image

    def add(self, stamp_ns: int, image: np.ndarray, depth: np.ndarray | None = None,
            right_image: np.ndarray | None = None, colour: np.ndarray | None = None) -> None:
        if depth is None:
            depth = self._early_depth.pop(int(stamp_ns), None)
        self.pending.append(WaitingFrame(int(stamp_ns), image, depth, right_image, colour))

    def add_depth(self, stamp_ns: int, depth: np.ndarray) -> bool:
        """Give the waiting frame of ``stamp_ns`` its depth (True), or keep the depth for a frame to come (False)."""
        stamp_ns = int(stamp_ns)
        for f in self.pending:
            if f.stamp == stamp_ns:
                f.depth = depth
                return True
        self._early_depth[stamp_ns] = depth
        while len(self._early_depth) > EARLY_DEPTH_KEPT:  # depth whose image never came: keep only the newest
            self._early_depth.pop(min(self._early_depth))
        return False

    def take_ready(self, first: int, last: int, *, final: bool, expect_depth: bool) -> list[WaitingFrame]:
        """Remove and return the frames the odometry from ``first`` to ``last`` covers (all with ``final``).

        With ``expect_depth`` the newest frame waits for its depth (or for the next frame). Frames
        before ``first`` are dropped: there is no pose to attach to them.
        """
        keep, ready = [], []
        newest = self.pending[-1] if self.pending else None
        for f in self.pending:
            complete = f.depth is not None or not expect_depth or f is not newest
            if (f.stamp <= last and complete) or final:
                if f.stamp < first:
                    continue  # before the first odometry sample: no pose to attach
                ready.append(f)
            else:
                keep.append(f)
        self.pending = keep
        return ready

    def put_back(self, frames: list[WaitingFrame]) -> None:
        """Frames taken but not processed (an interrupt) go back to the front, in order."""
        self.pending = frames + self.pending

    def clear(self) -> None:
        self.pending.clear()
