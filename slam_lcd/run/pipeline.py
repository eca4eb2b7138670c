"""The whole chain as one object: odometry + images in, loop closures and a corrected trajectory out.

:class:`Pipeline` is the plugin API: a user's own front end feeds it odometry samples and
camera frames (or ready-made keyframes) and gets loop closures through a callback and the
corrected trajectory at any time. :func:`slam_lcd.run.runner.run_log` drives it from a recorded
log and writes every output file.

Stages: keyframe selection (:mod:`slam_lcd.frontend`) → features (:mod:`slam_lcd.features`)
→ BoW candidates, graph verification, metric pose (:mod:`slam_lcd.lcd`, :mod:`slam_lcd.vocab`)
→ iSAM2 pose graph with robust loop handling (:mod:`slam_lcd.backend`) → full-rate correction.

Interrupts: every step leaves the pipeline consistent whatever instant a Ctrl-C (or an
error inside a stage) stops it. A keyframe is in the pose graph exactly when it is in
:attr:`Pipeline.keyframes`; loop detection runs after that, and a loop is in the graph's
records exactly when iSAM2 holds it (see :mod:`slam_lcd.backend.pose_graph`). Frames not
yet processed stay queued. An interrupt inside the loop detector itself may leave its
database half-updated: its candidates for that keyframe are dropped and later keyframes
go to the back end without loop detection (one warning says so).

Background extraction (``run.extract_ahead``): a keyframe's features are computed in a worker
thread while earlier keyframes go through loop detection (``run.lcd_threads`` BLAS/faiss threads
while it runs); keyframes reach the graph in order; one interrupted waiting for features stays queued.
"""
from __future__ import annotations

import logging
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future

import numpy as np

from ..backend import PoseGraph, correct_full_rate
from ..backend.pose_graph import ACCEPTED
from ..config import Config
from ..features import load_extractor
from ..frontend import KeyframeSelector
from ..frontend.odometry_buffer import OdometryBuffer
from ..lcd import LoopDetector
from ..runtime.stage_timer import StageTimer, resident_kb
from ..runtime.thread_limits import limited_threads
from ..types import CameraModel, Keyframe, LoopClosure, Trajectory
from .extract_ahead import ExtractionPool
from .frame_queue import FrameQueue, WaitingFrame
from .odometry_breaks import OdometryBreaks

log = logging.getLogger(__name__)


class Pipeline:
    """Incremental loop-closing back end.

    Feed :meth:`add_odometry` with every odometry sample (any rate) and :meth:`add_image`
    with camera frames; frames wait until odometry covers their stamp, then the keyframe
    selector decides, loop detection runs on each keyframe and verified loops go to iSAM2.
    Or skip our front end and call :meth:`add_keyframe` directly.

    ``on_loop(closure, record)`` is called for every loop the back end accepts; ``loop_sink(record)``
    for every loop the detector hands on, with the matches its graph verified (before they are dropped);
    ``feature_source(stamp, image) -> Features`` replaces the extractor's own call (e.g. an
    on-disk cache keyed by log, topic and stamp); ``expect_depth``: see :meth:`_release`.
    ``map_cloud`` (a :class:`slam_lcd.cloud.MapCloudBuilder`) takes each keyframe the graph took,
    with its depth or stereo images, before they are dropped (the map's point cloud).
    """

    def __init__(
        self,
        config: Config | None = None,
        *,
        camera: CameraModel | None = None,
        T_body_camera: np.ndarray | None = None,
        extractor=None,
        vocab=None,
        on_loop: Callable[[LoopClosure, object], None] | None = None,
        feature_source: Callable[[int, np.ndarray], object] | None = None,
        expect_depth: bool = False,
        keyframe_sink: Callable[[Keyframe], None] | None = None,
        loop_sink: Callable[[object], None] | None = None,
        map=None,
        map_mode: str = "append",
        map_cloud=None,
    ):
        self.config = config or Config()
        self.camera = camera
        self.T_body_camera = np.eye(4) if T_body_camera is None else np.asarray(T_body_camera, float)
        if extractor is None:
            extractor = load_extractor(self.config.features)
        self.extractor = extractor
        self.selector = KeyframeSelector(self.config.frontend, camera=camera, T_body_camera=self.T_body_camera,
                                         keep_images=False)
        self.detector = LoopDetector(self.config.lcd, vocab=vocab, extractor=extractor, vocab_conf=self.config.vocab)
        self.detector.loop_sink = loop_sink  # sees each loop's verified matches (the loop pictures keep them)
        self.graph = PoseGraph(self.config.backend)
        self.on_loop = on_loop
        self.feature_source = feature_source
        # sees each keyframe (image and features) once, after loop detection, before they are dropped
        self.keyframe_sink = keyframe_sink
        self.map_cloud = map_cloud
        self.timer = StageTimer()
        self.keyframes: list[Keyframe] = []
        self.closures: list[LoopClosure] = []
        self._odom = OdometryBuffer()
        self._frames = FrameQueue()  # frames waiting for odometry (run.frame_queue)
        # when the log carries depth, a frame waits for its depth image (or for the next frame):
        # message order at equal stamps differs between log formats, the result must not
        self.expect_depth = bool(expect_depth)
        self.breaks = OdometryBreaks()  # tracking lost: which frame opens a segment, which have no pose
        self._finalized = False
        self._detector_stale = self._stale_warned = False  # an interrupt inside the detector: no more detection
        # keyframes handed in, made by the selector but not handed in, waiting for features / loops
        self._n_submitted = 0
        self._unsubmitted: list[tuple[int, Keyframe]] = []
        self._extraction = ExtractionPool(self.config.run, extractor)  # background extraction (run.extract_ahead)
        self._ahead = self._extraction.ahead
        self._inflight: deque[tuple[Keyframe, Future | None]] = deque()
        # per keyframe: seconds of loop detection (and its parts), of the back end, resident kB after it
        self.keyframe_seconds: list[dict[str, float]] = []
        # a multi-session map (slam_lcd.map.Map): its keyframes are loop candidates; loops to them are
        # collected here for the map's joint graph (this session's own pose graph cannot hold them)
        self.map = map
        self.map_closures: list[LoopClosure] = []
        self._id_base = 0
        if map_mode not in ("append", "localize"):
            raise ValueError(f"map_mode must be 'append' or 'localize', got {map_mode!r}")
        self._insert_keyframes = map is None or map_mode == "append"  # localize: the map stays as it is
        if map is not None:
            map.load_into(self.detector)
            self.detector.begin_session()
            self._id_base = map.next_kf_id()

    # ------------------------------------------------------------------ inputs
    def set_camera(self, camera: CameraModel, T_body_camera: np.ndarray | None = None) -> None:
        self.camera = camera
        self.selector.camera = camera
        if T_body_camera is not None:
            self.T_body_camera = np.asarray(T_body_camera, float)
            self.selector.T_body_camera = self.T_body_camera.copy()

    def add_odometry(self, stamp_ns: int, T_world_body: np.ndarray, covariance: np.ndarray | None = None,
                     *, segment_start: bool = False) -> list[LoopClosure]:
        """One odometry sample; returns the loops found on frames this sample released.

        ``segment_start=True``: the odometry broke here (tracking lost); the next keyframe opens a new segment.
        """
        if segment_start:
            self.breaks.add(stamp_ns)
        self._odom.add(stamp_ns, T_world_body, covariance)
        return self._release(final=False)

    def add_image(self, stamp_ns: int, image: np.ndarray, *, depth: np.ndarray | None = None,
                  right_image: np.ndarray | None = None, colour: np.ndarray | None = None) -> list[LoopClosure]:
        """One camera frame (grayscale or RGB); processed once odometry reaches its stamp.

        ``colour``: the same frame in colour (RGB uint8) when ``image`` is its grey version; only the
        map cloud uses it (the features see ``image``)."""
        self._frames.add(stamp_ns, image, depth, right_image, colour)
        return self._release(final=False)

    def add_depth(self, stamp_ns: int, depth: np.ndarray) -> list[LoopClosure]:
        """A depth image for the frame of the same stamp, whether that frame came before or comes after."""
        if self._frames.add_depth(stamp_ns, depth):
            return self._release(final=False)
        return []

    def add_keyframe(self, kf: Keyframe) -> list[LoopClosure]:
        """Plugin entry for a user's own front end: a ready keyframe (pose = odometry).

        With ``run.extract_ahead = N > 0`` the keyframe's features are extracted in a
        background thread and its loop detection runs once N newer keyframes have been
        handed in (or at :meth:`flush`/:meth:`finalize`): the loops returned by a call may
        belong to earlier keyframes. ``on_loop`` fires for each accepted loop either way.
        """
        kf.id = self._id_base + self._n_submitted
        if kf.camera is None:
            kf.camera = self.camera
        future = None
        if kf.features is None and kf.image is not None:
            if self._ahead > 0:
                future = self._extraction.submit(self._extract, kf.stamp, kf.image)
            else:
                kf.features = self._extract(kf.stamp, kf.image)
        self._inflight.append((kf, future))
        self._n_submitted += 1  # queued: an interrupt before this line hands the keyframe over again
        return self._drain(keep=self._ahead)

    def _drain(self, keep: int) -> list[LoopClosure]:
        """Detect loops on the oldest waiting keyframes until at most ``keep`` wait."""
        accepted: list[LoopClosure] = []
        while len(self._inflight) > keep:
            kf, future = self._inflight[0]
            if future is not None:
                with self.timer("features_wait"):
                    kf.features = future.result()
                self._inflight[0] = (kf, None)
            try:
                accepted += self._add_to_graph(kf)
            finally:
                if self.keyframes and self.keyframes[-1] is kf:  # the graph took it
                    self._inflight.popleft()
        return accepted

    def _add_to_graph(self, kf: Keyframe) -> list[LoopClosure]:
        """Pose graph, loop detection and loop factors for one keyframe with its features.

        Order (see the module docstring): the pose graph and :attr:`keyframes` together, then
        loop detection and the loops.
        """
        t0 = time.perf_counter()
        try:
            with self.timer("backend"):
                self.graph.add_keyframe(kf.id, kf.stamp, kf.T_world_body, kf.covariance_since_last,
                                        segment_start=kf.segment_start)
        finally:
            # if the pose graph took this keyframe (even when interrupted just after), the list keeps it too
            if len(self.graph) > len(self.keyframes):
                self.keyframes.append(kf)
        t1 = time.perf_counter()
        accepted = []
        try:
            closures = self._detect_loops(kf)
            t2 = time.perf_counter()
            for c in closures:
                if not np.all(np.isfinite(c.T_match_query)):
                    continue  # verified by appearance but no metric pose: nothing to add to the graph
                if c.evidence.get("inter_session"):
                    self.map_closures.append(c)  # judged with every session in the map's joint graph
                    continue
                n_loops = self.graph.n_loops
                try:
                    with self.timer("backend"):
                        rec = self.graph.add_loop(c)
                finally:
                    if self.graph.n_loops > n_loops:
                        self.closures.append(c)
                if getattr(rec, "verdict", "") == ACCEPTED:
                    accepted.append(c)
                    if self.on_loop is not None:
                        self.on_loop(c, rec)
        finally:
            if self.keyframe_sink is not None and kf.features is not None:
                self._sink(kf)
            if self.map_cloud is not None and self.keyframes and self.keyframes[-1] is kf:
                self._cloud(kf)
            # memory stays bounded: the detector keeps what it needs of past keyframes (compactly), this list poses only
            kf.image = None
            kf.right_image = None
            kf.depth = None
            kf.colour = None
            kf.features = None
        self.keyframe_seconds.append({"loop_detection": t2 - t1, "backend": (t1 - t0) + (time.perf_counter() - t2),
                                      "rss_kb": resident_kb(), **self.detector.last_part_seconds})
        return accepted

    def _sink(self, kf: Keyframe) -> None:
        sink = self.keyframe_sink
        if sink is None:
            return
        try:
            with self.timer("keyframe_sink"):
                sink(kf)
        except Exception as e:  # pictures are optional: a failure logs one warning and the run goes on
            log.warning("keyframe %d not kept for the loop pictures (%s); no more are kept", kf.id, e)
            self.keyframe_sink = None

    def _cloud(self, kf: Keyframe) -> None:
        try:
            with self.timer("map_cloud"):
                self.map_cloud.add_keyframe(kf)
        except Exception as e:  # the map cloud is optional: a failure logs one warning and the run goes on
            log.warning("keyframe %d not added to the map cloud (%s); no more are added", kf.id, e)
            self.map_cloud.close()
            self.map_cloud = None

    def _detect_loops(self, kf: Keyframe) -> list[LoopClosure]:
        """Loop detection for a keyframe already in the graph; an interrupt inside it drops its candidates."""
        self.detector.last_part_seconds = {}
        if self._detector_stale:
            if not self._stale_warned:  # warn once, when a keyframe actually goes without loop detection
                self._stale_warned = True
                log.warning("no loop detection from keyframe %d on: an earlier interrupt inside the loop "
                            "detector left its database incomplete", kf.id)
            return []
        det = self.detector
        n_records, n_closures = len(det.records), len(det.closures)
        done = False
        try:
            busy = any(f is not None and not f.done() for _, f in self._inflight)  # extraction running now
            with self.timer("loop_detection"), limited_threads(self._extraction.lcd_threads if busy else 0):
                closures = det.add(kf, insert=self._insert_keyframes)
            done = True
            return closures
        finally:
            if not done:
                del det.records[n_records:]
                del det.closures[n_closures:]
                self._detector_stale = True

    def close(self) -> None:
        """Stop the background extraction thread (waiting keyframes are not processed)."""
        self._extraction.close()

    # ------------------------------------------------------------------ internals
    def _extract(self, stamp: int, image: np.ndarray):
        with self.timer("features"):
            if self.feature_source is not None:
                return self.feature_source(stamp, image)
            return self.extractor.extract(image)

    def _release(self, final: bool) -> list[LoopClosure]:
        """Process the frames odometry covers (all with ``final``); with ``expect_depth`` the newest waits for
        its depth."""
        out: list[LoopClosure] = []
        if not self._odom:
            if final:
                self._frames.clear()
            return out
        ready = self._frames.take_ready(self._odom.stamps[0], self._odom.stamps[-1], final=final,
                                        expect_depth=self.expect_depth)
        for i, f in enumerate(ready):
            try:
                out += self._process(f)
            except BaseException:
                self._frames.put_back(ready[i + 1:])  # interrupted: the rest stays queued
                raise
        return out

    def _process(self, f: WaitingFrame) -> list[LoopClosure]:
        if self.breaks.inside(f.stamp, self._odom.stamps):  # no odometry pose there
            return []
        T, cov = self._odom.at(f.stamp)
        features = None
        if self.config.run.keyframe_on_overlap and self.config.frontend.kf_min_overlap > 0:
            features = self._extract(f.stamp, f.image)
        brk = self.breaks.opens_segment(f.stamp)
        with self.timer("keyframe_selection"):
            made = self.selector.push(f.stamp, T, cov, image=f.image, features=features,
                                      depth=f.depth, right_image=f.right_image, segment_start=brk,
                                      colour=f.colour)
        if not made:
            return []
        # one new keyframe, two on an odometry break (the frame before it is promoted), and one an
        # interrupt kept from the queue (its selector id is not below the count handed in)
        self._unsubmitted += [(k.id, k) for k in made]  # the selector's id (add_keyframe renumbers from the map's)
        out: list[LoopClosure] = []
        while self._unsubmitted:
            if self._unsubmitted[0][0] < self._n_submitted:
                self._unsubmitted.pop(0)
                continue
            out += self.add_keyframe(self._unsubmitted[0][1])
        return out

    # ------------------------------------------------------------------ results
    def flush(self) -> list[LoopClosure]:
        """Process frames still waiting for odometry (uses the last odometry pose) and every waiting keyframe."""
        out = self._release(final=True)
        return out + self._drain(keep=0)

    def finalize(self, *, flush: bool = True):
        """Flush waiting frames and keyframes, then run the back end's final batch re-check (idempotent).

        ``flush=False`` (after a Ctrl-C) leaves waiting frames and keyframes unprocessed.
        """
        if flush:
            self.flush()
        self.close()
        if not self._finalized:
            with self.timer("backend"):
                self.graph.finalize()
            self._finalized = True
        return self

    def odometry_trajectory(self) -> Trajectory:
        return self._odom.trajectory()

    def keyframe_trajectory(self) -> Trajectory:
        """Corrected keyframe poses (current iSAM2 estimate)."""
        return self.graph.keyframe_trajectory()

    def keyframe_odometry(self) -> Trajectory:
        return Trajectory(np.array([k.stamp for k in self.keyframes], np.int64),
                          np.array([k.T_world_body for k in self.keyframes]).reshape(-1, 4, 4))

    def corrected_trajectory(self) -> Trajectory:
        """Every odometry stamp with the loop correction carried from the keyframes."""
        odom = self.odometry_trajectory()
        if len(self.keyframes) == 0:
            return odom
        kf_odom = self.keyframe_odometry()
        kf_corr = self.keyframe_trajectory()
        return correct_full_rate(odom, kf_odom.stamps, kf_odom.poses, kf_corr.poses)

    @property
    def loop_records(self):
        return self.graph.loop_records

    @property
    def candidate_records(self):
        return self.detector.records
