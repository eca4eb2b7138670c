"""Ground truth from whatever the log has: a pose-like topic of any common type, or a TF chain.

``--gt-topic`` names one of

- a topic of ``geometry_msgs/PoseStamped``, ``PoseWithCovarianceStamped``, ``nav_msgs/Odometry``,
  ``geometry_msgs/TransformStamped`` (EuRoC's Vicon ``/vicon/firefly_sbx/firefly_sbx``) or
  ``geometry_msgs/PointStamped`` (EuRoC's Leica ``/leica/position``): position only, so the
  rotation is unknown; it is stored as identity and the report says the ATE is on translation;
- a TF chain ``TOPIC:PARENT:CHILD`` (TUM RGB-D's mocap: ``/tf:/world:/kinect``): ``T_parent_child``
  sampled at the stamps of the chain's densest dynamic edge, through the log's static
  transforms as well (:class:`~slam_lcd.io.tf.TfBuffer`).

The ground-truth body need not be the odometry's body nor the camera: the world-frame
offset between the two trajectories is what the ATE alignment (``eval.align``) estimates;
a fixed lever arm between the ground-truth body (prism, marker, mocap frame) and the
odometry's body is not estimated and stays in the ATE (docs/io.md says how much).
"""
from __future__ import annotations

import logging

import numpy as np

from ..errors import InputError, MessageEncodingError, stamp_text
from ..io.decode import decode_pose
from ..io.tf import TfBuffer, TfLookupError
from ..types import Trajectory

POSE_GT_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped",
                 "nav_msgs/msg/Odometry", "geometry_msgs/msg/TransformStamped")
POINT_TYPE = "geometry_msgs/msg/PointStamped"
GT_TYPES = (*POSE_GT_TYPES, POINT_TYPE)
TF_TYPE = "tf2_msgs/msg/TFMessage"
POSITION_ONLY_NOTE = "position-only ground truth (PointStamped): ATE on translation"
# why a run against position-only ground truth reports no rotation error and no RPE
POSITION_ONLY_REASON = ("a point has no orientation, so there is no rotation error and no RPE (the RPE takes each "
                        "pair's motion in the ground truth's orientation)")

log = logging.getLogger(__name__)


def split_tf_spec(spec: str) -> tuple[str, str | None, str | None]:
    """``(topic, parent, child)`` of ``TOPIC:PARENT:CHILD``; ``(spec, None, None)`` for a plain topic."""
    parts = spec.split(":")
    if len(parts) == 1:
        return spec, None, None
    if len(parts) == 3 and all(parts):
        return parts[0], parts[1], parts[2]
    raise InputError(f"--gt-topic {spec!r}: give a pose topic or a TF chain TOPIC:PARENT:CHILD (e.g. /tf:world:kinect)")


def decode_ground_truth(m) -> np.ndarray:
    """``T_world_gtbody`` of one ground-truth message (PointStamped: identity rotation)."""
    if m.msgtype == POINT_TYPE:
        p = m.msg.point
        t = np.array([float(p.x), float(p.y), float(p.z)])
        if not np.all(np.isfinite(t)):
            raise MessageEncodingError(f"PointStamped with NaN/inf position {t.tolist()}")
        T = np.eye(4)
        T[:3, 3] = t
        return T
    return decode_pose(m.msg)[0]


def ground_truth_from_tf(reader, topic: str, parent: str, child: str, static_topics=()) -> Trajectory:
    """``T_parent_child`` over the log from the TF topic ``topic`` (and the static TF topics)."""
    buf = TfBuffer(int(reader.conf.tf_extrapolation_s * 1e9))
    statics = set(static_topics)
    for m in reader.messages([topic, *statics]):
        buf.add(m.msg, static=m.topic in statics)
    try:
        stamps = buf.stamps(parent, child)
        if len(stamps) == 0:
            raise TfLookupError(f"TF chain {parent} -> {child} has no dynamic transform to sample")
        poses = np.stack([buf.lookup(parent, child, int(s)) for s in stamps])
    except TfLookupError as e:
        raise InputError(f"--gt-topic {topic}:{parent}:{child}: {e.problem}", reader.path) from None
    return Trajectory(stamps, poses, None, frame_id=parent.lstrip("/"), child_frame_id=child.lstrip("/"))


def ground_truth_from_messages(stamps, poses, log_path, topic: str) -> Trajectory | None:
    """The ground truth read from ``topic`` while the log streams, in time order (None: no message).

    A repeated stamp is kept with one warning line, as ``slam-lcd ate`` does with a file: the
    ATE's time association picks one of the poses, and where the ground truth is interpolated
    (at keyframe stamps) the first pose of the stamp counts.
    """
    if not len(stamps):
        return None
    st = np.asarray(stamps, np.int64)
    order = np.argsort(st, kind="stable")
    st = st[order]
    rep = np.flatnonzero(np.diff(st) == 0)
    if rep.size:
        log.warning("%s: topic %s: %d repeated ground-truth stamp(s) (first: %s); both poses are kept",
                    log_path, topic, int(rep.size), stamp_text(int(st[rep[0]])))
    return Trajectory(st, np.asarray(poses)[order])
