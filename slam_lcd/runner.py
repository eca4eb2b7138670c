"""``slam-lcd run``: stream a recorded log through the :class:`~slam_lcd.pipeline.Pipeline` and write every output.

Topic choice: explicit flags win; otherwise the log's only ``sensor_msgs/Image`` (or
``CompressedImage``) topic that is not a depth or right-stereo image, its ``CameraInfo``
in the same namespace, the depth image in the same namespace, the only
``nav_msgs/Odometry`` topic, and a ground-truth ``PoseStamped`` topic whose name says so.

Outputs (all written atomically into ``out_dir``): config.yaml, odometry.tum,
corrected.tum, keyframes_corrected.tum, loops.csv, graph.g2o, corrected.mcap,
report.json, report.md, trajectory.png, ate_over_time.png.
"""
from __future__ import annotations

import csv
import io as _io
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .atomic import guard_not_input, write_text
from .config import Config, save_config
from .errors import FileMissingError, PipelineError
from .geometry import interpolate_poses, inv, rotation_angle_deg
from .progress import progress_bar
from .types import Trajectory

log = logging.getLogger(__name__)

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
CAMINFO_TYPE = "sensor_msgs/msg/CameraInfo"
ODOM_TYPES = ("nav_msgs/msg/Odometry",)
POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry")


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


def choose_topics(reader, image_topic=None, odom_topic=None, gt_topic=None, depth_topic=None) -> Topics:
    topics = reader.topics
    path = reader.path
    images = [t for t, info in topics.items() if info.msgtype in IMAGE_TYPES]
    if image_topic is not None:
        image_topic = reader.resolve_topics(image_topic)[0]
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
    else:
        odoms = [t for t, i in topics.items() if i.msgtype in ODOM_TYPES]
        odom_topic = odoms[0] if len(odoms) == 1 else None
        if len(odoms) > 1:
            raise PipelineError(f"several odometry topics {odoms}; choose one with --odom-topic", path)
    ns = _ns(image_topic)
    infos = [t for t, i in topics.items() if i.msgtype == CAMINFO_TYPE and _ns(t) == ns]
    if depth_topic is not None:
        depth_topic = reader.resolve_topics(depth_topic)[0]
    else:
        depths = [t for t in images if "depth" in t.lower() and (_ns(t) == ns or _ns(_ns(t)) == ns)]
        depth_topic = depths[0] if depths else None
    if gt_topic is not None:
        gt_topic = reader.resolve_topics(gt_topic)[0]
    else:
        gts = [t for t, i in topics.items() if i.msgtype in POSE_TYPES and ("ground_truth" in t or "groundtruth" in t)]
        gt_topic = gts[0] if len(gts) == 1 else None
    return Topics(image_topic, odom_topic, infos[0] if infos else None, depth_topic, gt_topic)


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
    progress: bool = True,
    write_mcap: bool = True,
) -> RunResult:
    """Correct the trajectory of ``log_path`` with loop closures; write outputs into ``out_dir``."""
    from .io import open_log
    from .io.decode import decode_camera_info, decode_compressed_image, decode_image, decode_pose, image_to_gray
    from .io.tf import TfBuffer

    cfg = config or Config()
    log_path = Path(log_path)
    out_dir = Path(out_dir)
    if not log_path.exists():
        raise FileMissingError("no such log file or directory", log_path)
    guard_not_input(out_dir, log_path)
    t_start = time.perf_counter()
    result = RunResult(out_dir=out_dir)

    with open_log(log_path, conf=cfg.io) as reader:
        topics = choose_topics(reader, image_topic, odom_topic, gt_topic, depth_topic)
        vo_odometry = None
        if topics.odom is None:
            if topics.depth is None:
                raise PipelineError(
                    "log has no odometry topic (nav_msgs/Odometry) and no depth image for the built-in "
                    "visual odometry; pass --odom-topic", log_path)
            vo_odometry = _visual_odometry(log_path, topics, cfg, progress)
        gt_traj = _read_gt_file(gt_file) if gt_file is not None else None
        tf = TfBuffer()
        static_topics = [t for t, i in reader.topics.items() if i.msgtype == "tf2_msgs/msg/TFMessage" and "static" in t]
        # static transforms first (tiny): the camera mounting must not depend on message order
        for m in reader.messages(static_topics) if static_topics else ():
            tf.add(m.msg, static=True)
        wanted = [t for t in (topics.image, topics.odom, topics.camera_info, topics.depth, topics.gt) if t]
        from .pipeline import Pipeline  # imported late: topic errors need no model

        pipe = Pipeline(cfg, extractor=extractor)
        pipe.expect_depth = topics.depth is not None
        if cfg.features.feature_cache:
            from .features import FeatureCache

            cache = FeatureCache(pipe.extractor)
            pipe.feature_source = lambda stamp, img: cache.extract(log_path, topics.image, stamp, img)
        save_config(cfg, out_dir / "config.yaml")
        gt_st, gt_T = [], []
        # the body frame is the odometry's child frame (read once, before streaming)
        first_odom = next(iter(reader.messages([topics.odom])), None) if topics.odom else None
        body_frame = (getattr(first_odom.msg, "child_frame_id", None) or None) if first_odom else None
        if vo_odometry is not None:  # built-in VO ran first: its poses are the odometry
            traj = vo_odometry.result.trajectory()
            breaks = vo_odometry.result.segment_starts
            for k in range(len(traj)):
                cov = None if traj.covariances is None else traj.covariances[k]
                pipe.add_odometry(int(traj.stamps[k]), traj.poses[k], cov, segment_start=bool(breaks[k]) and k > 0)
        n_img = reader.topics[topics.image].count
        camera_set = False
        bar = progress_bar(total=n_img, desc="frames", unit="img", enabled=progress)
        try:
            for m in reader.messages(wanted):
                if m.topic == topics.odom:
                    T, cov = decode_pose(m.msg)
                    pipe.add_odometry(m.stamp, T, cov)
                elif m.topic == topics.camera_info and not camera_set:
                    cam = decode_camera_info(m.msg)
                    T_bc = _camera_mount(tf, body_frame, m.msg.header.frame_id, m.stamp, cfg)
                    pipe.set_camera(cam, T_bc)
                    camera_set = True
                elif m.topic == topics.depth:
                    with pipe.timer("decode"):
                        d = decode_image(m.msg).astype(np.float32)
                        if m.msg.encoding in ("16UC1", "mono16"):
                            d = d * 1e-3  # millimetres (ROS convention for 16-bit depth)
                    pipe.add_depth(m.stamp, d)
                elif m.topic == topics.image:
                    with pipe.timer("decode"):
                        img = decode_compressed_image(m.msg) if m.msgtype.endswith("CompressedImage") else decode_image(m.msg)
                        gray = image_to_gray(img)
                    pipe.add_image(m.stamp, gray)
                    result.n_frames += 1
                    bar.update(1)
                elif m.topic == topics.gt:
                    T, _ = decode_pose(m.msg)
                    gt_st.append(m.stamp)
                    gt_T.append(T)
        except KeyboardInterrupt:
            result.interrupted = True
            log.warning("interrupted: writing the partial result")
        finally:
            bar.close()
        result.log_duration_s = reader.duration_ns * 1e-9
        # input topics copied into corrected.mcap: all of them, or all but images (large)
        copy_topics = [t for t, i in reader.topics.items() if cfg.run.copy_images or i.msgtype not in IMAGE_TYPES]

    pipe.finalize()
    if gt_traj is None and gt_st:
        gt_traj = Trajectory(np.array(gt_st, np.int64), np.array(gt_T))
    result.wall_s = time.perf_counter() - t_start
    write_outputs(pipe, out_dir, result, gt_traj, log_path if (write_mcap and cfg.run.write_mcap) else None,
                  copy_topics)
    return result


def _visual_odometry(log_path, topics: Topics, cfg, progress: bool):
    """Built-in RGB-D visual odometry over the whole log (a first pass; see slam_lcd.frontend)."""
    from .frontend.log_vo import visual_odometry_from_log

    log.warning("%s: no odometry topic; running the built-in RGB-D visual odometry first", log_path)
    return visual_odometry_from_log(log_path, cfg.frontend, image_topic=topics.image, depth_topic=topics.depth,
                                    camera_info_topic=topics.camera_info)


def _camera_mount(tf, body_frame, camera_frame, stamp, cfg) -> np.ndarray | None:
    fc = cfg.frontend
    if fc.T_body_camera is not None:
        from .frontend.camera import parse_T_body_camera

        return parse_T_body_camera(fc.T_body_camera)
    body = body_frame or fc.body_frame
    cam = fc.camera_frame or camera_frame
    try:
        return tf.lookup(body, cam, stamp)
    except Exception:  # no mounting published: camera at the body origin
        log.warning("no transform %s -> %s in /tf_static; assuming the camera is at the body origin", body, cam)
        return None


def _read_gt_file(path) -> Trajectory:
    from .io.trajectory_files import read_trajectory

    return read_trajectory(path)


# --------------------------------------------------------------------------- outputs
def _gt_relative(gt: Trajectory, s_q: int, s_m: int):
    """Ground-truth T_match_query (body frames) at the two keyframe stamps (GT interpolated)."""
    P = interpolate_poses(gt.stamps, gt.poses, np.array([s_q, s_m]))
    return inv(P[1]) @ P[0]


def write_outputs(pipe, out_dir: Path, result: RunResult, gt: Trajectory | None,
                  mcap_source: Path | None, copy_topics: list[str] | None = None) -> None:
    from .eval import ate as compute_ate
    from .io.trajectory_files import write_tum

    cfg = pipe.config
    out_dir.mkdir(parents=True, exist_ok=True)
    odom = pipe.odometry_trajectory()
    corrected = pipe.corrected_trajectory()
    kf_corr = pipe.keyframe_trajectory()
    write_tum(out_dir / "odometry.tum", odom)
    write_tum(out_dir / "corrected.tum", corrected)
    write_tum(out_dir / "keyframes_corrected.tum", kf_corr)
    pipe.graph.write_g2o(out_dir / "graph.g2o")
    outputs = ["config.yaml", "odometry.tum", "corrected.tum", "keyframes_corrected.tum", "graph.g2o"]

    # ---- loops: every candidate, with the back end's verdict joined in
    backend = {(r.query_id, r.match_id): r for r in pipe.loop_records}
    kf_stamp = {k.id: k.stamp for k in pipe.keyframes}
    rows = []
    for rec in pipe.candidate_records:
        q, mt = int(rec.query_id), int(rec.match_id)
        b = backend.get((q, mt))
        row = {"query_stamp_ns": kf_stamp.get(q, ""), "match_stamp_ns": kf_stamp.get(mt, "")}
        row.update(rec.row())
        row["verdict"] = "accepted" if rec.accepted else "rejected"
        row["backend_verdict"] = b.verdict if b is not None else ""
        row["backend_reason"] = b.reason if b is not None else ""
        row.update({"gt_distance_m": "", "err_trans_m": "", "err_rot_deg": ""})
        if gt is not None and q in kf_stamp and mt in kf_stamp:
            T_gt = _gt_relative(gt, kf_stamp[q], kf_stamp[mt])
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

    # ---- evaluation against ground truth
    ate_before = ate_after = None
    if gt is not None and len(gt) > 1:
        ec = cfg.run
        ate_before = compute_ate(gt, odom, align=ec.align, t_max_diff=ec.t_max_diff)
        ate_after = compute_ate(gt, corrected, align=ec.align, t_max_diff=ec.t_max_diff)
        result.ate_before, result.ate_after = ate_before.rmse, ate_after.rmse
        result.alignment = ec.align
        false = 0
        for r in rows:
            if r["backend_verdict"] == "accepted" and r["gt_distance_m"] != "":
                if float(r["gt_distance_m"]) > cfg.run.loop_true_max_distance:
                    false += 1
        result.false_loops_accepted = false

    # ---- corrected MCAP (input topics + corrected trajectory)
    if mcap_source is not None:
        from .io.writers import write_trajectory_log

        write_trajectory_log(out_dir / "corrected.mcap", corrected, "mcap", topic="/slam_lcd/corrected",
                             frame_id="map", child_frame_id="base_link_corrected",
                             copy_from=mcap_source, copy_topics=copy_topics)
        outputs.append("corrected.mcap")

    # ---- plots
    if cfg.run.plots:
        try:
            _plots(out_dir, odom, corrected, gt, pipe, ate_before, ate_after)
            outputs += ["trajectory.png", "ate_over_time.png"] if gt is not None else ["trajectory.png"]
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
