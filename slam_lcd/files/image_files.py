"""Reading one image file with one-line errors: unreadable and damaged files are told apart.

Why apart from :mod:`slam_lcd.io.image_folder` (which frames a folder holds, their order and
stamps): a ground-truth loop image is read the same way by modules that never read logs or folders.

``cv2.imread`` returns None for an unreadable file and decodes a truncated JPEG with a
grey bottom (libjpeg only prints a warning). :func:`read_image` reports both as typed
errors naming the file, with the decoder's own words in the message instead of on the
terminal (:mod:`slam_lcd.runtime.quiet`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import DamagedImageError, InputError
from ..runtime.quiet import native_stderr, one_line, quiet_opencv

# file endings read as images (frames of an image folder, ground-truth loop images)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff")


def read_image(path: str | Path, flags: int | None = None) -> np.ndarray:
    """``cv2.imread(path, flags)``; InputError if unreadable, DamagedImageError if decoded from damaged bytes."""
    import cv2

    quiet_opencv()
    if flags is None:
        flags = cv2.IMREAD_UNCHANGED
    with native_stderr() as cap:
        img = cv2.imread(str(path), flags)
    if img is None:
        said = f" ({one_line(cap.text)})" if cap.text else ""
        raise InputError(f"cannot read this image (not an image file, or damaged){said}", path)
    if cap.damage:
        raise DamagedImageError(f"image is damaged or truncated (decoder: {cap.damage})", path)
    return img
