"""Run the built-in visual odometry on a recorded log (bag / rosbag2 / MCAP).

Streams the camera topics of a log in time order, pairs each image with its depth image
(RGB-D) or right image (stereo) by header stamp, reads the camera model from CameraInfo
and the camera mounting from ``/tf_static`` (or the config), and feeds the frames to
:class:`RgbdOdometry` / :class:`StereoOdometry`.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..errors import PipelineError, SlamLcdError, in_context, stamp_text
from ..types import CameraModel
from .camera import camera_from_camera_info, camera_mounting
from .config import FrontendConfig
from .vo import RgbdOdometry, StereoOdometry, VoResult

log = logging.getLogger(__name__)

PAIR_TOLERANCE_NS = 5_000_000  # image and depth/right image belong together within 5 ms


@dataclass
class LogVo:
    result: VoResult
    camera: CameraModel
    T_body_camera: np.ndarray
    mode: str  # 'rgbd' | 'stereo'


def _info_topic(image_topic: str) -> str:
    base = image_topic.rsplit("/", 1)[0] if image_topic.count("/") > 1 else ""
    if base.endswith("/image_raw"):
        base = base.rsplit("/", 1)[0]
    return f"{base}/camera_info"


def _decode(m) -> np.ndarray:
    from ..io.decode import decode_compressed_image, decode_image

    if m.msgtype.endswith("CompressedImage"):
        img = decode_compressed_image(m.msg)
    else:
        img = decode_image(m.msg)
    return img


def visual_odometry_from_log(path, conf: FrontendConfig | None = None, *, image_topic: str = "/camera/image_raw",
                             depth_topic: str | None = None, right_topic: str | None = None,
                             camera_info_topic: str | None = None, right_camera_info_topic: str | None = None,
                             extractor=None, max_frames: int | None = None) -> LogVo:
    """VO over a log: RGB-D when ``depth_topic`` is given, stereo when ``right_topic`` is."""
    from ..io import open_log
    from ..io.decode import image_to_gray

    conf = conf or FrontendConfig()
    if (depth_topic is None) == (right_topic is None):
        raise PipelineError("visual odometry needs exactly one of a depth topic (RGB-D) or a right image topic (stereo)")
    mode = "rgbd" if depth_topic else "stereo"
    aux_topic = depth_topic or right_topic
    info_topic = camera_info_topic or _info_topic(image_topic)
    with open_log(path) as reader:
        topics = reader.topics
        for t in (image_topic, aux_topic, info_topic):
            if t not in topics:
                from ..errors import TopicNotFoundError

                raise TopicNotFoundError(t, topics, reader.path)
        camera = None
        cam_frame = None
        for m in reader.messages([info_topic]):
            try:
                camera = camera_from_camera_info(m.msg)
            except SlamLcdError as e:
                raise in_context(e, f"topic {m.topic}, stamp {stamp_text(m.stamp)}", reader.path) from None
            cam_frame = m.msg.header.frame_id
            break
        if camera is None:
            raise PipelineError(f"camera info topic {info_topic} has no messages; visual odometry needs the intrinsics",
                                reader.path)
        if mode == "stereo":
            rinfo = right_camera_info_topic or _info_topic(right_topic)
            if rinfo in topics:
                for m in reader.messages([rinfo]):
                    rc = camera_from_camera_info(m.msg)
                    if rc.baseline:
                        camera.baseline = rc.baseline
                    break
        tf = None
        if "/tf_static" in topics or "tf_static" in topics:
            from ..io.tf import TfBuffer

            tf = TfBuffer.from_log(reader, tf_topics=(), static_topics=("/tf_static",))
        T_bc = camera_mounting(conf, tf, cam_frame)
        vo = (RgbdOdometry(camera, conf, T_bc, extractor) if mode == "rgbd"
              else StereoOdometry(camera, conf, T_bc, extractor))
        pending_img: dict[int, np.ndarray] = {}
        pending_aux: dict[int, np.ndarray] = {}
        n = 0
        for m in reader.messages([image_topic, aux_topic]):
            try:
                if m.topic == image_topic:
                    pending_img[m.stamp] = image_to_gray(_decode(m))
                else:
                    a = _decode(m)
                    pending_aux[m.stamp] = a if mode == "rgbd" else image_to_gray(a)
            except SlamLcdError as e:  # name the log, topic and stamp of the bad message
                raise in_context(e, f"topic {m.topic}, stamp {stamp_text(m.stamp)}", reader.path) from None
            # pair the oldest image with an aux image within tolerance, in time order
            while pending_img and pending_aux:
                si = min(pending_img)
                sa = min(pending_aux, key=lambda s: abs(s - si))
                if abs(sa - si) <= PAIR_TOLERANCE_NS:
                    vo.process(si, pending_img.pop(si), pending_aux.pop(sa))
                    for s in [s for s in pending_aux if s < sa]:
                        pending_aux.pop(s)
                    n += 1
                    if max_frames is not None and n >= max_frames:
                        return LogVo(vo.result(), camera, T_bc, mode)
                elif sa > si + PAIR_TOLERANCE_NS:
                    log.warning("image at %d ns has no %s partner; skipped", si, aux_topic)
                    pending_img.pop(si)
                else:
                    pending_aux.pop(sa)
        return LogVo(vo.result(), camera, T_bc, mode)
