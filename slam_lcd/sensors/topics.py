"""Which topics of a log a run reads, and which it copies into corrected.mcap.

Explicit flags win; otherwise the log's only ``sensor_msgs/Image`` (or ``CompressedImage``)
topic that is not a depth or right-stereo image, its ``CameraInfo`` in the same namespace,
the depth image in the same namespace, the only ``nav_msgs/Odometry`` topic (not the
ground truth), and a ground-truth pose topic whose name says so. ``--gt-topic`` may also be
a ``PointStamped``, ``TransformStamped`` or a TF chain ``TOPIC:PARENT:CHILD``
(:mod:`slam_lcd.sensors.ground_truth`).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

from ..errors import PipelineError, TopicTypeError
from .ground_truth import GT_TYPES, POINT_TYPE, split_tf_spec

log = logging.getLogger(__name__)

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
CAMINFO_TYPE = "sensor_msgs/msg/CameraInfo"
ODOM_TYPES = ("nav_msgs/msg/Odometry",)
POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped", "nav_msgs/msg/Odometry")
TF_TYPE = "tf2_msgs/msg/TFMessage"


@dataclass
class Topics:
    image: str
    odom: str | None
    camera_info: str | None = None
    depth: str | None = None
    gt: str | None = None
    gt_frames: tuple[str, str] | None = None  # (parent, child) when the ground truth is a TF chain on ``gt``
    gt_position_only: bool = False  # PointStamped ground truth
    right: str | None = None  # second camera of a stereo pair (a log without depth): VO and loop-pose depth

    def wanted(self) -> list[str]:
        """The topics streamed, in the order they are listed here (each once; a TF ground truth is read first)."""
        gt = self.gt if self.gt_frames is None else None
        return [t for t in (self.image, self.odom, self.camera_info, self.depth, gt, self.right) if t]


def _ns(topic: str) -> str:
    return topic.rsplit("/", 1)[0]


def _gt_name(topic: str) -> bool:
    """A topic whose name says it is ground truth (never taken as the odometry)."""
    return "ground_truth" in topic or "groundtruth" in topic


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
        image_topic = reader.resolve_topics(image_topic, flag="--image-topic")[0]
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
        odom_topic = reader.resolve_topics(odom_topic, flag="--odom-topic")[0]
        _check_type(reader, "--odom-topic", odom_topic, POSE_TYPES, "odometry")
    else:
        named_gt = (reader.resolve_topics(split_tf_spec(gt_topic)[0], flag="--gt-topic")[0]
                    if gt_topic is not None else None)
        odoms = [t for t, i in topics.items() if i.msgtype in ODOM_TYPES and t != named_gt and not _gt_name(t)]
        odom_topic = odoms[0] if len(odoms) == 1 else None
        if len(odoms) > 1:
            raise PipelineError(f"several odometry topics {odoms}; choose one with --odom-topic", path)
    ns = _ns(image_topic)
    infos = [t for t, i in topics.items() if i.msgtype == CAMINFO_TYPE and _ns(t) == ns]
    if depth_topic is not None:
        depth_topic = reader.resolve_topics(depth_topic, flag="--depth-topic")[0]
        _check_type(reader, "--depth-topic", depth_topic, IMAGE_TYPES, "a depth image")
    else:
        depths = [t for t in images if "depth" in t.lower() and (_ns(t) == ns or _ns(_ns(t)) == ns)]
        if not depths:  # a sibling namespace (TUM: /camera/rgb/image_color beside /camera/depth_registered/image_raw)
            depths = sorted(t for t in images if "depth" in t.lower() and _ns(_ns(t)) == _ns(ns) and _ns(ns))
        depth_topic = depths[0] if depths else None
    gt_frames = None
    if gt_topic is not None:
        gt_topic, parent, child = split_tf_spec(gt_topic)
        gt_topic = reader.resolve_topics(gt_topic, flag="--gt-topic")[0]
        if parent is not None:
            assert child is not None  # split_tf_spec gives both frames or neither
            _check_type(reader, "--gt-topic", gt_topic, (TF_TYPE,), "a TF topic for TOPIC:PARENT:CHILD")
            gt_frames = (parent, child)
        elif reader.topics[gt_topic].msgtype == TF_TYPE:
            raise TopicTypeError(f"--gt-topic {gt_topic} carries TF: name the frames as {gt_topic}:PARENT:CHILD",
                                 reader.path)
        else:
            _check_type(reader, "--gt-topic", gt_topic, GT_TYPES, "a pose or a position")
    else:
        gts = [t for t, i in topics.items() if i.msgtype in POSE_TYPES and _gt_name(t)]
        gt_topic = gts[0] if len(gts) == 1 else None
    position_only = gt_topic is not None and gt_frames is None and topics[gt_topic].msgtype == POINT_TYPE
    return Topics(image_topic, odom_topic, infos[0] if infos else None, depth_topic, gt_topic, gt_frames, position_only)


def choose_right_topic(reader, image_topic: str, right_topic: str | None = None,
                       calibrated_partner: str | None = None) -> str | None:
    """The second camera of a stereo pair, for the stereo VO of a log without odometry or depth.

    ``right_topic`` when given (checked); else the calibration's next camera (its ``rostopic``,
    e.g. EuRoC's ``/cam1/image_raw``) when the log has it; else ``image_topic`` with ``left``
    spelled ``right`` (KITTI's ``camera_gray_left`` / ``camera_gray_right``); else the only
    image topic with ``right`` in its name under the same first namespace (``/camera/right/image_raw``).
    """
    topics = reader.topics
    if right_topic is not None:
        right_topic = reader.resolve_topics(right_topic, flag="--right-topic")[0]
        _check_type(reader, "--right-topic", right_topic, IMAGE_TYPES, "a camera image")
        return right_topic
    if calibrated_partner:
        for t in topics:
            if t.strip("/") == calibrated_partner.strip("/") and topics[t].msgtype in IMAGE_TYPES:
                return t
    swapped = image_topic.replace("left", "right")
    if swapped != image_topic and swapped in topics and topics[swapped].msgtype in IMAGE_TYPES:
        return swapped
    root = image_topic.strip("/").split("/")[0]
    rights = [t for t, i in topics.items() if i.msgtype in IMAGE_TYPES and "right" in t.lower()
              and "depth" not in t.lower() and t.strip("/").split("/")[0] == root and t != image_topic]
    return rights[0] if len(rights) == 1 else None


def static_tf_topics(reader) -> list[str]:
    """The log's static TF topics (``/tf_static`` and the like)."""
    return [t for t, i in reader.topics.items() if i.msgtype == TF_TYPE and "static" in t]


def copyable_topics(reader, copy_images: bool, log_path) -> list[str]:
    """Input topics copied into corrected.mcap: all (or all but images), minus types we cannot describe."""
    from ..io.writers import describable  # lazy: rosbags

    chosen: list[str] = []
    skipped: list[str] = []
    for t, i in reader.topics.items():
        if not (copy_images or i.msgtype not in IMAGE_TYPES):
            continue
        (chosen if describable(i.msgtype, reader.typestore) else skipped).append(t)
    if skipped:
        kinds = ", ".join(f"{t} ({reader.topics[t].msgtype})" for t in skipped)
        log.warning("%s: topics with message types the log does not define are not copied into corrected.mcap: %s",
                    log_path, kinds)
    return chosen


def configured_topics(reader, conf, image_topic=None, odom_topic=None, gt_topic=None, depth_topic=None,
                      right_topic=None) -> dict:
    """The topic flags of a run, each flag given filled in from the config's `sensors` section.

    A flag wins; a configured topic the log lacks is skipped with a warning (the automatic
    choice is made then); of ``sensors.gt_topics`` the first the log has is taken (a TF chain
    ``TOPIC:PARENT:CHILD`` by its topic).
    """
    have = set(reader.topics)

    def present(spec):
        topic = split_tf_spec(spec)[0]
        return topic in have or "/" + topic.lstrip("/") in have or topic.lstrip("/") in have

    chosen = {"image_topic": image_topic, "odom_topic": odom_topic, "depth_topic": depth_topic,
              "right_topic": right_topic, "gt_topic": gt_topic}
    for key in ("image_topic", "odom_topic", "depth_topic", "right_topic"):
        want = getattr(conf, key)
        if chosen[key] is None and want:
            if present(want):
                chosen[key] = want
            else:
                log.warning("%s: sensors.%s %s is not in the log; choosing automatically", reader.path, key, want)
    if gt_topic is None and conf.gt_topics:
        found = [g for g in conf.gt_topics if present(g)]
        if found:
            chosen["gt_topic"] = found[0]
        else:
            log.warning("%s: none of sensors.gt_topics %s is in the log; choosing automatically", reader.path,
                        list(conf.gt_topics))
    return chosen
