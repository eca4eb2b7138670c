"""Decoders from ROS message objects (ROS1 or ROS2, as rosbags deserialises them) to numpy.

- images: mono HxW (uint8 / uint16 / float32) or RGB uint8 HxWx3 for every colour encoding;
  raw mono8/mono16/32FC1 images without row padding are zero-copy, read-only views of the
  message buffer (copy before writing into them);
- poses: 4x4 float64 ``T_frame_child`` and the covariance in GTSAM order and body frame
  (see :mod:`slam_lcd.io.transforms`), or None when the message says it is unknown.
"""
from __future__ import annotations

import struct

import cv2
import numpy as np

from ..errors import DamagedImageError, InvalidPoseError, MessageEncodingError
from ..runtime.quiet import native_stderr, one_line, quiet_opencv
from ..types import CameraModel
from .transforms import pose_from_tq, ros_cov_to_gtsam

# encoding -> (dtype, channels)
IMAGE_ENCODINGS = {
    "mono8": (np.uint8, 1),
    "8UC1": (np.uint8, 1),
    "mono16": (np.uint16, 1),
    "16UC1": (np.uint16, 1),
    "32FC1": (np.float32, 1),
    "rgb8": (np.uint8, 3),
    "bgr8": (np.uint8, 3),
    "8UC3": (np.uint8, 3),
    "rgba8": (np.uint8, 4),
    "bgra8": (np.uint8, 4),
}


def _msgname(msg) -> str:
    return getattr(msg, "__msgtype__", type(msg).__name__)


def decode_image(msg) -> np.ndarray:
    """sensor_msgs/Image -> HxW (mono8 uint8, mono16/16UC1 uint16, 32FC1 float32) or HxWx3 RGB uint8."""
    enc = msg.encoding
    layout = IMAGE_ENCODINGS.get(enc)
    if layout is None:
        raise MessageEncodingError(
            f"image encoding {enc!r} is not supported; supported: {', '.join(IMAGE_ENCODINGS)}"
        )
    dtype, nch = layout
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    item = np.dtype(dtype).itemsize
    row = w * nch * item
    data = msg.data
    if h <= 0 or w <= 0:
        raise MessageEncodingError(f"image has size {w}x{h}")
    if step < row or len(data) < step * (h - 1) + row:
        raise MessageEncodingError(
            f"{enc} image {w}x{h} with step {step} needs {step * h} bytes, message has {len(data)}"
        )
    buf = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data
    if step == row:
        img = buf[: h * row].view(dtype) if item > 1 else buf[: h * row]
    else:  # padded rows
        img = np.lib.stride_tricks.as_strided(buf, shape=(h, row), strides=(step, 1)).copy().reshape(-1)
        img = img.view(dtype) if item > 1 else img
    if item > 1 and bool(msg.is_bigendian) == np.little_endian:
        img = img.byteswap()  # stored in the other byte order than this machine's
    img = img.reshape(h, w) if nch == 1 else img.reshape(h, w, nch)
    if enc in ("bgr8", "8UC3"):
        return img[..., ::-1].copy()
    if enc == "bgra8":
        return img[..., 2::-1].copy()
    if enc == "rgba8":
        return img[..., :3].copy()
    return img


def decode_compressed_image(msg) -> np.ndarray:
    """sensor_msgs/CompressedImage (jpeg/png, incl. 'compressedDepth png') -> gray HxW or RGB HxWx3.

    compressedDepth 16UC1 gives uint16 depth; 32FC1 gives float32 metres (inverse-depth
    quantisation undone, NaN where no depth).
    """
    fmt = str(msg.format).lower()
    data = np.asarray(msg.data, dtype=np.uint8)
    if data.size == 0:
        raise MessageEncodingError(f"compressed image ({msg.format!r}) has no data (0 bytes)")
    depth_hdr = None
    if "compresseddepth" in fmt:
        if len(data) < 12:
            raise MessageEncodingError(f"compressedDepth image of {len(data)} bytes has no 12-byte header")
        depth_hdr = struct.unpack("<iff", data[:12].tobytes())
        data = data[12:]
    elif not any(k in fmt for k in ("jpeg", "jpg", "png")):
        raise MessageEncodingError(f"compressed image format {msg.format!r} is not supported (jpeg or png)")
    if data.size == 0:
        raise MessageEncodingError(f"compressedDepth image ({msg.format!r}) has a header but no image data")
    quiet_opencv()
    try:
        with native_stderr() as cap:  # libjpeg/libpng warnings become our message, not terminal noise
            img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    except cv2.error as e:
        raise MessageEncodingError(f"compressed image ({msg.format!r}, {len(data)} bytes) cannot be decoded "
                                   f"(OpenCV: {one_line(e, 120)})") from None
    if img is None:
        said = f" ({one_line(cap.text, 120)})" if cap.text else ""
        raise MessageEncodingError(f"compressed image ({msg.format!r}, {len(data)} bytes) cannot be decoded{said}")
    if cap.damage:
        raise DamagedImageError(f"compressed image ({msg.format!r}, {len(data)} bytes) is damaged "
                                f"(decoder: {cap.damage})")
    if depth_hdr is not None:
        if "32fc1" in fmt:
            _, qa, qb = depth_hdr
            v = img.astype(np.float32)
            with np.errstate(divide="ignore"):
                out = qa / (v - qb)
            out[img == 0] = np.nan
            return out.astype(np.float32)
        return img
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    return img


def decode_camera_info(msg) -> CameraModel:
    """sensor_msgs/CameraInfo (ROS1 K/D/P or ROS2 k/d/p fields) -> CameraModel."""
    K = np.asarray(getattr(msg, "k", None) if hasattr(msg, "k") else msg.K, dtype=np.float64).reshape(-1)
    D = np.asarray(getattr(msg, "d", None) if hasattr(msg, "d") else msg.D, dtype=np.float64).reshape(-1)
    P = np.asarray(getattr(msg, "p", None) if hasattr(msg, "p") else msg.P, dtype=np.float64).reshape(-1)
    if K.size != 9 or not np.all(np.isfinite(K)) or K[0] <= 0 or K[4] <= 0:
        raise MessageEncodingError(f"CameraInfo has no valid intrinsics (K = {K.tolist()}); camera is uncalibrated")
    model = str(msg.distortion_model) or "none"
    if not D.any():
        model, D = "none", np.zeros(0)
    baseline = None
    if P.size == 12 and P[0] > 0 and P[3] != 0:
        baseline = float(-P[3] / P[0])
    return CameraModel(
        width=int(msg.width),
        height=int(msg.height),
        fx=float(K[0]),
        fy=float(K[4]),
        cx=float(K[2]),
        cy=float(K[5]),
        distortion_model=model,
        D=D,
        baseline=baseline,
    )


def _pose_T(p, what):
    return pose_from_tq((p.position.x, p.position.y, p.position.z),
                        (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w), what)


def transform_to_matrix(tr, what: str = "transform") -> np.ndarray:
    """geometry_msgs/Transform -> 4x4."""
    return pose_from_tq((tr.translation.x, tr.translation.y, tr.translation.z),
                        (tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w), what)


def decode_pose(msg) -> tuple[np.ndarray, np.ndarray | None]:
    """(T 4x4, cov 6x6 GTSAM order/body frame or None) of PoseStamped, PoseWithCovariance(Stamped),
    Odometry, TransformStamped, Pose or Transform. NaN/inf or non-unit quaternions -> InvalidPoseError."""
    name = _msgname(msg)
    short = name.rsplit("/", 1)[-1]
    if short == "PoseStamped":
        return _pose_T(msg.pose, name), None
    if short in ("PoseWithCovarianceStamped", "Odometry"):
        T = _pose_T(msg.pose.pose, name)
        return T, ros_cov_to_gtsam(msg.pose.covariance, T[:3, :3])
    if short == "PoseWithCovariance":
        T = _pose_T(msg.pose, name)
        return T, ros_cov_to_gtsam(msg.covariance, T[:3, :3])
    if short == "TransformStamped":
        return transform_to_matrix(msg.transform, name), None
    if short == "Transform":
        return transform_to_matrix(msg, name), None
    if short == "Pose":
        return _pose_T(msg, name), None
    raise MessageEncodingError(f"{name} is not a pose message "
                               "(PoseStamped, PoseWithCovarianceStamped, Odometry, TransformStamped)")


def header_stamp(msg) -> int:
    """int ns of ``msg.header.stamp``."""
    st = msg.header.stamp
    return int(st.sec) * 1_000_000_000 + int(st.nanosec)


def frame_ids(msg) -> tuple[str, str | None]:
    """(header frame_id, child_frame_id or None) of a pose message."""
    return str(msg.header.frame_id), (str(msg.child_frame_id) if hasattr(msg, "child_frame_id") else None)


__all__ = [
    "decode_image",
    "decode_compressed_image",
    "decode_camera_info",
    "decode_pose",
    "transform_to_matrix",
    "header_stamp",
    "frame_ids",
    "IMAGE_ENCODINGS",
    "InvalidPoseError",
]
