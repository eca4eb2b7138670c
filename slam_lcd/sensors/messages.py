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

from ..errors import DamagedImageError, MessageEncodingError, PipelineError, SlamLcdError, in_context, stamp_text
from ..vision.camera import normalise_camera
from ..io.decode import decode_camera_info, decode_compressed_image, decode_image, decode_pose
from ..types import CameraModel
from .ground_truth import decode_ground_truth
from ..vision.gray import image_to_gray

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
