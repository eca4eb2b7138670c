"""One decode dispatch for the messages a run reads, with errors that say where they happened.

Images (raw or compressed) become arrays, grey images uint8 through one conversion
(:func:`slam_lcd.vision.gray.image_to_gray`), depth images float32 metres (16-bit images are
millimetres, the ROS convention; 32FC1 is metres), poses 4x4 matrices with covariances,
CameraInfo a :class:`~slam_lcd.types.CameraModel`. :func:`at_message` names the log, topic
and stamp of a message whose decoding (or use) fails.
"""
from __future__ import annotations

import contextlib

import numpy as np

from ..errors import (
    CalibrationError,
    DamagedImageError,
    MessageEncodingError,
    PipelineError,
    SlamLcdError,
    in_context,
    stamp_text,
)
from ..io.decode import decode_camera_info, decode_compressed_image, decode_image, decode_pose
from ..types import CameraModel
from ..vision.camera import normalise_camera
from ..vision.gray import image_to_gray
from .ground_truth import decode_ground_truth

DEPTH_ENCODINGS = ("16UC1", "mono16", "32FC1")


def where(m) -> str:
    return f"topic {m.topic}, stamp {stamp_text(m.stamp)}"


@contextlib.contextmanager
def at_message(m, log_path, decoding: bool = True):
    """Errors inside the block name the log, the topic and the stamp of message ``m``.

    ``decoding``: other exceptions (a message with fields of the wrong kind) become a
    :class:`MessageEncodingError`; otherwise they pass through.
    """
    try:
        yield
    except SlamLcdError as e:
        raise in_context(e, where(m), log_path) from None
    except (ValueError, TypeError, IndexError, AttributeError, KeyError) as e:
        if not decoding:
            raise
        raise MessageEncodingError(f"{where(m)}: {m.msgtype} message cannot be decoded "
                                   f"({type(e).__name__}: {' '.join(str(e).split())[:200]})", log_path) from None


def decode_any_image(m) -> np.ndarray:
    """The image of an ``Image`` or ``CompressedImage`` message, as encoded (colour as RGB)."""
    return decode_compressed_image(m.msg) if m.msgtype.endswith("CompressedImage") else decode_image(m.msg)


def decode_gray(m) -> np.ndarray:
    return image_to_gray(decode_any_image(m))


def decode_depth(m, unit_m: float = 1e-3) -> np.ndarray:
    """Depth in metres (float32): 16-bit images are ``unit_m`` per unit (ROS convention: millimetres), 32FC1 metres."""
    if m.msgtype.endswith("CompressedImage"):
        d = decode_compressed_image(m.msg)
        if d.ndim != 2 or d.dtype not in (np.uint16, np.float32):
            raise MessageEncodingError(f"compressed image ({m.msg.format!r}) is not a depth image "
                                       "(compressedDepth 16UC1 or 32FC1)")
        return d.astype(np.float32) * (unit_m if d.dtype == np.uint16 else 1.0)
    enc = m.msg.encoding
    if enc not in DEPTH_ENCODINGS:
        raise MessageEncodingError(f"depth image encoding {enc!r} is not a depth encoding "
                                   f"({', '.join(DEPTH_ENCODINGS)}: 16-bit in millimetres, 32FC1 in metres)")
    d = decode_image(m.msg).astype(np.float32)
    return d * np.float32(unit_m) if enc in ("16UC1", "mono16") else d


def decode_pose_of(m):
    """``(T, covariance or None)`` of a pose, odometry or transform message."""
    return decode_pose(m.msg)


def decode_camera_of(m) -> CameraModel:
    """The camera model of a CameraInfo message, as the message states it."""
    return decode_camera_info(m.msg)


def camera_from_camera_info(msg) -> CameraModel:
    """A checked :class:`CameraModel` from a ROS1/ROS2 CameraInfo message: the decoded model
    with its distortion name and coefficient count normalised
    (:func:`slam_lcd.vision.camera.normalise_camera`). The stereo baseline is taken from
    the projection matrix (``P[0,3] = -fx * baseline`` for a right camera)."""
    return normalise_camera(decode_camera_info(msg))


def check_first_messages(reader, topics) -> dict:
    """Read and decode the first message of every chosen topic before any work is done."""
    roles = [("--image-topic", topics.image, decode_gray), ("--odom-topic", topics.odom, decode_pose_of),
             ("camera info", topics.camera_info, decode_camera_of),
             ("--depth-topic", topics.depth, decode_depth),
             ("--gt-topic", topics.gt if topics.gt_frames is None else None, decode_ground_truth)]
    first = {}
    for flag, topic, decode in roles:
        if topic is None or topic in first:
            continue
        m = next(iter(reader.messages([topic])), None)
        if m is None:
            raise PipelineError(f"topic {topic} ({flag}) has no messages", reader.path)
        try:
            with at_message(m, reader.path):
                decode(m)
        except DamagedImageError:
            pass  # one damaged frame is skipped while streaming (and counted in a warning)
        first[topic] = m
    return first


def _size(wh) -> str:
    return f"{wh[0]}x{wh[1]}"


def check_image_sizes(reader, topics, first: dict, calibrated=None, calibration=None) -> None:
    """The camera model and the depth images must be of the images' size; else one line naming both.

    Checked on the first messages (:func:`check_first_messages`), before any work: the
    calibration file's ``resolution`` of the image topic's camera, the CameraInfo's
    width x height (0 x 0: not stated, not checked) and the depth image's size against the
    first image's. Nothing is resampled: intrinsics of another size put every point in the
    wrong place, and a depth image of another size gives the wrong depth to every pixel.
    """
    m = first.get(topics.image)
    if m is None:
        return
    try:
        img = decode_any_image(m)
    except SlamLcdError:
        return  # a damaged first frame: the stream skips it (and says so)
    image = (int(img.shape[1]), int(img.shape[0]))
    if calibrated is not None:
        cam = calibrated.camera
        if (cam.width, cam.height) != image:
            source = calibration.sources[0] if calibration is not None and calibration.sources else None
            raise CalibrationError(f"camera {calibrated.name} has resolution {_size((cam.width, cam.height))} but "
                                   f"the images of {topics.image} in {reader.path} are {_size(image)}; give the "
                                   "calibration of this camera at this image size", source)
    info = first.get(topics.camera_info) if topics.camera_info else None
    if info is not None:
        w, h = int(info.msg.width), int(info.msg.height)
        if (w, h) != (0, 0) and (w, h) != image:
            raise PipelineError(f"CameraInfo {topics.camera_info} is for {_size((w, h))} images but the images of "
                                f"{topics.image} are {_size(image)}: the intrinsics do not fit the images",
                                reader.path)
    d = first.get(topics.depth) if topics.depth else None
    if d is not None:
        try:
            depth = decode_depth(d)
        except SlamLcdError:
            return
        dsize = (int(depth.shape[1]), int(depth.shape[0]))
        if dsize != image:
            raise PipelineError(f"depth images of {topics.depth} are {_size(dsize)} but the images of {topics.image} "
                                f"are {_size(image)}: depth must be registered to the image, pixel for pixel",
                                reader.path)
