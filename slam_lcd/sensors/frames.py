"""Image sources for loop-detection evaluation from a log: the frames of an image topic, and any frame as a keyframe.

Frames become :class:`Keyframe` records numbered 0..N-1 in order (those positions index the
ground-truth loop matrix). An image folder is read by :func:`slam_lcd.io.image_folder.folder_frames`
(the one home of image-folder reading); its frames are the same :class:`~slam_lcd.io.image_folder.Frame`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import PipelineError
from ..io import open_log
from ..io.image_folder import Frame
from ..types import CameraModel, Keyframe
from .messages import at_message, decode_any_image, decode_camera_of


def log_frames(
    path: str | Path, topic: str, camera_info_topic: str | None = None
) -> tuple[list[str], list[int], list[Frame]]:
    """All frames of an image (or compressed image) topic of a bag/MCAP file, in time order."""
    frames: list[Frame] = []
    camera = None
    with open_log(path) as reader:
        topics = reader.resolve_topics([topic], flag="--image-topic")
        if camera_info_topic:
            camera_info_topic = reader.resolve_topics(
                [camera_info_topic], flag="--camera-info-topic",
                hint="leave --camera-info-topic out to take the intrinsics from --focal-factor")[0]
            topics.append(camera_info_topic)
        for m in reader.messages(topics):
            with at_message(m, reader.path, decoding=False):  # name the log, topic and stamp of a bad message
                if m.topic == camera_info_topic:
                    camera = decode_camera_of(m)
                    continue
                img = decode_any_image(m)
            frames.append(Frame(f"{m.stamp}", int(m.stamp), img, camera))
    if not frames:
        raise PipelineError(f"topic {topic!r} holds no images", path)
    return [f.name for f in frames], [f.stamp for f in frames], frames


def frame_to_keyframe(k: int, frame: Frame, camera: CameraModel | None) -> Keyframe:
    return Keyframe(id=k, stamp=frame.stamp, T_world_body=np.eye(4), image=frame.image,
                    camera=frame.camera or camera)
