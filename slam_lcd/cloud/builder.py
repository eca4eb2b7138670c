"""The map's cloud from keyframes: sensor points per keyframe as they come, merged with any poses at the end.

:class:`MapCloudBuilder` takes each keyframe while it still has its depth or stereo images
(the pipeline hands it over before they are dropped), keeps its points (merged per voxel in the
body frame) in a :class:`~.store.KeyframeCloudStore`, and :meth:`MapCloudBuilder.cloud` merges
them into a :class:`~.voxel_grid.VoxelGrid` with the poses given (odometry or corrected).
``export-map`` goes the same way, so that it gives the run's ``map.ply`` point for point when its
settings are the run's.

Keyframes it cannot use are skipped and counted by reason; each reason is logged once (a log
warning naming the source), never an error: the map is a view of the run, not part of it.
"""
from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any

import numpy as np

from ..errors import InputError
from ..types import Keyframe
from .config import MapCloudConfig
from .sensor_points import SensorPoints, depth_points, stereo_points
from .store import KeyframeCloudStore
from .voxel_grid import Cloud, VoxelGrid, voxel_means

log = logging.getLogger(__name__)


def keyframe_points(kf: Keyframe, conf: MapCloudConfig) -> SensorPoints | None:
    """The keyframe's camera-frame points (depth first, else a rectified stereo pair); None without either."""
    cam = kf.camera
    if cam is None:
        return None
    colour = getattr(kf, "colour", None)
    kw: dict[str, Any] = dict(step=conf.pixel_step, min_depth=conf.min_depth_m, max_depth=conf.max_depth_m)
    if kf.depth is not None:
        return depth_points(cam, kf.depth, colour if colour is not None else kf.image, **kw)
    if kf.right_image is not None and kf.image is not None and cam.baseline:
        return stereo_points(cam, kf.image, kf.right_image, colour, match_step=conf.stereo_match_step,
                             max_jump=conf.stereo_max_jump_px, **kw)
    return None


def _to_body(sp: SensorPoints, T_body_camera: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """Points in the body frame, merged per voxel (a keyframe's many pixels per voxel become one point)."""
    T = np.asarray(T_body_camera, np.float64)
    pts = sp.points @ T[:3, :3].T.astype(np.float32) + T[:3, 3].astype(np.float32)
    return voxel_means(pts, sp.colours, voxel)


class Skips:
    """Keyframes left out, counted by reason; the first of each reason is said (naming ``source``)."""

    def __init__(self, source: str = ""):
        self.source = source
        self.counts: dict[str, int] = {}
        self._pending: list[str] = []

    def add(self, reason: str, *, later: bool = False) -> None:
        """Count a keyframe left out; the first of a reason is said now, or (``later``) when the map is built.

        ``later`` is for a failure of the builder itself (its store's disk full, say): the run
        meets the same cause writing its own files and says it in its one line; the map's warning
        is only worth a line when the run goes on to build the map."""
        if reason not in self.counts:
            if later:
                self._pending.append(reason)
            else:
                self._say(reason)
        self.counts[reason] = self.counts.get(reason, 0) + 1

    def say_pending(self) -> None:
        for reason in self._pending:
            self._say(reason)
        self._pending.clear()

    def _say(self, reason: str) -> None:
        log.warning("%smap cloud: %s; such keyframes are left out of the map", f"{self.source}: " if self.source
                    else "", reason)

    def points_of(self, kf: Keyframe, conf: MapCloudConfig) -> SensorPoints | None:
        """:func:`keyframe_points`, or None (counted) when the keyframe gives none."""
        try:
            sp = keyframe_points(kf, conf)
        except InputError as e:
            self.add(e.problem)
            return None
        if sp is None:
            self.add("no depth image and no stereo pair")
        elif len(sp) == 0:
            self.add(f"no valid depth in range {conf.min_depth_m:g}-{conf.max_depth_m:g} m")
            sp = None
        return sp


def _snapshot(kf: Keyframe) -> Keyframe:
    """What the cloud needs of a keyframe, kept apart from it (the pipeline drops the images once it is done)."""
    return Keyframe(id=kf.id, stamp=kf.stamp, T_world_body=kf.T_world_body, image=kf.image, camera=kf.camera,
                    T_body_camera=kf.T_body_camera, depth=kf.depth, right_image=kf.right_image,
                    colour=getattr(kf, "colour", None))


class MapCloudBuilder:
    """See the module docstring. ``source``: the topic(s) named in warnings; ``folder``: where the store's file lives.

    With ``conf.queue_keyframes`` > 0 the keyframes are taken in a thread of the builder's own, through a
    queue of that many (the caller waits only when it is full): back-projection, stereo matching and
    the voxel merge run in numpy and OpenCV, which release the GIL, so on a second core the run does
    not wait for them. One thread and a first-in-first-out queue: the store, and so the map, is the same
    as when they are taken in the caller's thread. Whatever reads the builder's state waits for the queue.
    """

    def __init__(self, conf: MapCloudConfig | None = None, *, source: str = "", folder=None):
        self.conf = conf or MapCloudConfig()
        self.store = KeyframeCloudStore(self.conf.voxel_m, folder)
        self.skips = Skips(source)
        self.seconds = 0.0  # time spent taking keyframes in (in the builder's thread when it has one)
        self.wait_seconds = 0.0  # the caller's time in add_keyframe (handing over, waiting on a full queue)
        self.points_in = 0
        self.failed: str | None = None  # an unexpected error in the builder's thread: no more keyframes taken
        self._queue: queue.Queue | None = None
        self._thread: threading.Thread | None = None
        if self.conf.queue_keyframes > 0:
            self._queue = queue.Queue(maxsize=int(self.conf.queue_keyframes))
            self._thread = threading.Thread(target=self._work, name="slam-lcd-map-cloud", daemon=True)
            self._thread.start()

    @property
    def skipped(self) -> dict[str, int]:
        self.drain()
        return self.skips.counts

    def add_keyframe(self, kf: Keyframe) -> bool:
        """Keep the keyframe's points. In the caller's thread: False (counted, one warning per reason) when it
        has none to give; with a thread of its own: True once handed over (False after a failure there)."""
        t0 = time.perf_counter()
        try:
            if self._queue is None:
                return self._take(kf)
            if self.failed is not None:
                self.skips.add(self.failed, later=True)
                return False
            self._queue.put(_snapshot(kf))
            return True
        finally:
            self.wait_seconds += time.perf_counter() - t0

    def _take(self, kf: Keyframe) -> bool:
        t0 = time.perf_counter()
        try:
            sp = self.skips.points_of(kf, self.conf)
            if sp is None:
                return False
            self.points_in += len(sp)
            pts, col = _to_body(sp, kf.T_body_camera, self.conf.voxel_m)
            self.store.add(kf.id, kf.stamp, pts, col)
            return True
        finally:
            self.seconds += time.perf_counter() - t0

    def _work(self) -> None:
        assert self._queue is not None  # the thread is made with its queue
        while True:
            kf = self._queue.get()
            try:
                if kf is None:
                    return
                if self.failed is None:
                    self._take(kf)
                else:
                    self.skips.add(self.failed, later=True)
            except Exception as e:  # the map is a view of the run: one warning, never raised into the run
                self.failed = f"failed from keyframe {kf.id} on ({e.__class__.__name__}: {e})"
                self.skips.add(self.failed, later=True)
            finally:
                self._queue.task_done()

    def drain(self) -> None:
        """Wait until every keyframe handed over is taken (no-op without a thread); the wait counts as the
        caller's (``wait_seconds``)."""
        if self._queue is not None and self._thread is not None and self._thread.is_alive():
            t0 = time.perf_counter()
            self._queue.join()
            self.wait_seconds += time.perf_counter() - t0

    @property
    def n_keyframes(self) -> int:
        self.drain()
        return len(self.store)

    def cloud(self, poses: dict[int, np.ndarray], voxel: float | None = None) -> Cloud:
        """The map with ``poses`` (keyframe id -> 4x4 ``T_world_body``); keyframes without a pose are left out."""
        self.drain()
        self.skips.say_pending()
        grid = VoxelGrid(voxel or self.conf.voxel_m)
        for i, (kf_id, _, _, _) in enumerate(self.store.index):
            T = poses.get(kf_id)
            if T is None:
                continue
            pts, col = self.store.read(i)
            grid.add(pts @ T[:3, :3].T + T[:3, 3], col)
        return grid.cloud(self.conf.min_keyframes_per_voxel)

    def close(self) -> None:
        """Stop the builder's thread (after the keyframes handed over) and remove the store's file."""
        if self._queue is not None and self._thread is not None and self._thread.is_alive():
            self._queue.put(None)
            self._thread.join()
        self.store.close()
