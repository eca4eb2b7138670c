"""Where the camera sits on the body: one rule for the visual-odometry pass and the main pass.

``T_body_camera`` comes from the config (``frontend.T_body_camera``) when set, else from the
log's static transforms (read first, so the answer does not depend on message order),
else identity (:func:`camera_mounting`). The body frame is the odometry's child frame
when the log has an odometry topic.
"""
from __future__ import annotations

import logging

import numpy as np

from ..errors import SlamLcdError
from ..geometry import pose_from_list
from ..io.tf import TfBuffer
from .messages import at_message
from .topics import static_tf_topics

log = logging.getLogger(__name__)


def camera_mounting(conf, tf_buffer=None, camera_frame: str | None = None, stamp_ns: int = 0,
                    body_frame: str | None = None) -> np.ndarray:
    """``T_body_camera``: from the config when set, else from ``/tf_static``, else identity.

    The one camera-mounting rule of slam-lcd (the visual-odometry pass and the main pass
    both use it). ``tf_buffer`` is a :class:`~slam_lcd.io.tf.TfBuffer` (anything with
    ``lookup(parent, child, stamp_ns)``); the body frame is ``body_frame`` (the odometry's
    child frame, when there is an odometry topic), else ``conf.body_frame``; the camera
    frame is ``conf.camera_frame``, else ``camera_frame`` (the CameraInfo header's).
    """
    if conf.T_body_camera is not None:
        return pose_from_list(conf.T_body_camera)
    body = body_frame or conf.body_frame
    frame = conf.camera_frame or camera_frame
    if frame and body and frame == body:  # the camera is the body (e.g. odometry of the optical frame)
        return np.eye(4)
    if tf_buffer is not None and frame:
        try:
            return np.asarray(tf_buffer.lookup(body, frame, stamp_ns), dtype=np.float64)
        except (SlamLcdError, LookupError, ValueError) as e:  # no such frame: identity is the documented fallback
            log.warning("no transform %s -> %s in /tf_static (%s); using identity camera mounting",
                        body, frame, e)
    return np.eye(4)


def static_transforms(reader, log_path) -> TfBuffer:
    """A TF buffer holding the log's static transforms (tiny topics, read before streaming)."""
    tf = TfBuffer()
    static_topics = static_tf_topics(reader)
    for m in reader.messages(static_topics) if static_topics else ():
        with at_message(m, log_path):
            tf.add(m.msg, static=True)
    return tf


def body_frame_of(first_odometry_message) -> str | None:
    """The odometry's child frame (None without an odometry topic or when it is empty)."""
    m = first_odometry_message
    return (getattr(m.msg, "child_frame_id", None) or None) if m is not None else None


def mounting_from_camera_info(frontend_conf, tf: TfBuffer, camera_info_message, body_frame: str | None) -> np.ndarray:
    """``T_body_camera`` for the camera of a CameraInfo message (its header names the camera frame)."""
    m = camera_info_message
    return camera_mounting(frontend_conf, tf, m.msg.header.frame_id, m.stamp, body_frame=body_frame)


def calibrated_mounting(frontend_conf, calibrated_camera, tf: TfBuffer, body_frame: str | None) -> np.ndarray:
    """``T_body_camera`` of a camera from a calibration file: the config's when set, else the file's
    (Kalibr ``inv(T_cam_imu)``, EuRoC ``T_BS``: its body is taken as the odometry's body), else the
    ``/tf_static`` rule of :func:`camera_mounting`."""
    if frontend_conf.T_body_camera is None and calibrated_camera.T_body_camera is not None:
        return np.asarray(calibrated_camera.T_body_camera, dtype=np.float64)
    return camera_mounting(frontend_conf, tf, None, 0, body_frame=body_frame)
