"""Image sources for loop-detection evaluation: an image folder or an image topic of a log.

Frames become :class:`Keyframe` records numbered 0..N-1 in order (those positions index the
ground-truth loop matrix). Stamps: a folder whose file stems are all numbers larger than
1e6 (TUM style seconds) uses them; otherwise frames are spaced 1 s apart.
"""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, PipelineError
from ..io import open_log
from ..io.image_folder import list_image_files, read_frame
from ..types import CameraModel, Keyframe
from .messages import at_message, decode_any_image, decode_camera_of


@dataclass
class Frame:
    name: str
    stamp: int
    image: np.ndarray
    camera: CameraModel | None = None


def folder_frames(folder: str | Path, exclude=()) -> tuple[list[str], list[int], Iterator[Frame]]:
    """Names, stamps and a lazy iterator of the frames of an image folder (``exclude``: files to skip)."""
    files = list_image_files(folder, exclude)
    if not files:
        raise InputError("no images (.png/.jpg/...) in folder", folder)
    try:
        secs = [float(p.stem) for p in files]
        use_stems = all(s > 1e6 for s in secs)
    except ValueError:
        use_stems = False

    stamps = [int(round(float(p.stem) * 1e9)) if use_stems else k * 1_000_000_000 for k, p in enumerate(files)]

    def gen():
        for k, p in enumerate(files):
            # damaged or unreadable: a one-line error naming it
            yield Frame(p.name, stamps[k], read_frame(p))

    return [p.name for p in files], stamps, gen()


def log_frames(
    path: str | Path, topic: str, camera_info_topic: str | None = None
) -> tuple[list[str], list[int], list[Frame]]:
    """All frames of an image (or compressed image) topic of a bag/MCAP file, in time order."""
    frames: list[Frame] = []
    camera = None
    with open_log(path) as reader:
        topics = [topic] + ([camera_info_topic] if camera_info_topic else [])
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
