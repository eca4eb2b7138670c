"""``slam-lcd run``: choose the sources of a log, drive them into the :class:`~slam_lcd.run.pipeline.Pipeline`,
write the outputs.

Sources (:mod:`slam_lcd.sensors`): the topics (explicit flags win, else the log's only
camera image, its CameraInfo and depth, the only ``nav_msgs/Odometry``, a ground-truth
pose topic whose name says so), their decoding, the camera mounting and, for a log without
odometry, the built-in visual odometry as the odometry source (chosen in :mod:`slam_lcd.run.sources`). Outputs
(:mod:`slam_lcd.outputs`): :data:`RUN_OUTPUTS`, written as one set into ``out_dir``.

Bad input fails before any work, in one line that names the log (and the flag, topic and
stamp): an output that would land on an input, an unwritable target, a topic of the wrong
type, a first message that does not decode. A message that fails to decode later names
its topic and stamp; nothing is written then, and an earlier run's folder is untouched.
"""
from __future__ import annotations

import logging
import time
from collections import deque
from pathlib import Path

from ..config import Config, validate_config
from ..errors import DamagedImageError, PipelineError
from ..io import open_log
from ..io.prefetch import prefetched
from ..io.raw_spool import RawSpool
from ..io.trajectory_files import read_trajectory
from ..map.session_graph import BUILTIN_VO
from ..map.summary import localisation_report, map_summary
from ..outputs.corrected_log import copied_topics
from ..outputs.loop_pictures import KeyframeAlbum
from ..outputs.result import RunResult
from ..outputs.write import write_set
from ..runtime.interrupts import interrupted_word, signal_name
from ..runtime.progress import progress_bar
from ..sensors.ground_truth import POSITION_ONLY_NOTE, decode_ground_truth, ground_truth_from_messages
from ..sensors.messages import (
    at_message,
    check_first_messages,
    check_image_sizes,
    decode_any_image,
    decode_camera_of,
    decode_depth,
    decode_gray,
    decode_pose_of,
)
from ..sensors.mounting import body_frame_of, mounting_from_camera_info, static_transforms
from ..sensors.topics import Topics, choose_topics, configured_topics, copyable_topics
from ..types import Trajectory
from ..vision.gray import image_to_gray
from .checks import check_run_paths, run_inputs
from .options import MapUse, Models, OutputOptions, Sources
from .sources import (
    calibrated_camera,
    calibration_of,
    cloud_sensor,
    ground_truth_tf,
    log_frame_ids,
    make_pipeline,
    map_cloud_builder,
    no_keyframe_reason,
    odometry_and_stereo,
    set_calibrated_camera,
)

log = logging.getLogger(__name__)

__all__ = ["MapUse", "Models", "OutputOptions", "RunResult", "Sources", "run_inputs", "run_log"]


# --------------------------------------------------------------------------- main entry
def run_log(
    log_path: str | Path,
    out_dir: str | Path,
    config: Config | None = None,
    *,
    sources: Sources | None = None,
    models: Models | None = None,
    map_use: MapUse | None = None,
    output: OutputOptions | None = None,
) -> RunResult:
    """Correct the trajectory of ``log_path`` with loop closures; write outputs into ``out_dir``.

    Before any work: outputs are checked against every input (``output.input_paths`` adds the
    caller's), the target folder must be writable, the chosen topics must have the right types
    and their first messages must decode. Outputs are written as one set
    (:class:`slam_lcd.outputs.output_set.OutputSet`). A Ctrl-C stops the stream and writes the
    result so far, marked partial (``PARTIAL.txt``); ``result.interrupted``. A log without
    odometry gets the built-in visual odometry: RGB-D on its depth topic, else stereo on
    ``sources.right_topic`` (default: the second camera found by
    :func:`slam_lcd.sensors.topics.choose_right_topic`). Each group of inputs has the defaults
    of a plain ``slam-lcd run`` (:mod:`slam_lcd.run.options`): ``sources`` (topics, ground-truth
    file, calibration), ``models`` (extractor, vocabulary, used as given), ``map_use`` (append
    to a map, or localise against it) and ``output`` (progress, corrected.mcap, what is reported).
    """
    sources = sources if sources is not None else Sources()
    models = models if models is not None else Models()
    output = output if output is not None else OutputOptions()
    session_map = map_use.session_map if map_use is not None else None
    map_mode = map_use.mode if map_use is not None else "append"
    gt_file, live = sources.gt_file, output.live
    cfg = validate_config(config or Config())
    log_path = Path(log_path)
    out_dir = Path(out_dir)
    calibration = calibration_of(sources.calib)
    extra_inputs = dict(output.input_paths)
    if calibration is not None:
        extra_inputs.update({f"--calib {i}": p for i, p in enumerate(calibration.sources)})
    outputs = check_run_paths(log_path, out_dir, cfg, gt_file, extra_inputs,
                              map_dir=session_map.root if session_map is not None else None,
                              appended=map_mode == "append")
    t_start = time.perf_counter()
    result = RunResult(out_dir=out_dir, log_path=str(log_path), command_line=output.command_line,
                       overrides=list(output.overrides))
    gt_traj = read_trajectory(gt_file) if gt_file is not None else None

    album = spool = map_cloud = None
    try:  # the staging folder may exist from here on (the loop pictures' keyframe album, the copy spool)
        with open_log(log_path, conf=cfg.io) as reader:
            if reader.message_count == 0:
                raise PipelineError("log holds no messages", log_path)
            flags = configured_topics(reader, cfg.sensors, sources.image_topic, sources.odom_topic, sources.gt_topic,
                                      sources.depth_topic, sources.right_topic)
            right_topic = flags.pop("right_topic")
            topics = choose_topics(reader, **flags)
            if session_map is not None and map_mode == "append":
                session_map.refuse_held(log_path, topics.image)  # not run again (Map.session_of_log)
            calibrated = calibrated_camera(calibration, topics, log_path)
            first = check_first_messages(reader, topics)
            check_image_sizes(reader, topics, first, calibrated, calibration)
            result.topics = {k: v for k, v in vars(topics).items() if v}
            result.frames = log_frame_ids(first, topics)
            result.gt_source = (f"file {gt_file}" if gt_file is not None else
                                f"topic {topics.gt}" if topics.gt else None)
            gt_from_tf = ground_truth_tf(reader, topics)
            if topics.gt_position_only:
                result.alignment = f"{cfg.eval.align}; {POSITION_ONLY_NOTE}"
                log.warning("%s: %s", log_path, POSITION_ONLY_NOTE)
            mcap_wanted = output.write_mcap and cfg.run.write_mcap
            copy_topics = copyable_topics(reader, cfg.run.copy_images, log_path) if mcap_wanted else []
            vo_odometry, stereo, right = odometry_and_stereo(reader, topics, right_topic, cfg, calibration,
                                                             calibrated, log_path)
            if right is not None:
                result.topics["right"] = right
            tf = static_transforms(reader, log_path)
            if cfg.run.loop_pictures:  # a working folder inside the staging folder: discarded with it on failure
                album = KeyframeAlbum(outputs.staging / ".loop_keyframes", cfg.lcd.descriptor_dtype)
            if copy_topics:  # the topics corrected.mcap copies, kept undecoded from the one pass over the log
                spool = RawSpool(outputs.staging / ".corrected_mcap_spool", copied_topics(copy_topics))
            map_cloud = map_cloud_builder(cfg, topics, stereo, outputs, result, log_path)
            pipe = make_pipeline(cfg, models, log_path, topics, album if live is None else live.sink(album),
                                 rectified=stereo is not None and stereo.rectifier is not None, map_use=map_use,
                                 map_cloud=map_cloud)
            result.features = {"kind": getattr(pipe.extractor, "kind", None),
                               "precision": getattr(pipe.extractor, "precision", None),
                               "precision_setting": cfg.features.precision}
            if calibrated is not None:  # the calibration file's camera (CameraInfo is not read then)
                set_calibrated_camera(pipe, cfg, calibrated, vo_odometry, stereo, tf,
                                      body_frame_of(first.get(topics.odom)))
            if vo_odometry is not None:  # built-in VO ran first: its poses are the odometry
                for stamp, T, cov, segment_start in vo_odometry.odometry_samples():
                    pipe.add_odometry(stamp, T, cov, segment_start=segment_start)
            if cfg.run.plots:
                _import_in_background("slam_lcd.eval.plots")
            gt_traj_from_log = _drive(reader, topics, pipe, result, cfg, tf, body_frame_of(first.get(topics.odom)),
                                      vo_odometry, log_path, output.progress, stereo, spool)
            result.log_duration_s = reader.duration_ns * 1e-9
            if map_cloud is not None:
                result.map_cloud_sensor = cloud_sensor(pipe, topics, stereo, calibration)
            if gt_from_tf is not None:
                gt_traj_from_log = gt_from_tf

        notes: list[str] = []
        read_to_end = not result.interrupted
        try:
            pipe.finalize(flush=not result.interrupted)
        except KeyboardInterrupt:  # Ctrl-C (maybe a second one): skip the back end's final re-check
            log.warning("%s%s: the back end's final re-check is skipped", interrupted_word(),
                        " again" if result.interrupted else "")

            notes.append(f"The back end's final re-check (GNC) was interrupted ({signal_name()}) and skipped.")
            result.interrupted = True
        if not result.interrupted and not pipe.keyframes:
            raise PipelineError(no_keyframe_reason(pipe, topics, result.n_frames, vo_odometry), log_path)
        if gt_traj is None:
            gt_traj = gt_traj_from_log
        if gt_traj is None:
            result.gt_source = None  # a ground-truth topic without a message
        result.ground_truth = gt_traj
        if session_map is not None and map_mode == "localize":
            result.localization = localisation_report(session_map, session_map.localise(pipe), gt_traj)
        elif map_use is not None and session_map is not None:
            result.map = _append_to_map(map_use, pipe, result, log_path, gt_traj, notes)
        result.wall_s = time.perf_counter() - t_start
    except BaseException:
        if spool is not None:
            spool.discard()
        if map_cloud is not None:  # its anonymous file lives in the staging folder: closed before that goes
            map_cloud.close()
        outputs.discard()  # a run that fails before its outputs leaves no staging folder behind
        raise
    try:
        write_set(outputs, pipe, result, gt_traj, log_path if mcap_wanted else None, copy_topics, notes, read_to_end,
                  album=album, spool=spool, surfaces=output.surfaces)
    finally:  # also when writing failed (a full disk) before the map cloud was written
        if map_cloud is not None:
            map_cloud.close()
    return result


def _import_in_background(module: str) -> None:
    """Import ``module`` in a daemon thread while the log streams (matplotlib: ~0.4 s of one core).

    Why: the plots are drawn after the stream, when the outputs are the whole run's critical path;
    during the stream the import takes its share of the busy cores instead. A failure here is
    silent: the plots import the module again where they need it, and say what went wrong."""
    import importlib
    import threading

    def load():
        try:
            importlib.import_module(module)
        except Exception:  # reported by the import at output time
            pass

    threading.Thread(target=load, name="slam-lcd-import", daemon=True).start()


_READ_AHEAD_AFTER = 10  # judged over the last this many keyframes whose features loop detection waited for
_READ_AHEAD_MAX_WAIT = 0.1  # the share of their time spent waiting for features below which reading ahead pays


class _ReadAheadJudge:
    """Whether the log should now be read in a thread of its own (``run.read_ahead``).

    Why judged while the log streams: reading ahead pays when the main thread (reading, loop
    detection, back end) is what the run waits for: features cached, a GPU, many cores. When
    the extraction is (SuperPoint on two CPU cores: loop detection waits ~half the time for
    features) a fourth busy thread costs more hand-overs and memory than it overlaps (the
    2-lap demo: wall x1.007-1.02, +100 MB). The share is that of the last
    :data:`_READ_AHEAD_AFTER` keyframes, so a slow first forward (a GPU's start-up) does not
    weigh on it for the rest of the run. Without background extraction (``run.extract_ahead =
    0``) nothing is waited for and the log is read inline, as before."""

    def __init__(self, pipe):
        self.timer = pipe.timer
        self.seen = 0
        self.marks: deque = deque(maxlen=_READ_AHEAD_AFTER + 1)  # (time, seconds waited so far)

    def pays(self) -> bool:
        n = self.timer.calls.get("features_wait", 0)
        if n == self.seen:
            return False
        self.seen = n
        self.marks.append((time.perf_counter(), self.timer.seconds["features_wait"]))
        if len(self.marks) <= _READ_AHEAD_AFTER:  # not yet the last _READ_AHEAD_AFTER keyframes' span
            return False
        (t0, w0), (t1, w1) = self.marks[0], self.marks[-1]
        return w1 - w0 < _READ_AHEAD_MAX_WAIT * (t1 - t0)


def _append_to_map(map_use: MapUse, pipe, result: RunResult, log_path: Path, gt, notes: list[str]) -> dict:
    """Add the finished session to the map and commit it; an interrupted run adds nothing (said in the notes)."""
    m = map_use.session_map
    if result.interrupted:
        notes.append(f"The map {m.root} was left as it was: an interrupted session is not added to a map.")
        log.warning("interrupted: %s was not changed", m.root)
        return {"root": str(m.root), "appended": False, "reason": "interrupted"}
    joined = m.add_session(pipe, name=map_use.session_name or log_path.stem, log_path=log_path, ground_truth=gt,
                           extra={"image_topic": result.topics.get("image"),
                                  "odometry_source": result.topics.get("odom") or BUILTIN_VO})
    m.save()
    return map_summary(m, joined, current=m.session_names[-1], pipe=pipe)


def _drive(reader, topics: Topics, pipe, result: RunResult, cfg, tf, body_frame, vo_odometry, log_path,
           progress: bool, stereo=None, spool=None) -> Trajectory | None:
    """Stream the chosen topics into ``pipe`` in log order; returns the ground truth read on the way.

    A Ctrl-C stops the stream (``result.interrupted``); a damaged image is skipped and counted.
    ``stereo`` (a :class:`~slam_lcd.sensors.stereo_pairs.StereoFrames`): each left image waits for
    its right one and goes in with it (the loop detector's stereo points, for keyframes only).
    ``spool`` (a :class:`~slam_lcd.io.raw_spool.RawSpool`): the same pass keeps the topics
    ``corrected.mcap`` copies, undecoded; it is complete only when the log was read to its end.
    """
    gt_st, gt_T = [], []
    camera_set = False
    damaged: list[DamagedImageError] = []
    bar = progress_bar(total=reader.topics[topics.image].count, desc="frames", unit="img", enabled=progress)
    raw = dict(raw_topics=spool.wanted, raw_sink=spool.add) if spool is not None and spool.wanted else {}
    read_all = False
    # read inline until reading ahead pays (see _ReadAheadJudge)
    stream = prefetched(reader.messages(topics.wanted(), **raw), depth=max(1, cfg.run.read_ahead), threaded=False)
    judge = _ReadAheadJudge(pipe) if cfg.run.read_ahead > 0 else None
    try:
        for m in stream:
            if judge is not None and not stream.threaded and judge.pays():
                stream.start()
            if m.topic == topics.odom:
                with at_message(m, log_path):
                    T, cov = decode_pose_of(m)
                with at_message(m, log_path, decoding=False):
                    pipe.add_odometry(m.stamp, T, cov)
            elif m.topic == topics.camera_info and not camera_set:
                with at_message(m, log_path):
                    cam = decode_camera_of(m)
                    # one camera-mounting rule for the VO pass and this one
                    T_bc = (vo_odometry.T_body_camera if vo_odometry is not None else
                            mounting_from_camera_info(cfg.frontend, tf, m, body_frame))
                if stereo is not None and not cam.baseline:  # a rectified CameraInfo pair: the right one's baseline
                    cam.baseline = stereo.baseline
                pipe.set_camera(cam, T_bc)
                camera_set = True
            elif m.topic == topics.depth:
                try:
                    with pipe.timer("decode"), at_message(m, log_path):
                        d = decode_depth(m, cfg.sensors.depth_unit_m)
                except DamagedImageError as e:
                    damaged.append(e)
                    continue
                with at_message(m, log_path, decoding=False):
                    pipe.add_depth(m.stamp, d)
            elif m.topic == topics.image:
                try:
                    with pipe.timer("decode"), at_message(m, log_path):
                        img = decode_any_image(m)
                        gray = image_to_gray(img)  # decode_gray's, so the features are those of a grey decode
                except DamagedImageError as e:  # a damaged frame is skipped, not fatal
                    damaged.append(e)
                    continue
                # the colour image goes to the map cloud only (keyframes keep it until it took their points)
                colour = img if img.ndim == 3 and pipe.map_cloud is not None else None
                with at_message(m, log_path, decoding=False):
                    if stereo is None:
                        pipe.add_image(m.stamp, gray, colour=colour)
                    else:
                        for stamp, left, right in stereo.add_left(m.stamp, gray):
                            pipe.add_image(stamp, left, right_image=right)
                result.n_frames += 1
                bar.update(1)
            elif stereo is not None and m.topic == topics.right:
                try:
                    with pipe.timer("decode"), at_message(m, log_path):
                        right_gray = decode_gray(m)
                except DamagedImageError as e:
                    damaged.append(e)
                    continue
                with at_message(m, log_path, decoding=False):
                    for stamp, left, right in stereo.add_right(m.stamp, right_gray):
                        pipe.add_image(stamp, left, right_image=right)
            elif m.topic == topics.gt:
                with at_message(m, log_path):
                    T = decode_ground_truth(m)
                gt_st.append(m.stamp)
                gt_T.append(T)
        read_all = True
        if stereo is not None:
            for stamp, left, right in stereo.flush():
                pipe.add_image(stamp, left, right_image=right)
    except KeyboardInterrupt:
        result.interrupted = True
        log.warning("%s: writing the partial result", interrupted_word())
    finally:
        stream.close()  # the reading stops before the spool is finished
        bar.close()
        if spool is not None:
            spool.finish(complete=read_all)
    if stereo is not None and stereo.unpaired:
        log.warning("%s: %d image(s) of %s had no %s partner within %.0f ms: no stereo points for them", log_path,
                    stereo.unpaired, topics.image, topics.right, stereo.tolerance_ns * 1e-6)
    if damaged:
        log.warning("%s: %d damaged image message(s) skipped; the first: %s", log_path, len(damaged),
                    damaged[0].problem)
    if topics.gt is None:  # no ground-truth topic streamed: nothing was read on the way
        return None
    return ground_truth_from_messages(gt_st, gt_T, log_path, topics.gt)
