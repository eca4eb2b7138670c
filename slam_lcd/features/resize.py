"""``features.resize_max``: extract on a smaller copy of the image, report keypoints in the image's own pixels.

Why: SuperPoint's cost grows with the pixel count (its first full-resolution convolutions are
most of it), and on a CPU without bfloat16 or int8 hardware a 640x480 forward is near what
float32 can do; choosing the resolution is what feature pipelines do instead (hloc's
``resize_max``, with the same meaning here: the longest side at most N pixels, the aspect
ratio kept, area interpolation, never enlarged).

The keypoints go back to full-resolution pixel coordinates, pixel centres on pixel centres
(hloc's ``(x + 0.5) * scale - 0.5``), so everything geometric downstream (the verification
graph, RANSAC, PnP, depth look-up, loop information) works on the camera's own pixels and
its calibration, unchanged.
"""
from __future__ import annotations

import cv2
import numpy as np

from ..errors import ConfigError


def resized_shape(height: int, width: int, resize_max: int | None) -> tuple[int, int]:
    """(height, width) an image of this size is extracted at: scaled so that its longest side
    is ``resize_max``, rounded to whole pixels; unchanged when it already fits or the knob is unset."""
    if resize_max is None or max(height, width) <= resize_max:
        return height, width
    if resize_max < 1:
        raise ConfigError(f"features.resize_max must be a positive number of pixels or null, got {resize_max}")
    scale = resize_max / max(height, width)
    return max(1, int(round(height * scale))), max(1, int(round(width * scale)))


def downscale(image: np.ndarray, resize_max: int | None) -> np.ndarray:
    """``image`` (H x W, any dtype OpenCV resizes) with its longest side at most ``resize_max``
    (area interpolation); the same array, untouched, when it already fits."""
    h, w = image.shape[:2]
    nh, nw = resized_shape(h, w, resize_max)
    if (nh, nw) == (h, w):
        return image
    return cv2.resize(image, (nw, nh), interpolation=cv2.INTER_AREA)


def to_full_resolution(keypoints: np.ndarray, small_size: tuple[int, int], full_size: tuple[int, int]) -> np.ndarray:
    """Keypoints (N x 2, x/y) found in a ``small_size`` (w, h) copy, in the pixels of the
    ``full_size`` (w, h) image: a small pixel's centre goes to the centre of the area it was
    averaged from. The same array when the sizes are equal (no arithmetic: bit for bit)."""
    if tuple(small_size) == tuple(full_size):
        return keypoints
    scale = np.array([full_size[0] / small_size[0], full_size[1] / small_size[1]], np.float32)
    return ((keypoints + np.float32(0.5)) * scale - np.float32(0.5)).astype(np.float32)
