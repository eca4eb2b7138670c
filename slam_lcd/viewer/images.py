"""Keyframe images for a recording: small thumbnails, read back from the run's log at the keyframes' stamps.

Why read from the log: a run folder holds no keyframe images (the loop pictures' album is
removed before the set is published), but ``report.json`` names the log and its image topic,
and ``keyframes_corrected.tum`` the keyframes' stamps, so ``slam-lcd view`` reads the image of
each keyframe from the log again (reading, not running anything again). Why a thumbnail
(at most :data:`IMAGE_WIDTH` pixels wide, a JPEG of ~3 kB): the recording shows them small,
and a long run's keyframes stay a few MB (the live recorder, :mod:`.live`, logs the same).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

IMAGE_WIDTH = 160
JPEG_QUALITY = 75
STAMP_TOLERANCE_NS = 1_000_000  # a keyframe's stamp in keyframes_corrected.tum (decimal seconds) vs its image's


def thumbnail(image: np.ndarray) -> tuple[np.ndarray, float]:
    """``image`` (grey or RGB, any dtype) at most :data:`IMAGE_WIDTH` wide as uint8, and the scale applied."""
    import cv2

    h, w = image.shape[:2]
    s = min(1.0, IMAGE_WIDTH / w)
    small = cv2.resize(image, (max(1, round(w * s)), max(1, round(h * s))), interpolation=cv2.INTER_AREA)
    if small.dtype != np.uint8:
        small = np.clip(small * (255.0 if small.max() <= 1.0 else 1.0), 0, 255).astype(np.uint8)
    return small, s


def jpeg(small: np.ndarray) -> bytes | None:
    """A thumbnail (RGB or grey) as JPEG bytes, or None when OpenCV cannot encode it."""
    import cv2

    bgr = cv2.cvtColor(small, cv2.COLOR_RGB2BGR) if small.ndim == 3 else small
    ok, data = cv2.imencode(".jpg", bgr, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    return data.tobytes() if ok else None


def read_keyframe_images(log_path: str | Path, topic: str, stamps,
                         stamp_source: str = "header") -> dict[int, np.ndarray]:
    """Thumbnails of the images of ``topic`` in ``log_path`` at the keyframe ``stamps`` (ns): keyframe
    stamp -> thumbnail, for each keyframe whose image is found within :data:`STAMP_TOLERANCE_NS`."""
    from ..io import open_log  # lazy: rosbags, mcap
    from ..sensors.messages import at_message, decode_any_image  # lazy: OpenCV

    want = np.unique(np.asarray(stamps, np.int64))
    found: dict[int, np.ndarray] = {}
    if not len(want):
        return found
    with open_log(log_path, stamp_source) as reader:
        names = reader.resolve_topics(topic, hint="the run's image topic is not in this log: give the log the run "
                                             "read with --log")
        for m in reader.messages(names):
            i = int(np.searchsorted(want, m.stamp))
            near = [j for j in (i - 1, i) if 0 <= j < len(want)]
            j = min(near, key=lambda k: abs(int(want[k]) - int(m.stamp)))
            key = int(want[j])
            if abs(key - int(m.stamp)) > STAMP_TOLERANCE_NS or key in found:
                continue
            with at_message(m, reader.path, decoding=False):
                found[key] = thumbnail(decode_any_image(m))[0]
            if len(found) == len(want):
                break
    return found
