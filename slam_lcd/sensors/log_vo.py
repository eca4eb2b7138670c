"""Run the built-in visual odometry on a recorded log (bag / rosbag2 / MCAP).

Streams the camera topics of a log in time order, pairs each image with its depth image
(RGB-D) or right image (stereo) by header stamp, reads the camera model from CameraInfo
and the camera mounting from ``/tf_static`` (or the config), and feeds the frames to
:class:`~slam_lcd.frontend.vo.RgbdOdometry` / :class:`~slam_lcd.frontend.vo.StereoOdometry`.
This is the log's odometry source when it has no odometry topic (``slam-lcd run``).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ..errors import PipelineError, TopicNotFoundError
from ..frontend.config import FrontendConfig
from ..frontend.vo import RgbdOdometry, StereoOdometry, VoResult
from ..io import open_log
from ..io.tf import TfBuffer
from ..types import CameraModel
from .calibration import missing_camera_info_hint
from .messages import at_message, camera_from_camera_info, decode_depth, decode_gray
from .mounting import camera_mounting

log = logging.getLogger(__name__)

PAIR_TOLERANCE_NS = 5_000_000  # image and depth/right image belong together within 5 ms


@dataclass
class LogVo:
    result: VoResult
    camera: CameraModel
    T_body_camera: np.ndarray
    mode: str  # 'rgbd' | 'stereo'

    def odometry_samples(self):
        """``(stamp_ns, T_world_body, covariance or None, segment_start)`` per VO pose: the log's
        odometry source when it has no odometry topic (a tracking loss starts a new segment)."""
        traj = self.result.trajectory()
        breaks = self.result.segment_starts
        for k in range(len(traj)):
            cov = None if traj.covariances is None else traj.covariances[k]
            yield int(traj.stamps[k]), traj.poses[k], cov, bool(breaks[k]) and k > 0


def camera_info_topic_of(image_topic: str) -> str:
    """The CameraInfo topic beside an image topic (``/cam/image_raw`` -> ``/cam/camera_info``)."""
    base = image_topic.rsplit("/", 1)[0] if image_topic.count("/") > 1 else ""
    if base.endswith("/image_raw"):
        base = base.rsplit("/", 1)[0]
    return f"{base}/camera_info"


def visual_odometry_from_log(path, conf: FrontendConfig | None = None, *, image_topic: str = "/camera/image_raw",
                             depth_topic: str | None = None, right_topic: str | None = None,
                             camera_info_topic: str | None = None, right_camera_info_topic: str | None = None,
                             extractor=None, max_frames: int | None = None, camera: CameraModel | None = None,
                             T_body_camera: np.ndarray | None = None, rectifier=None,
                             depth_unit_m: float = 1e-3) -> LogVo:
    """VO over a log: RGB-D when ``depth_topic`` is given, stereo when ``right_topic`` is.

    ``camera`` (e.g. from a calibration file, :mod:`slam_lcd.sensors.calibration`) replaces the
    CameraInfo topic (stereo: its ``baseline`` is used); ``T_body_camera`` replaces the
    ``/tf_static`` mounting (the config's ``frontend.T_body_camera`` still wins when set).
    ``rectifier`` (a :class:`~slam_lcd.sensors.rectify.StereoRectifier` of a raw calibrated pair):
    each pair is rectified first; the VO runs on the rectified camera, mounted at
    ``T_body_camera @ rectifier.T_cam0_rect``, so its poses are still of the body.
    ``depth_unit_m``: metres per unit of a 16-bit depth image (RGB-D).
    """
    conf = conf or FrontendConfig()
    if (depth_topic is None) == (right_topic is None):
        raise PipelineError("visual odometry needs exactly one of a depth topic (RGB-D) "
                            "or a right image topic (stereo)")
    mode = "rgbd" if depth_topic else "stereo"
    aux_topic = depth_topic or right_topic  # stereo: the right topic
    assert aux_topic is not None  # exactly one of the two is given (checked above)
    info_topic = camera_info_topic or camera_info_topic_of(image_topic)
    with open_log(path) as reader:
        topics = reader.topics
        for t in (image_topic, aux_topic):
            if t not in topics:
                raise TopicNotFoundError(t, topics, reader.path)
        if camera is None and info_topic not in topics:
            raise TopicNotFoundError(info_topic, topics, reader.path,
                                     hint=missing_camera_info_hint(reader.path, image_topic))
        given_camera = camera is not None
        cam_frame = None
        for m in (reader.messages([info_topic]) if not given_camera else ()):
            with at_message(m, reader.path, decoding=False):
                camera = camera_from_camera_info(m.msg)
            cam_frame = m.msg.header.frame_id
            break
        if camera is None:
            raise PipelineError(f"camera info topic {info_topic} has no messages; visual odometry needs the intrinsics",
                                reader.path)
        if mode == "stereo" and not given_camera:
            rinfo = right_camera_info_topic or camera_info_topic_of(aux_topic)
            if rinfo in topics:
                for m in reader.messages([rinfo]):
                    rc = camera_from_camera_info(m.msg)
                    if rc.baseline:
                        camera.baseline = rc.baseline
                    break
        tf = None
        if "/tf_static" in topics or "tf_static" in topics:
            tf = TfBuffer.from_log(reader, tf_topics=(), static_topics=("/tf_static",))
        T_bc = (camera_mounting(conf, tf, cam_frame) if T_body_camera is None or conf.T_body_camera is not None
                else np.asarray(T_body_camera, np.float64))
        vo_camera, vo_T_bc = camera, T_bc  # LogVo keeps the log's camera and mounting (the main pass's)
        if rectifier is not None:
            if mode != "stereo":
                raise PipelineError("a stereo rectifier was given for RGB-D visual odometry")
            vo_camera, vo_T_bc = rectifier.camera, T_bc @ rectifier.T_cam0_rect
        vo = (RgbdOdometry(vo_camera, conf, vo_T_bc, extractor) if mode == "rgbd"
              else StereoOdometry(vo_camera, conf, vo_T_bc, extractor))
        pending_img: dict[int, np.ndarray] = {}
        pending_aux: dict[int, np.ndarray] = {}
        n = 0
        for m in reader.messages([image_topic, aux_topic]):
            with at_message(m, reader.path, decoding=False):  # name the log, topic and stamp of a bad message
                if m.topic == image_topic:
                    pending_img[m.stamp] = decode_gray(m)
                else:
                    pending_aux[m.stamp] = decode_depth(m, depth_unit_m) if mode == "rgbd" else decode_gray(m)
            # pair the oldest image with an aux image within tolerance, in time order
            while pending_img and pending_aux:
                si = min(pending_img)
                sa = min(pending_aux, key=lambda s: abs(s - si))
                if abs(sa - si) <= PAIR_TOLERANCE_NS:
                    pair = (pending_img.pop(si), pending_aux.pop(sa))
                    vo.process(si, *(rectifier.rectify(*pair) if rectifier is not None else pair))
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
