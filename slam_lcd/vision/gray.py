"""The grey conversion of slam-lcd: colour to grey with OpenCV's RGB weights, and the scaling of each image kind.

- :func:`to_gray_float`: float32 in [0, 1], what SuperPoint takes (uint8 / 255, uint16 / 65535);
- :func:`to_gray_uint8`: uint8, what ORB, Lucas-Kanade and stereo matching take;
- :func:`image_to_gray`: a camera image decoded from a log (uint8 as it is; a 16-bit or
  float mono image is stretched from its own minimum to its maximum, since such cameras
  rarely fill the 16-bit range).
"""
from __future__ import annotations

import cv2
import numpy as np

from ..errors import InputError, MessageEncodingError


def to_gray_float(image: np.ndarray) -> np.ndarray:
    """uint8/uint16 gray or RGB, or float gray in [0, 1] -> float32 H x W in [0, 1]."""
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3 and img.shape[2] in (3, 4):
        if img.dtype == np.uint8:
            img = cv2.cvtColor(img[:, :, :3], cv2.COLOR_RGB2GRAY)
        else:
            img = img[:, :, :3].astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)
    if img.ndim != 2:
        raise InputError(f"expected a grayscale or RGB image, got an array of shape {img.shape}")
    if img.dtype == np.uint8:
        return img.astype(np.float32) * (1.0 / 255.0)
    if img.dtype == np.uint16:
        return img.astype(np.float32) * (1.0 / 65535.0)
    if np.issubdtype(img.dtype, np.floating):
        return np.ascontiguousarray(img, dtype=np.float32)
    raise InputError(f"unsupported image dtype {img.dtype}")


def to_gray_uint8(image: np.ndarray) -> np.ndarray:
    """uint8 H x W: uint8 images as they are (colour through OpenCV's RGB weights), others via :func:`to_gray_float`."""
    img = np.asarray(image)
    if img.dtype == np.uint8 and img.ndim == 2:
        return img
    if img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 1:
        return img[:, :, 0]
    if img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] in (3, 4):
        return cv2.cvtColor(img[:, :, :3], cv2.COLOR_RGB2GRAY)  # what to_gray_float rounds back to
    g = to_gray_float(img)
    return np.clip(g * 255.0 + 0.5, 0, 255).astype(np.uint8)


def image_to_gray(img: np.ndarray) -> np.ndarray:
    """uint8 HxW gray of an RGB or gray image (uint16 and float images are min-max scaled)."""
    img = np.asarray(img)
    if img.ndim == 3:
        if img.dtype != np.uint8:
            raise MessageEncodingError(f"colour image of dtype {img.dtype} cannot be made gray")
        return to_gray_uint8(img)
    if img.dtype == np.uint8:
        return img
    f = img.astype(np.float32)
    finite = np.isfinite(f)
    if not finite.any():
        return np.zeros(img.shape, np.uint8)
    lo, hi = float(f[finite].min()), float(f[finite].max())
    out = np.zeros(img.shape, np.uint8)
    if hi > lo:
        out[finite] = np.clip(np.rint((f[finite] - lo) * (255.0 / (hi - lo))), 0, 255).astype(np.uint8)
    return out
