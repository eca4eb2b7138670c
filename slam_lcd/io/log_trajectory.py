"""Read a trajectory (time-stamped poses) from a log topic or from a TF frame pair."""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..errors import InputError, InvalidPoseError, MessageEncodingError
from ..types import Trajectory
from .decode import decode_pose
from .reader import LogReader, open_log
from .tf import TfBuffer

log = logging.getLogger(__name__)

POSE_TYPES = (
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "nav_msgs/msg/Odometry",
    "geometry_msgs/msg/TransformStamped",
)
TF_TYPE = "tf2_msgs/msg/TFMessage"


def read_trajectory_from_log(
    path: str | Path | LogReader,
    topic: str | None = None,
    *,
    parent_frame: str | None = None,
    child_frame: str | None = None,
    stamp_source: str = "header",
    with_covariance: bool = True,
) -> Trajectory:
    """Trajectory of a pose topic (PoseStamped, PoseWithCovarianceStamped, Odometry,
    TransformStamped) or of a TF frame pair (``topic`` a TFMessage topic or None, with
    ``parent_frame`` and ``child_frame``).

    Poses are sorted by stamp; repeated stamps keep the first pose. Covariances (GTSAM
    order, body frame) are kept when every message has one. frame ids come from the
    messages. A NaN pose raises :class:`InvalidPoseError` naming the stamp.
    """
    own = not isinstance(path, LogReader)
    reader = path if isinstance(path, LogReader) else open_log(path, stamp_source)
    try:
        if topic is None and not (parent_frame and child_frame):
            raise InputError("give a pose topic, or parent_frame and child_frame for a TF pair", reader.path)
        if topic is not None:
            (name,) = reader.resolve_topics([topic])
            msgtype = reader.topics[name].msgtype
            if msgtype == TF_TYPE:
                if not (parent_frame and child_frame):
                    raise InputError(f"topic {name!r} carries TF; give parent_frame and child_frame", reader.path)
                return _from_tf(reader, parent_frame, child_frame)
            if msgtype not in POSE_TYPES:
                raise MessageEncodingError(
                    f"topic {name!r} carries {msgtype}, not a pose type ({', '.join(POSE_TYPES)})", reader.path
                )
            return _from_topic(reader, name, with_covariance)
        assert parent_frame and child_frame  # no topic: the check above required both
        return _from_tf(reader, parent_frame, child_frame)
    finally:
        if own:
            reader.close()


def _from_topic(reader: LogReader, topic: str, with_covariance: bool) -> Trajectory:
    stamps, poses, covs = [], [], []
    frame, child = "world", "body"
    for i, m in enumerate(reader.messages([topic])):
        try:
            T, cov = decode_pose(m.msg)
        except InvalidPoseError as e:
            raise InvalidPoseError(f"topic {topic!r} message {i} (stamp {m.stamp} ns): {e.problem}",
                                   reader.path) from None
        if i == 0:
            frame = m.msg.header.frame_id or frame
            child = getattr(m.msg, "child_frame_id", "") or child
        stamps.append(m.stamp)
        poses.append(T)
        covs.append(cov)
    if not stamps:
        raise InputError(f"topic {topic!r} has no messages", reader.path)
    st = np.asarray(stamps, np.int64)
    P = np.asarray(poses)
    C = np.asarray(covs) if with_covariance and all(c is not None for c in covs) else None
    order = np.argsort(st, kind="stable")
    keep = np.ones(len(st), bool)
    keep[1:] = st[order][1:] != st[order][:-1]
    if not keep.all():
        log.info("%s: topic %s: dropped %d messages with repeated stamps", reader.path, topic, int((~keep).sum()))
    idx = order[keep]
    return Trajectory(st[idx], P[idx], None if C is None else C[idx], frame_id=frame, child_frame_id=child)


def _from_tf(reader: LogReader, parent: str, child: str) -> Trajectory:
    buf = TfBuffer.from_log(reader, extrapolation_ns=int(reader.conf.tf_extrapolation_s * 1e9))
    stamps = buf.stamps(parent, child)
    if len(stamps) == 0:
        raise InputError(f"TF chain {parent} -> {child} has no dynamic transforms to sample", reader.path)
    poses = np.stack([buf.lookup(parent, child, int(s)) for s in stamps])
    return Trajectory(stamps, poses, None, frame_id=parent.lstrip("/"), child_frame_id=child.lstrip("/"))
