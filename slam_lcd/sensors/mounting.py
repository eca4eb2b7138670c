"""Where the camera sits on the body: one rule for the visual-odometry pass and the main pass.

``T_body_camera`` comes from the config when set, else from the log's static transforms
(read first, so the answer does not depend on message order), else identity; the rule
itself is :func:`slam_lcd.frontend.camera.camera_mounting`. The body frame is the
odometry's child frame when the log has an odometry topic.
"""
from __future__ import annotations

import numpy as np

from ..frontend.camera import camera_mounting
from ..io.tf import TfBuffer
from .messages import at_message
from .topics import static_tf_topics


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
