"""`slam-lcd run --rerun [spawn | FILE.rrd]`: keyframes and loops logged while the run goes.

The hook is the pipeline's keyframe sink, the one the loop pictures' album already takes: each
keyframe passes once, after loop detection, with its image and keypoints still there (they are
dropped right after), and each loop the detector verifies passes through ``keep_loop``. So a
live recording holds what a run folder cannot: every keyframe's image (a small JPEG, at most
:data:`~slam_lcd.viewer.images.IMAGE_WIDTH` pixels wide) with its keypoints, under ``world/live/camera`` at the odometry
pose it had then, and the verified loops as they were found (``world/live/loops``). When the
run's outputs are written, :meth:`LiveRecorder.finish` adds what ``slam-lcd view`` shows of the
run folder (corrected trajectory, keyframe frusta, loops by the back end's verdict, map cloud,
ATE over time) to the same recording, and the ``.rrd`` is renamed into place.

Why it never costs the run: an error while logging is reported in one warning and logging stops; the album
and the run go on.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..errors import SlamLcdError, ViewerMissingError
from . import INSTALL_HINT, TIMELINE, require_rerun
from .folders import read_run
from .images import jpeg, thumbnail
from .layout import blueprint
from .record import log_run, seconds
from .targets import AtomicRrd, check_display, close, new_stream

log = logging.getLogger(__name__)

SPAWN = "spawn"


class LiveRecorder:
    """A recording fed while a run goes: ``target`` is ``'spawn'`` (the native viewer) or an ``.rrd`` path."""

    def __init__(self, target: str, name: str):
        import importlib.util
        import threading

        if importlib.util.find_spec("rerun") is None:  # said now, before the run starts, not at its first keyframe
            raise ViewerMissingError(f"the Rerun viewer needs rerun-sdk, which is not installed: {INSTALL_HINT}")
        if target == SPAWN:
            check_display()
        self.file: AtomicRrd | None = None if target == SPAWN else AtomicRrd(target)
        self.positions: dict[int, np.ndarray] = {}
        self.loops: list[np.ndarray] = []
        self.failed: str | None = None
        self.keyframes = 0
        self._setup_error: BaseException | None = None
        # importing rerun and building the layout take about 0.6 s: done beside the run's own start
        # (reading the log's index, loading the model), not before it
        self._setup = threading.Thread(target=self._open_stream, args=(target, name), name="rerun-setup",
                                       daemon=True)
        self._setup.start()

    def _open_stream(self, target: str, name: str) -> None:
        try:
            rr = require_rerun()

            bp = blueprint(images=True, ate=True)
            rec = new_stream(name)
            if self.file is None:
                rec.spawn(default_blueprint=bp)
            else:
                rec.set_sinks(rr.FileSink(self.file.tmp), default_blueprint=bp)
            rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
            self._rec = rec
        except BaseException as e:  # raised where the stream is first used
            self._setup_error = e

    @property
    def rec(self):
        """The recording stream, once the setup thread has opened it (its error raised here)."""
        self._setup.join()
        if self._setup_error is not None:
            raise self._setup_error
        return self._rec

    # ------------------------------------------------------------------ the pipeline's side
    def sink(self, album=None) -> _Tee:
        """The keyframe sink to give the pipeline: the album's (when there is one) and this recorder's."""
        return _Tee(self, album)

    def keyframe(self, kf) -> None:
        rr = require_rerun()
        rec = self.rec
        rec.set_time(TIMELINE, timestamp=seconds([int(kf.stamp)])[0])
        T = np.asarray(kf.T_world_body, float) @ np.asarray(kf.T_body_camera, float)
        self.positions[int(kf.id)] = np.asarray(kf.T_world_body, float)[:3, 3].copy()
        small, s = thumbnail(kf.colour if kf.colour is not None else kf.image)
        data = jpeg(small)
        parts = [rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3])]
        cam = kf.camera
        if cam is not None:
            parts.append(rr.Pinhole(focal_length=[cam.fx * s, cam.fy * s], principal_point=[cam.cx * s, cam.cy * s],
                                    width=small.shape[1], height=small.shape[0], camera_xyz=rr.ViewCoordinates.RDF,
                                    image_plane_distance=0.3))
        if data is not None:
            parts.append(rr.EncodedImage(contents=data, media_type="image/jpeg"))
        rec.log("world/live/camera", *parts)
        kp = np.asarray(kf.features.keypoints, np.float32)[:, :2] * s if kf.features is not None else np.zeros((0, 2))
        rec.log("world/live/camera/keypoints", rr.Points2D(kp, colors=[(255, 220, 0)], radii=[1.0]))
        self.keyframes += 1

    def loop(self, record) -> None:
        """A loop the detector verified (the back end has not judged it yet): a segment between its keyframes."""
        rr = require_rerun()
        q, m = self.positions.get(int(record.query_id)), self.positions.get(int(record.match_id))
        if q is None or m is None:  # a match in an earlier session of a map: not in this log's poses
            return
        self.loops.append(np.stack([q, m]))
        self.rec.log("world/live/loops", rr.LineStrips3D(self.loops, colors=[(255, 200, 0)], radii=[0.02]))

    def stop(self, why: Exception) -> None:
        self.failed = f"{why.__class__.__name__}: {why}"
        log.warning("rerun: live logging stopped (%s); the run goes on", self.failed)

    # ------------------------------------------------------------------ the end of the run
    def finish(self, out_dir: str | Path, gt=None) -> Path | None:
        """Add the run folder's contents, close the stream and (a file) rename it into place; its path or None.

        ``gt``: the ground truth the run evaluated against (``RunResult.ground_truth``): reading it
        again from the log would cost as much as a tenth of the run."""
        try:
            rec = self.rec
        except Exception as e:  # the stream never opened (a viewer that would not start): the run stands
            self.stop(e)
            self.discard()
            return None
        try:
            run = read_run(out_dir, gt=gt)
        except SlamLcdError as e:  # an interrupted run's partial set: the live part is kept
            log.warning("rerun: the run folder is not added to the recording (%s)", e)
        else:
            log_run(rec, run)
        close(rec)
        return self.file.commit() if self.file is not None else None

    def discard(self) -> None:
        try:
            self._setup.join()
            if self._setup_error is None:
                close(self._rec)
        finally:
            if self.file is not None:
                self.file.discard()


class _Tee:
    """The pipeline's keyframe sink (and ``keep_loop``) for the album and the live recorder together."""

    def __init__(self, live: LiveRecorder, album=None):
        self.live = live
        self.album = album

    def __call__(self, kf) -> None:
        if self.album is not None:
            self.album(kf)
        self._live(self.live.keyframe, kf)

    def keep_loop(self, record) -> None:
        if self.album is not None:
            self.album.keep_loop(record)
        self._live(self.live.loop, record)

    def _live(self, call, arg) -> None:
        if self.live.failed is None:
            try:
                call(arg)
            except Exception as e:  # the recording is a view of the run: never its end
                self.live.stop(e)
