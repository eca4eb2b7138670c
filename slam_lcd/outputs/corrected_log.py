"""``corrected.mcap``: the input's topics with the corrected trajectory, ready for Foxglove.

Why this shape: a viewer overlays what shares one TF tree. A SLAM node puts its correction
on ``/tf`` as ``map -> odom`` (REP 105), so the body frame seen from ``map`` is the
corrected pose and seen from ``odom`` the odometry's; we do the same, with the frame names
of the log (fixed frame = the odometry's ``frame_id``, body = its ``child_frame_id``;
``run.mcap_*_frame`` overrides them). What is written (:func:`write_corrected_log`):

- ``/tf``: ``map -> odom`` (corrected ∘ odometry⁻¹) at every corrected stamp, and
  ``odom -> body`` from the odometry when the log's own ``/tf`` does not carry it;
- when the log already gives the odometry frame a parent (e.g. a static ``world -> odom``),
  ``map -> odom`` would give it two: the corrected body is then its own frame
  ``<body>_corrected``, a child of ``odom`` (said in the log at INFO level);
- a ground-truth frame that the tree does not reach (the ground-truth topic's
  ``frame_id``; ``ground_truth`` for a ``--gt`` file, whose poses are then written on
  ``/slam_lcd/ground_truth``) is tied to the tree on ``/tf_static`` by the ATE's alignment
  of the corrected trajectory (rotation and translation; a Sim(3) scale cannot be a
  transform): as the parent of ``map``, or, when the odometry frame has a parent already,
  as a child of it;
- ``/slam_lcd/corrected`` (PoseStamped per stamp), ``/slam_lcd/corrected/path``
  (nav_msgs/Path of the corrected keyframes, growing: once per keyframe, at most
  :data:`MAX_PATH_MESSAGES` messages so a long log does not grow quadratically) and
  ``/slam_lcd/loops`` (visualization_msgs/MarkerArray, one LINE_LIST marker per accepted
  loop, at the loop's query stamp, between the corrected keyframe positions);
- the map's point cloud (``map.ply``: :mod:`slam_lcd.cloud`) as one ``sensor_msgs/PointCloud2`` on
  ``map_cloud.mcap_topic`` (``/slam_lcd/map_cloud``) in the corrected trajectory's frame, at the
  first corrected stamp, so a viewer shows the whole map under the trajectory from the start.

Poses are the final estimate (the whole log's optimum), shown as time goes on.

A run that appends to a map (``run --map``) writes the log in the map's frame and adds every
session of the map (:class:`SessionLayer`), so that one TF tree holds them all:

- the corrected trajectory is this session's in the map frame (the map's joint solution at
  every stamp), so ``map -> odom`` places the log among the earlier sessions;
- every session has a frame ``session_<name>``, a child of ``map`` on ``/tf_static``: the
  identity for sessions joined to this one (their keyframes are in the map frame already); a
  session of another component was never tied to this one, its frame is put at the map's
  origin and the log says so (INFO) -- toggle it in the viewer, do not read its position;
- ``/slam_lcd/map/<name>/path`` (nav_msgs/Path of each session's keyframes, in its frame) and
  ``/slam_lcd/map/loops`` (one LINE_LIST of the accepted loops between sessions, in ``map``),
  each once, at the log's first stamp;
- the ground-truth link uses the map's alignment (one SE(3) of the whole component).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InvalidPoseError
from ..geometry import interpolate_poses, inv
from ..io.reader import open_log
from ..types import Trajectory

log = logging.getLogger(__name__)

TF_TYPE = "tf2_msgs/msg/TFMessage"
MAX_PATH_MESSAGES = 200
POSE_TOPIC = "/slam_lcd/corrected"
PATH_TOPIC = "/slam_lcd/corrected/path"
LOOPS_TOPIC = "/slam_lcd/loops"
GT_TOPIC = "/slam_lcd/ground_truth"  # ground truth given as a file (--gt), in frame GT_FILE_FRAME
GT_FILE_FRAME = "ground_truth"
CLOUD_TOPIC = "/slam_lcd/map_cloud"
MAP_TOPIC_PREFIX = "/slam_lcd/map"
SESSION_FRAME_PREFIX = "session_"


@dataclass
class SessionLayer:
    """A map's sessions as corrected.mcap draws them (arrays only; built by the map outputs).

    ``names``: file-safe session names; ``paths``: each session's keyframes in its component's
    frame; ``joined``: in this log's component; ``loops``: ``(p_match, p_query)`` map-frame
    positions of the accepted loops between sessions of this log's component.
    """

    names: list[str]
    paths: list[Trajectory]
    joined: list[bool]
    loops: list[tuple[np.ndarray, np.ndarray]]


@dataclass
class TfPlan:
    """Which frames the corrected log uses and which transforms it adds (see the module docstring)."""

    map_frame: str
    odom_frame: str
    body_frame: str
    corrected_frame: str  # where the corrected poses, Path and loop markers live
    corrected_body: str  # the frame whose pose (seen from map_frame) is the corrected one
    publish_map_odom: bool
    publish_odom_body: bool
    gt_frame: str | None = None
    link_gt: bool = False
    notes: list[str] = field(default_factory=list)


def copied_topics(copy_topics) -> list[str]:
    """The input topics copied as they are (the file's own topics are written anew)."""
    return [t for t in copy_topics if t not in (POSE_TOPIC, PATH_TOPIC, LOOPS_TOPIC, GT_TOPIC, CLOUD_TOPIC)
            and not t.startswith(MAP_TOPIC_PREFIX + "/")]


def log_tf_parents(reader, topics, spooled=None) -> dict[str, str]:
    """``{child: parent}`` of every transform on the (copied) TF topics of the log (or of ``spooled``, its
    undecoded messages kept by the run: see :mod:`slam_lcd.io.raw_spool`)."""
    tf_topics = [t for t in topics if reader.topics[t].msgtype == TF_TYPE]
    if spooled is not None:
        wanted = set(tf_topics)
        msgs = (reader.deserialise(r) for r in spooled if r.topic in wanted) if wanted else ()
    else:
        msgs = (m.msg for m in reader.messages(tf_topics)) if tf_topics else ()
    parents: dict[str, str] = {}
    for msg in msgs:
        for ts in msg.transforms:
            parents.setdefault(ts.child_frame_id.lstrip("/"), ts.header.frame_id.lstrip("/"))
    return parents


def _root(frame: str, parents: dict[str, str]) -> str:
    seen = set()
    while frame in parents and frame not in seen:
        seen.add(frame)
        frame = parents[frame]
    return frame


def plan_frames(run_conf, log_frame_ids: dict, parents: dict[str, str]) -> TfPlan:
    """The frames and added transforms for a log whose TF tree is ``parents``."""
    odom = run_conf.mcap_odom_frame or log_frame_ids.get("odom") or "odom"
    body = run_conf.mcap_body_frame or log_frame_ids.get("body") or "base_link"
    known = set(parents) | set(parents.values()) | {odom, body}
    notes = []
    map_frame = run_conf.mcap_map_frame
    if map_frame in known:
        new = f"{map_frame}_slam_lcd"
        notes.append(f"frame {map_frame!r} is already a frame of the log; the corrected map frame is {new!r}")
        map_frame = new
    if odom in parents:  # the log gives odom a parent: it cannot get map as a second one
        corrected_body = f"{body}_corrected"
        notes.append(f"the log gives {odom!r} the parent {parents[odom]!r}, so the correction cannot be "
                     f"{map_frame} -> {odom}; the corrected body is {corrected_body!r}, a child of {odom!r}")
        plan = TfPlan(map_frame, odom, body, odom, corrected_body, False, body not in parents)
    else:
        plan = TfPlan(map_frame, odom, body, map_frame, body, True, body not in parents)
    gt = log_frame_ids.get("gt")
    if gt:
        plan.gt_frame = gt
        tree = dict(parents)
        if plan.publish_map_odom:
            tree[odom] = map_frame
        if plan.publish_odom_body:
            tree[body] = odom
        if not plan.publish_map_odom:
            tree[corrected_body] = odom
        apart = _root(gt, tree) != _root(plan.corrected_frame, tree)
        # map (new, parentless) becomes the ground truth's child; else the ground truth, if it
        # has no parent, becomes a child of the corrected trajectory's frame
        plan.link_gt = apart and (plan.publish_map_odom or gt not in tree)
        if apart and not plan.link_gt:
            notes.append(f"ground-truth frame {gt!r} is not connected to the corrected trajectory's tree")
    plan.notes = notes
    return plan


def _keyframe_paths(kf: Trajectory, frame: str):
    """(stamp, Path) once per keyframe (at most MAX_PATH_MESSAGES), each with the keyframes so far."""
    from ..io import message_builders as M  # lazy: rosbags (the runner imports this module)

    n = len(kf)
    if n == 0:
        return []
    ends = np.unique(np.round(np.linspace(1, n, min(n, MAX_PATH_MESSAGES))).astype(int))
    return [(int(kf.stamps[e - 1]), msg) for e, msg in zip(ends, M.growing_path_msgs(kf, ends, frame), strict=True)]


def _add_sessions(add, layer: SessionLayer, plan: TfPlan, s0: int) -> None:
    """Every session's frame (static, under the map frame), its keyframe path and the loops between sessions."""
    from ..io import message_builders as M

    statics = []
    for name, path, joined in zip(layer.names, layer.paths, layer.joined, strict=True):
        frame = SESSION_FRAME_PREFIX + name
        statics.append((np.eye(4), s0, plan.corrected_frame, frame))  # where this log's corrected poses live
        if not joined:
            note = (f"session {name!r} is not joined to this log's sessions: frame {frame!r} is put at the origin "
                    f"of {plan.corrected_frame!r}, not aligned to it")
            plan.notes.append(note)
            log.info("corrected.mcap: %s", note)
        add(s0, f"{MAP_TOPIC_PREFIX}/{name}/path", M.path_msg(path, frame))
    if statics:
        add(s0, "/tf_static", M.tf_message(statics))
    if layer.loops:
        add(s0, MAP_TOPIC_PREFIX + "/loops", M.marker_array([M.line_marker(layer.loops, s0, plan.corrected_frame,
                                                                            "sessions", 0, rgba=(0.9, 0.4, 0.1, 1.0))]))


def write_corrected_log(path: Path, *, odom: Trajectory, corrected: Trajectory, kf_ids: list[int],
                        kf_corrected: Trajectory, loops: list[tuple[int, int, int]], log_frame_ids: dict, run_conf,
                        copy_from: Path, copy_topics: list[str], gt_alignment=None, gt_poses: Trajectory | None = None,
                        io_conf=None, spooled=None, sessions: SessionLayer | None = None, cloud=None,
                        cloud_topic: str = CLOUD_TOPIC) -> TfPlan:
    """Write ``path`` (see the module docstring). ``loops``: ``(query_id, match_id, stamp_ns)`` of accepted loops.

    ``gt_poses``: a ground truth read from a file (it is not in the log), written on
    :data:`GT_TOPIC` in frame ``log_frame_ids['gt']`` and tied to the tree like a log's.
    ``spooled``: a complete :class:`~slam_lcd.io.raw_spool.RawSpool` of the copied topics (the run's
    pass kept them): read instead of decompressing the log again. ``sessions``: a map's sessions
    (``corrected`` and ``kf_corrected`` are then in the map frame, ``gt_alignment`` the map's).
    ``cloud``: the map's :class:`~slam_lcd.cloud.Cloud` in the corrected trajectory's frame,
    written on ``cloud_topic``."""
    from ..io import message_builders as M
    from ..io.writers import open_writer

    if not np.all(np.isfinite(corrected.poses)):
        raise InvalidPoseError("the corrected trajectory has NaN/inf poses; corrected.mcap not written")
    with open_log(copy_from) as reader:
        chosen = copied_topics(copy_topics)
        if spooled is not None and not (spooled.complete and set(spooled.wanted) == set(chosen)):
            spooled = None  # an interrupted pass (or other topics): read the log
        plan = plan_frames(run_conf, log_frame_ids, log_tf_parents(reader, chosen, spooled))
        for note in plan.notes:
            log.info("corrected.mcap: %s", note)
        own: list[tuple[int, int, str, Any]] = []  # (stamp, order, topic, message)

        def add(stamp, topic, msg):
            own.append((int(stamp), len(own), topic, msg))

        cs, cp = corrected.stamps, corrected.poses
        if len(cs):  # per stamp: the corrected pose, then its /tf (one vectorised conversion each)
            poses = M.pose_stamped_msgs(cp, cs, plan.corrected_frame)
            if plan.publish_map_odom:
                odom_at = interpolate_poses(odom.stamps, odom.poses, cs)
                tfs = M.tf_messages(cp @ inv(odom_at), cs, plan.map_frame, plan.odom_frame)
            else:
                tfs = M.tf_messages(cp, cs, plan.odom_frame, plan.corrected_body)
            for s, pose, tf in zip(cs.tolist(), poses, tfs, strict=True):
                add(s, POSE_TOPIC, pose)
                add(s, "/tf", tf)
        if plan.publish_odom_body and len(odom):
            odom_tfs = M.tf_messages(odom.poses, odom.stamps, plan.odom_frame, plan.body_frame)
            for s, tf in zip(odom.stamps.tolist(), odom_tfs, strict=True):
                add(s, "/tf", tf)
        s0 = int(cs[0]) if len(cs) else 0
        if plan.link_gt and gt_alignment is not None:
            assert plan.gt_frame is not None  # plan_frames links a ground truth only when it has a frame
            T_gt_c = np.eye(4)  # the corrected trajectory's frame seen from the ground truth's (the ATE alignment)
            T_gt_c[:3, :3], T_gt_c[:3, 3] = gt_alignment.R, gt_alignment.t
            link = ((T_gt_c, s0, plan.gt_frame, plan.map_frame) if plan.publish_map_odom else
                    (inv(T_gt_c), s0, plan.corrected_frame, plan.gt_frame))
            add(s0, "/tf_static", M.tf_message([link]))
        if gt_poses is not None:  # ground truth from a file: written here so that it can be overlaid
            assert plan.gt_frame is not None  # its frame is log_frame_ids['gt'] (see the docstring)
            gt_msgs = M.pose_stamped_msgs(gt_poses.poses, gt_poses.stamps, plan.gt_frame) if len(gt_poses) else []
            for s, msg in zip(gt_poses.stamps.tolist(), gt_msgs, strict=True):
                add(s, GT_TOPIC, msg)
        if sessions is not None:
            _add_sessions(add, sessions, plan, s0)
        for s, msg in _keyframe_paths(kf_corrected, plan.corrected_frame):
            add(s, PATH_TOPIC, msg)
        pos = {k: kf_corrected.poses[i][:3, 3] for i, k in enumerate(kf_ids) if i < len(kf_corrected)}
        for n, (q, mt, s) in enumerate(sorted(loops, key=lambda x: x[2])):
            if q in pos and mt in pos:
                add(s, LOOPS_TOPIC, M.marker_array([M.line_marker([(pos[mt], pos[q])], s, plan.corrected_frame,
                                                                  "loops", n)]))
        if cloud is not None and len(cloud) and cloud_topic:
            add(s0, cloud_topic, M.point_cloud2_msg(cloud.points, cloud.colours, s0, plan.corrected_frame))
        own.sort(key=lambda x: (x[0], x[1]))

        with open_writer(path, "mcap", conf=io_conf, inputs=(copy_from,)) as w:
            k = 0

            def flush_until(t):
                nonlocal k
                while k < len(own) and (t is None or own[k][0] <= t):
                    s, _, topic, msg = own[k]
                    w.write(topic, msg, s)
                    k += 1

            ros1 = reader.format == "rosbag1"
            if chosen:
                for t_name, msgtype, log_time, raw in (spooled if spooled is not None else reader.raw_messages(chosen)):
                    flush_until(log_time)
                    w.write_raw(t_name, msgtype, raw, log_time, ros1=ros1, typestore=reader.typestore)
            flush_until(None)
    return plan
