"""``slam-lcd run``: stream a recorded log through the :class:`~slam_lcd.pipeline.Pipeline` and write every output.

Topic choice: explicit flags win; otherwise the log's only ``sensor_msgs/Image`` (or
``CompressedImage``) topic that is not a depth or right-stereo image, its ``CameraInfo``
in the same namespace, the depth image in the same namespace, the only
``nav_msgs/Odometry`` topic, and a ground-truth ``PoseStamped`` topic whose name says so.

Outputs (:data:`RUN_OUTPUTS`, written as one set into ``out_dir``: see
:mod:`slam_lcd.output_set`): config.yaml, odometry.tum, corrected.tum,
keyframes_corrected.tum, loops.csv, graph.g2o, corrected.mcap, report.json, report.md,
trajectory.png, ate_over_time.png; ``PARTIAL.txt`` when the run was interrupted.

Bad input fails before any work, in one line that names the log (and the flag, topic and
stamp): an output that would land on an input, an unwritable target, a topic of the wrong
type, a first message that does not decode. A message that fails to decode later names
its topic and stamp; nothing is written then, and an earlier run's folder is untouched.
"""
from __future__ import annotations

import contextlib
import csv
import io as _io
import json
import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .atomic import write_text
from .config import Config, save_config, validate_config
from .errors import (DamagedImageError, FileMissingError, InputError, MessageEncodingError, PipelineError, SlamLcdError, TopicTypeError,
                     in_context, stamp_text)
from .frontend.camera import camera_mounting
from .interrupts import defer_sigint
from .output_set import PARTIAL_MARKER, OutputSet
from .geometry import interpolate_poses, inv, rotation_angle_deg
from .progress import progress_bar
from .types import Trajectory

log = logging.getLogger(__name__)

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
CAMINFO_TYPE = "sensor_msgs/msg/CameraInfo"
ODOM_TYPES = ("nav_msgs/msg/Odometry",)
POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry")
GT_TYPES = (*POSE_TYPES, "geometry_msgs/msg/TransformStamped")
DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")
# every name `run` may write into --out (the set is published as a whole: slam_lcd.output_set)
RUN_OUTPUTS = ("config.yaml", "odometry.tum", "corrected.tum", "keyframes_corrected.tum", "graph.g2o", "loops.csv",
               "corrected.mcap", "trajectory.png", "ate_over_time.png", "report.json", "report.md")


@dataclass
class Topics:
    image: str
    odom: str | None
    camera_info: str | None = None
    depth: str | None = None
    gt: str | None = None


@dataclass
class RunResult:
    out_dir: Path
    n_frames: int = 0
    n_keyframes: int = 0
    loops_proposed: int = 0
    loops_verified: int = 0
    loops_accepted: int = 0
    loops_rejected_backend: int = 0
    false_loops_accepted: int | None = None
    ate_before: float | None = None
    ate_after: float | None = None
    alignment: str = ""
    interrupted: bool = False
    wall_s: float = 0.0
    log_duration_s: float = 0.0
    stages: dict = field(default_factory=dict)
    outputs: list[str] = field(default_factory=list)
    # per keyframe: loop detection (and its parts) and back end seconds, resident kB (benchmarks)
    keyframe_seconds: list = field(default_factory=list, repr=False)

    def summary_lines(self) -> list[str]:
        lines = [
            f"frames: {self.n_frames}, keyframes: {self.n_keyframes}",
            f"loops: {self.loops_proposed} candidates, {self.loops_verified} verified, "
            f"{self.loops_accepted} accepted by the back end, {self.loops_rejected_backend} rejected by it"
            + (f", {self.false_loops_accepted} false loops accepted" if self.false_loops_accepted is not None else ""),
        ]
        if self.ate_before is not None:
            ratio = self.ate_after / self.ate_before if self.ate_before else float("nan")
            lines.append(f"ATE ({self.alignment}): {self.ate_before:.3f} m -> {self.ate_after:.3f} m ({100 * ratio:.1f}% of odometry)")
        lines.append(f"time: {self.wall_s:.1f} s wall for {self.log_duration_s:.1f} s of log"
                     + (" (interrupted: partial result)" if self.interrupted else ""))
        return lines


# --------------------------------------------------------------------------- topics
def _ns(topic: str) -> str:
    return topic.rsplit("/", 1)[0]


def _check_type(reader, flag: str, topic: str, allowed, what: str) -> None:
    msgtype = reader.topics[topic].msgtype
    if msgtype not in allowed:
        raise TopicTypeError(f"{flag} {topic} carries {msgtype}, not {what} ({' or '.join(allowed)})", reader.path)


def choose_topics(reader, image_topic=None, odom_topic=None, gt_topic=None, depth_topic=None) -> Topics:
    """The topics of a run (see the module docstring); explicit ones are checked against their use."""
    topics = reader.topics
    path = reader.path
    images = [t for t, info in topics.items() if info.msgtype in IMAGE_TYPES]
    if image_topic is not None:
        image_topic = reader.resolve_topics(image_topic)[0]
        _check_type(reader, "--image-topic", image_topic, IMAGE_TYPES, "a camera image")
    else:
        plain = [t for t in images if "depth" not in t.lower() and "right" not in t.lower()]
        if not plain:
            listing = ", ".join(f"{t} ({i.msgtype})" for t, i in sorted(topics.items())) or "(none)"
            raise PipelineError(
                f"no camera image topic (sensor_msgs/Image or CompressedImage) in the log; loop detection needs one "
                f"(pass --image-topic); topics: {listing}", path)
        if len(plain) > 1:
            raise PipelineError(f"several image topics {plain}; choose one with --image-topic", path)
        image_topic = plain[0]
    if odom_topic is not None:
        odom_topic = reader.resolve_topics(odom_topic)[0]
        _check_type(reader, "--odom-topic", odom_topic, POSE_TYPES, "odometry")
    else:
        odoms = [t for t, i in topics.items() if i.msgtype in ODOM_TYPES]
        odom_topic = odoms[0] if len(odoms) == 1 else None
        if len(odoms) > 1:
            raise PipelineError(f"several odometry topics {odoms}; choose one with --odom-topic", path)
    ns = _ns(image_topic)
    infos = [t for t, i in topics.items() if i.msgtype == CAMINFO_TYPE and _ns(t) == ns]
    if depth_topic is not None:
        depth_topic = reader.resolve_topics(depth_topic)[0]
        _check_type(reader, "--depth-topic", depth_topic, IMAGE_TYPES, "a depth image")
    else:
        depths = [t for t in images if "depth" in t.lower() and (_ns(t) == ns or _ns(_ns(t)) == ns)]
        depth_topic = depths[0] if depths else None
    if gt_topic is not None:
        gt_topic = reader.resolve_topics(gt_topic)[0]
        _check_type(reader, "--gt-topic", gt_topic, GT_TYPES, "a pose")
    else:
        gts = [t for t, i in topics.items() if i.msgtype in POSE_TYPES and ("ground_truth" in t or "groundtruth" in t)]
        gt_topic = gts[0] if len(gts) == 1 else None
    return Topics(image_topic, odom_topic, infos[0] if infos else None, depth_topic, gt_topic)


# --------------------------------------------------------------------------- decoding, with where it happened
def _where(m) -> str:
    return f"topic {m.topic}, stamp {stamp_text(m.stamp)}"


@contextlib.contextmanager
def _at_message(m, log_path, decoding: bool = True):
    """Errors inside the block name the log, the topic and the stamp of message ``m``."""
    try:
        yield
    except SlamLcdError as e:
        raise in_context(e, _where(m), log_path) from None
    except (ValueError, TypeError, IndexError, AttributeError, KeyError) as e:
        if not decoding:
            raise
        raise MessageEncodingError(f"{_where(m)}: {m.msgtype} message cannot be decoded "
                                   f"({type(e).__name__}: {' '.join(str(e).split())[:200]})", log_path) from None


def _decode_gray(m) -> np.ndarray:
    from .io.decode import decode_compressed_image, decode_image, image_to_gray

    img = decode_compressed_image(m.msg) if m.msgtype.endswith("CompressedImage") else decode_image(m.msg)
    return image_to_gray(img)


def _decode_depth(m) -> np.ndarray:
    """Depth in metres (float32): 16-bit images are millimetres (ROS convention), 32FC1 metres."""
    from .io.decode import decode_compressed_image, decode_image

    if m.msgtype.endswith("CompressedImage"):
        d = decode_compressed_image(m.msg)
        if d.ndim != 2 or d.dtype not in (np.uint16, np.float32):
            raise MessageEncodingError(f"compressed image ({m.msg.format!r}) is not a depth image "
                                       "(compressedDepth 16UC1 or 32FC1)")
        return d.astype(np.float32) * (1e-3 if d.dtype == np.uint16 else 1.0)
    enc = m.msg.encoding
    if enc not in DEPTH_ENCODINGS:
        raise MessageEncodingError(f"depth image encoding {enc!r} is not a depth encoding "
                                   f"({', '.join(DEPTH_ENCODINGS)}: 16-bit in millimetres, 32FC1 in metres)")
    d = decode_image(m.msg).astype(np.float32)
    return d * 1e-3 if enc in ("16UC1", "mono16") else d


def _check_first_messages(reader, topics: Topics) -> dict:
    """Read and decode the first message of every chosen topic before any work is done."""
    from .io.decode import decode_camera_info

    roles = [("--image-topic", topics.image, _decode_gray), ("--odom-topic", topics.odom, decode_pose_of),
             ("camera info", topics.camera_info, lambda m: decode_camera_info(m.msg)),
             ("--depth-topic", topics.depth, _decode_depth), ("--gt-topic", topics.gt, decode_pose_of)]
    first = {}
    for flag, topic, decode in roles:
        if topic is None or topic in first:
            continue
        m = next(iter(reader.messages([topic])), None)
        if m is None:
            raise PipelineError(f"topic {topic} ({flag}) has no messages", reader.path)
        try:
            with _at_message(m, reader.path):
                decode(m)
        except DamagedImageError:
            pass  # one damaged frame is skipped while streaming (and counted in a warning)
        first[topic] = m
    return first


def decode_pose_of(m):
    from .io.decode import decode_pose

    return decode_pose(m.msg)


def _copyable_topics(reader, cfg, log_path) -> list[str]:
    """Input topics copied into corrected.mcap: all (or all but images), minus types we cannot describe."""
    from .io.writers import describable

    chosen, skipped = [], []
    for t, i in reader.topics.items():
        if not (cfg.run.copy_images or i.msgtype not in IMAGE_TYPES):
            continue
        (chosen if describable(i.msgtype, reader.typestore) else skipped).append(t)
    if skipped:
        kinds = ", ".join(f"{t} ({reader.topics[t].msgtype})" for t in skipped)
        log.warning("%s: topics with message types the log does not define are not copied into corrected.mcap: %s",
                    log_path, kinds)
    return chosen


def run_inputs(log_path, gt_file, cfg, extra=None) -> dict:
    """What the run reads, by the flag that named it (outputs must not land on any of them)."""
    inputs = {"the log": log_path, "--gt": gt_file}
    inputs.update(extra or {})
    if cfg.features.weights:
        inputs["--weights"] = cfg.features.weights
    env = os.environ.get("SLAM_LCD_SUPERPOINT_WEIGHTS")
    if env:
        inputs["$SLAM_LCD_SUPERPOINT_WEIGHTS"] = env
    return inputs


# --------------------------------------------------------------------------- main entry
def run_log(
    log_path: str | Path,
    out_dir: str | Path,
    config: Config | None = None,
    *,
    image_topic: str | None = None,
    odom_topic: str | None = None,
    gt_topic: str | None = None,
    gt_file: str | Path | None = None,
    depth_topic: str | None = None,
    extractor=None,
    vocab=None,
    progress: bool = True,
    write_mcap: bool = True,
    input_paths: dict | None = None,
) -> RunResult:
    """Correct the trajectory of ``log_path`` with loop closures; write outputs into ``out_dir``.

    Before any work: outputs are checked against every input (``input_paths`` adds the
    caller's, e.g. ``{"--config": path}``), the target folder must be writable, the chosen
    topics must have the right types and their first messages must decode. Outputs are
    written as one set (:class:`slam_lcd.output_set.OutputSet`). A Ctrl-C stops the stream
    and writes the result so far, marked partial (``PARTIAL.txt``); ``result.interrupted``.
    ``extractor`` and ``vocab`` (a :class:`slam_lcd.vocab.Vocabulary`; None: the online
    vocabulary) are used as given, so a caller running many logs loads each once.
    """
    from .io import open_log
    from .io.decode import decode_camera_info
    from .io.tf import TfBuffer

    cfg = validate_config(config or Config())
    log_path = Path(log_path)
    out_dir = Path(out_dir)
    if not log_path.exists():
        raise FileMissingError("no such log file or directory", log_path)
    if gt_file is not None and not Path(gt_file).is_file():
        raise FileMissingError("ground-truth trajectory file not found (--gt)", gt_file)
    outputs = OutputSet(out_dir, RUN_OUTPUTS)
    outputs.check(run_inputs(log_path, gt_file, cfg, input_paths))
    t_start = time.perf_counter()
    result = RunResult(out_dir=out_dir)
    gt_traj = _read_gt_file(gt_file) if gt_file is not None else None

    with open_log(log_path, conf=cfg.io) as reader:
        if reader.message_count == 0:
            raise PipelineError("log holds no messages", log_path)
        topics = choose_topics(reader, image_topic, odom_topic, gt_topic, depth_topic)
        first = _check_first_messages(reader, topics)
        mcap_wanted = write_mcap and cfg.run.write_mcap
        copy_topics = _copyable_topics(reader, cfg, log_path) if mcap_wanted else []
        vo_odometry = None
        if topics.odom is None:
            if topics.depth is None:
                raise PipelineError(
                    "log has no odometry topic (nav_msgs/Odometry) and no depth image for the built-in "
                    "visual odometry; pass --odom-topic", log_path)
            vo_odometry = _visual_odometry(log_path, topics, cfg, progress)
        tf = TfBuffer()
        static_topics = [t for t, i in reader.topics.items() if i.msgtype == "tf2_msgs/msg/TFMessage" and "static" in t]
        # static transforms first (tiny): the camera mounting must not depend on message order
        for m in reader.messages(static_topics) if static_topics else ():
            with _at_message(m, log_path):
                tf.add(m.msg, static=True)
        wanted = [t for t in (topics.image, topics.odom, topics.camera_info, topics.depth, topics.gt) if t]
        from .pipeline import Pipeline  # imported late: topic errors need no model

        pipe = Pipeline(cfg, extractor=extractor, vocab=vocab)
        pipe.expect_depth = topics.depth is not None
        if cfg.features.feature_cache:
            from .features import FeatureCache

            cache = FeatureCache(pipe.extractor)
            pipe.feature_source = lambda stamp, img: cache.extract(log_path, topics.image, stamp, img)
        gt_st, gt_T = [], []
        # the body frame is the odometry's child frame (read once, before streaming)
        first_odom = first.get(topics.odom)
        body_frame = (getattr(first_odom.msg, "child_frame_id", None) or None) if first_odom else None
        if vo_odometry is not None:  # built-in VO ran first: its poses are the odometry
            traj = vo_odometry.result.trajectory()
            breaks = vo_odometry.result.segment_starts
            for k in range(len(traj)):
                cov = None if traj.covariances is None else traj.covariances[k]
                pipe.add_odometry(int(traj.stamps[k]), traj.poses[k], cov, segment_start=bool(breaks[k]) and k > 0)
        n_img = reader.topics[topics.image].count
        camera_set = False
        damaged: list[DamagedImageError] = []
        bar = progress_bar(total=n_img, desc="frames", unit="img", enabled=progress)
        try:
            for m in reader.messages(wanted):
                if m.topic == topics.odom:
                    with _at_message(m, log_path):
                        T, cov = decode_pose_of(m)
                    with _at_message(m, log_path, decoding=False):
                        pipe.add_odometry(m.stamp, T, cov)
                elif m.topic == topics.camera_info and not camera_set:
                    with _at_message(m, log_path):
                        cam = decode_camera_info(m.msg)
                        # one camera-mounting rule for the VO pass and this one
                        T_bc = (vo_odometry.T_body_camera if vo_odometry is not None else
                                camera_mounting(cfg.frontend, tf, m.msg.header.frame_id, m.stamp, body_frame=body_frame))
                    pipe.set_camera(cam, T_bc)
                    camera_set = True
                elif m.topic == topics.depth:
                    try:
                        with pipe.timer("decode"), _at_message(m, log_path):
                            d = _decode_depth(m)
                    except DamagedImageError as e:
                        damaged.append(e)
                        continue
                    with _at_message(m, log_path, decoding=False):
                        pipe.add_depth(m.stamp, d)
                elif m.topic == topics.image:
                    try:
                        with pipe.timer("decode"), _at_message(m, log_path):
                            gray = _decode_gray(m)
                    except DamagedImageError as e:  # a damaged frame is skipped, not fatal
                        damaged.append(e)
                        continue
                    with _at_message(m, log_path, decoding=False):
                        pipe.add_image(m.stamp, gray)
                    result.n_frames += 1
                    bar.update(1)
                elif m.topic == topics.gt:
                    with _at_message(m, log_path):
                        T, _ = decode_pose_of(m)
                    gt_st.append(m.stamp)
                    gt_T.append(T)
        except KeyboardInterrupt:
            result.interrupted = True
            log.warning("interrupted: writing the partial result")
        finally:
            bar.close()
        if damaged:
            log.warning("%s: %d damaged image message(s) skipped; the first: %s", log_path, len(damaged),
                        damaged[0].problem)
        result.log_duration_s = reader.duration_ns * 1e-9

    notes: list[str] = []
    read_to_end = not result.interrupted
    try:
        pipe.finalize(flush=not result.interrupted)
    except KeyboardInterrupt:  # Ctrl-C (maybe a second one): skip the back end's final re-check
        log.warning("interrupted%s: the back end's final re-check is skipped", " again" if result.interrupted else "")
        notes.append("The back end's final re-check (GNC) was interrupted and skipped.")
        result.interrupted = True
    if not result.interrupted and not pipe.keyframes:
        raise PipelineError(_no_keyframe_reason(pipe, topics, result.n_frames), log_path)
    if gt_traj is None and gt_st:
        order = np.argsort(np.array(gt_st, np.int64), kind="stable")
        gt_traj = Trajectory(np.array(gt_st, np.int64)[order], np.array(gt_T)[order])
    result.wall_s = time.perf_counter() - t_start
    _write_set(outputs, pipe, result, gt_traj, log_path if mcap_wanted else None, copy_topics, notes, read_to_end)
    return result


def _no_keyframe_reason(pipe, topics: Topics, n_frames: int) -> str:
    odom = pipe.odometry_trajectory()
    span = (f"odometry from {stamp_text(odom.stamps[0])} to {stamp_text(odom.stamps[-1])}" if len(odom)
            else "no odometry sample")
    source = topics.odom or "the visual odometry"
    return (f"no keyframe was made from the {n_frames} frames of {topics.image}: none falls within the odometry "
            f"of {source} ({span}); nothing to correct")


def _partial_text(result: RunResult, notes=(), *, read_to_end: bool, while_writing: bool = False) -> str:
    """What PARTIAL.txt says: why the set is incomplete, and what is missing from it."""
    lines = []
    if not read_to_end:
        lines += [f"This run was interrupted (Ctrl-C) after {result.n_frames} frames: the files here hold the",
                  "result up to that point and agree with each other, but the log was not processed to its end."]
    lines += list(notes)
    if while_writing:
        lines.append(f"This run was interrupted{' again' if lines else ''} while the outputs were written: "
                     "only the files present here were written.")
    return "\n".join(lines)


def _write_set(outputs: OutputSet, pipe, result: RunResult, gt, mcap_source, copy_topics, notes=None,
               read_to_end: bool = True) -> None:
    """Write every output into the staging folder, then publish the set (partial when interrupted)."""
    notes = list(notes or [])
    partial = result.interrupted
    try:
        if partial:  # said first: a second Ctrl-C may stop the writing at any file
            outputs.mark_partial(_partial_text(result, notes, read_to_end=read_to_end))
        write_outputs(pipe, outputs.staging, result, gt, mcap_source, copy_topics,
                      skipped=notes if partial else None)
        if partial:
            outputs.mark_partial(_partial_text(result, notes, read_to_end=read_to_end))
    except KeyboardInterrupt:
        try:
            with defer_sigint():
                result.interrupted = True
                outputs.mark_partial(_partial_text(result, notes, read_to_end=read_to_end, while_writing=True))
                result.outputs = outputs.publish()
        except OSError as e:
            outputs.discard()
            raise _write_error(e, outputs) from None
        log.warning("interrupted while writing the outputs: %s holds a partial set (see %s)",
                    outputs.target, PARTIAL_MARKER)
        return
    except OSError as e:
        outputs.discard()
        raise _write_error(e, outputs) from None
    except BaseException:
        outputs.discard()
        raise
    try:
        outputs.publish()
    except OSError as e:
        outputs.discard()
        raise _write_error(e, outputs) from None


def _write_error(e: OSError, outputs: OutputSet) -> InputError:
    name = Path(e.filename).name if getattr(e, "filename", None) else ""
    target = outputs.target / name if name in outputs.names else outputs.target
    return InputError(f"cannot write the outputs ({e.strerror or e}); nothing was written there", target)


def _visual_odometry(log_path, topics: Topics, cfg, progress: bool):
    """Built-in RGB-D visual odometry over the whole log (a first pass; see slam_lcd.frontend)."""
    from .frontend.log_vo import visual_odometry_from_log

    log.warning("%s: no odometry topic; running the built-in RGB-D visual odometry first", log_path)
    return visual_odometry_from_log(log_path, cfg.frontend, image_topic=topics.image, depth_topic=topics.depth,
                                    camera_info_topic=topics.camera_info)


def _read_gt_file(path) -> Trajectory:
    from .io.trajectory_files import read_trajectory

    return read_trajectory(path)


# --------------------------------------------------------------------------- outputs
def _gt_at_keyframes(gt: Trajectory, kf_stamp: dict[int, int]) -> dict[int, np.ndarray]:
    """Ground-truth pose (interpolated) of every keyframe id, in one pass over the ground truth."""
    ids = list(kf_stamp)
    if not ids:
        return {}
    P = interpolate_poses(gt.stamps, gt.poses, np.array([kf_stamp[i] for i in ids], np.int64))
    return dict(zip(ids, P))


def write_outputs(pipe, out_dir: Path, result: RunResult, gt: Trajectory | None,
                  mcap_source: Path | None, copy_topics: list[str] | None = None,
                  skipped: list[str] | None = None) -> None:
    """Write every output of a run into ``out_dir`` (normally an :class:`OutputSet` staging folder).

    ``skipped`` (a list) means a partial result: outputs that have nothing to hold yet
    (no odometry, no keyframe) are left out and said so in ``skipped`` instead of failing.
    """
    from .eval import ate as compute_ate
    from .io.trajectory_files import write_tum

    cfg = pipe.config
    out_dir.mkdir(parents=True, exist_ok=True)
    save_config(cfg, out_dir / "config.yaml")
    outputs = ["config.yaml"]
    odom = pipe.odometry_trajectory()
    corrected = pipe.corrected_trajectory()
    kf_corr = pipe.keyframe_trajectory() if pipe.keyframes else Trajectory(np.zeros(0, np.int64), np.zeros((0, 4, 4)))
    for name, traj in (("odometry.tum", odom), ("corrected.tum", corrected), ("keyframes_corrected.tum", kf_corr)):
        if len(traj) == 0 and skipped is not None:
            skipped.append(f"{name}: not written (no poses yet)")
            continue
        write_tum(out_dir / name, traj)
        outputs.append(name)
    if pipe.keyframes or skipped is None:
        pipe.graph.write_g2o(out_dir / "graph.g2o")
        outputs.append("graph.g2o")
    else:
        skipped.append("graph.g2o: not written (no keyframe yet)")

    # ---- loops: every candidate, with the back end's verdict joined in
    backend = {(r.query_id, r.match_id): r for r in pipe.loop_records}
    kf_stamp = {k.id: k.stamp for k in pipe.keyframes}
    rows = []
    gt_pose = _gt_at_keyframes(gt, kf_stamp) if gt is not None else {}
    for rec in pipe.candidate_records:
        q, mt = int(rec.query_id), int(rec.match_id)
        b = backend.get((q, mt))
        row = {"query_stamp_ns": kf_stamp.get(q, ""), "match_stamp_ns": kf_stamp.get(mt, "")}
        row.update(rec.row())
        row["verdict"] = "accepted" if rec.accepted else "rejected"
        row["backend_verdict"] = b.verdict if b is not None else ""
        row["backend_reason"] = b.reason if b is not None else ""
        row.update({"gt_distance_m": "", "err_trans_m": "", "err_rot_deg": ""})
        if q in gt_pose and mt in gt_pose:
            T_gt = inv(gt_pose[mt]) @ gt_pose[q]  # ground-truth T_match_query (body frames)
            row["gt_distance_m"] = _fmt(float(np.linalg.norm(T_gt[:3, 3])))
            if rec.pose is not None and rec.pose.ok:
                E = inv(T_gt) @ np.asarray(rec.pose.T_match_query)
                row["err_trans_m"] = _fmt(float(np.linalg.norm(E[:3, 3])))
                row["err_rot_deg"] = _fmt(rotation_angle_deg(E))
        rows.append(row)
    _write_csv(out_dir / "loops.csv", rows, list(rows[0].keys()) if rows else ["query_id", "match_id", "verdict", "reason"])
    outputs.append("loops.csv")

    result.n_keyframes = len(pipe.keyframes)
    result.loops_proposed = len(rows)
    result.loops_verified = sum(1 for r in rows if r["verdict"] == "accepted")
    result.loops_accepted = sum(1 for r in pipe.loop_records if r.verdict == "accepted")
    result.loops_rejected_backend = sum(1 for r in pipe.loop_records if r.verdict != "accepted")
    result.stages = pipe.timer.as_dict()
    result.keyframe_seconds = list(pipe.keyframe_seconds)

    # ---- evaluation against ground truth
    ate_before = ate_after = None
    if gt is not None and len(gt) > 1 and len(odom) > 1:
        ec = cfg.run
        try:
            ate_before = compute_ate(gt, odom, align=ec.align, t_max_diff=ec.t_max_diff)
            ate_after = compute_ate(gt, corrected, align=ec.align, t_max_diff=ec.t_max_diff)
        except SlamLcdError as e:  # the trajectories are still worth having
            ate_before = ate_after = None
            log.warning("ATE against the ground truth not computed: %s", e.problem)
    if ate_before is not None:
        result.ate_before, result.ate_after = ate_before.rmse, ate_after.rmse
        result.alignment = ec.align
        false = 0
        for r in rows:
            if r["backend_verdict"] == "accepted" and r["gt_distance_m"] != "":
                if float(r["gt_distance_m"]) > cfg.run.loop_true_max_distance:
                    false += 1
        result.false_loops_accepted = false

    # ---- corrected MCAP (input topics + corrected trajectory)
    if mcap_source is not None and len(corrected) == 0 and skipped is not None:
        skipped.append("corrected.mcap: not written (no poses yet)")
    elif mcap_source is not None:
        from .io.writers import write_trajectory_log

        write_trajectory_log(out_dir / "corrected.mcap", corrected, "mcap", topic="/slam_lcd/corrected",
                             frame_id="map", child_frame_id="base_link_corrected",
                             copy_from=mcap_source, copy_topics=copy_topics)
        outputs.append("corrected.mcap")

    # ---- plots
    if cfg.run.plots:
        try:
            _plots(out_dir, odom, corrected, gt, pipe, ate_before, ate_after)
            outputs += ["trajectory.png", "ate_over_time.png"] if ate_before is not None else ["trajectory.png"]
        except Exception as e:  # a plot must never cost the user the numbers
            log.warning("plots not written: %s", e)
    outputs += ["report.json", "report.md"]
    result.outputs = outputs
    _write_report(out_dir, result, ate_before, ate_after)


def _fmt(x):
    return "" if x is None else f"{float(x):.6g}"


def _write_csv(path: Path, rows: list[dict], fields: list[str]) -> None:
    buf = _io.StringIO()
    w = csv.DictWriter(buf, fieldnames=fields)
    w.writeheader()
    for r in rows:
        w.writerow(r)
    write_text(path, buf.getvalue())


def _plots(out_dir, odom, corrected, gt, pipe, ate_before, ate_after):
    """Top view (estimates aligned to ground truth as in the ATE) and ATE over time."""
    from .eval.plots import plot_error_over_time, plot_trajectories_top

    kf = pipe.keyframe_trajectory()
    if ate_after is not None:
        odom = ate_before.alignment.apply(odom)
        corrected = ate_after.alignment.apply(corrected)
        kf = ate_after.alignment.apply(kf)
    trajs = [("odometry", odom), ("corrected", corrected)]
    if gt is not None:
        trajs = [("ground truth", gt)] + trajs
    pos = {k.id: kf.poses[i][:3, 3] for i, k in enumerate(pipe.keyframes) if i < len(kf)}
    edges = [(pos[r.query_id], pos[r.match_id]) for r in pipe.loop_records
             if r.verdict == "accepted" and r.query_id in pos and r.match_id in pos]
    align = ate_after.alignment.label if ate_after is not None else "no ground truth"
    plot_trajectories_top(trajs, loop_edges=edges, title=f"trajectories, accepted loops ({align})",
                          out=out_dir / "trajectory.png")
    if ate_before is not None:
        plot_error_over_time([("odometry", ate_before), ("corrected", ate_after)],
                             title=f"ATE over time ({align})", out=out_dir / "ate_over_time.png")


def _write_report(out_dir: Path, result: RunResult, ate_before, ate_after) -> None:
    rep = {
        "frames": result.n_frames, "keyframes": result.n_keyframes,
        "loops": {"candidates": result.loops_proposed, "verified": result.loops_verified,
                  "accepted": result.loops_accepted, "rejected_by_backend": result.loops_rejected_backend,
                  "false_accepted": result.false_loops_accepted},
        "ate": None if ate_before is None else {
            "alignment": result.alignment,
            "before": _ate_dict(ate_before), "after": _ate_dict(ate_after),
            "ratio_after_before": (ate_after.rmse / ate_before.rmse) if ate_before.rmse else None,
        },
        "interrupted": result.interrupted,
        "wall_s": round(result.wall_s, 3), "log_duration_s": round(result.log_duration_s, 3),
        "stages": result.stages, "outputs": result.outputs,
    }
    write_text(out_dir / "report.json", json.dumps(rep, indent=2))
    md = ["# slam-lcd run report", ""] + [f"- {line}" for line in result.summary_lines()]
    md += ["", "## Time per stage", "", "| stage | seconds | calls |", "|---|---|---|"]
    md += [f"| {k} | {v['seconds']:.2f} | {v['calls']} |" for k, v in result.stages.items()]
    md += ["", "## Outputs", ""] + [f"- `{o}`" for o in result.outputs]
    write_text(out_dir / "report.md", "\n".join(md) + "\n")


def _ate_dict(a) -> dict:
    return {k: float(getattr(a, k)) for k in ("rmse", "mean", "median", "max") if hasattr(a, k)} | {"pairs": int(len(a.errors))}
