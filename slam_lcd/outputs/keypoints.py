"""``keyframe_keypoints.npz``: each keyframe's keypoints, kept compactly in the run folder for ``slam-lcd view``.

Why: the viewer shows a keyframe's image with the keypoints its loop detection used. The image
is read back from the log (:mod:`slam_lcd.viewer.images`), but the keypoints cannot be: reading
them again would mean running the feature extractor again. The loop detector keeps every
keyframe's keypoints anyway, so the run writes them as they are when it ends.

Why this form: pixel coordinates as ``uint16`` in quarter pixels (:data:`QUARTER`; 4 bytes a
keypoint, exact to 0.125 px, images up to 16,383 px wide), rows of all keyframes concatenated
with an offset per keyframe, deflated (:func:`slam_lcd.files.npz.write_npz`). On the demo log at 640x480
with ORB (670 keypoints per keyframe) that is 1.9 kB per keyframe; 1,000 keypoints spread over
the whole image take 3.3 kB, written in about 1.5 ms per keyframe.

Arrays: ``stamps`` (n,) int64 ns, ``offsets`` (n + 1,) int64, ``xy`` (K, 2) uint16.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..files.npz import write_npz

KEYPOINTS_FILE = "keyframe_keypoints.npz"
QUARTER = 4.0  # stored value = round(pixel * QUARTER)
LIMIT = np.iinfo(np.uint16).max / QUARTER


def keyframe_keypoints(pipe) -> tuple[np.ndarray, list[np.ndarray]]:
    """(stamps, keypoints per keyframe, (k, 2) float pixels) of a finished pipeline: what its loop detector kept."""
    stamps, kps = [], []
    for kf in pipe.keyframes:
        try:
            light = pipe.detector.stored(kf.id)[0]
            xy = np.asarray(light.features.keypoints, np.float32).reshape(-1, 2)
        except (KeyError, AttributeError):  # a keyframe the detector did not keep: none to show
            xy = np.zeros((0, 2), np.float32)
        stamps.append(int(kf.stamp))
        kps.append(xy)
    return np.array(stamps, np.int64), kps


def write_keyframe_keypoints(path: Path, stamps: np.ndarray, kps: list[np.ndarray]) -> None:
    """Write the keypoints (see the module docstring); keypoints outside [0, :data:`LIMIT`) are left out."""
    rows = [k[np.all((k >= 0) & (k < LIMIT), axis=1)] for k in kps]
    offsets = np.concatenate([[0], np.cumsum([len(r) for r in rows])]).astype(np.int64)
    xy = np.round(np.concatenate(rows) * QUARTER).astype(np.uint16) if rows else np.zeros((0, 2), np.uint16)
    with open(path, "wb") as fh:
        write_npz(fh, {"stamps": np.asarray(stamps, np.int64), "offsets": offsets, "xy": xy.reshape(-1, 2)})


def read_keyframe_keypoints(path: Path) -> dict[int, np.ndarray]:
    """Keyframe stamp (ns) -> (k, 2) float32 pixels, from a run folder's :data:`KEYPOINTS_FILE`."""
    try:
        with np.load(path, allow_pickle=False) as z:
            stamps, offsets, xy = z["stamps"], z["offsets"], z["xy"]
    except (OSError, KeyError, ValueError) as e:
        raise InputError(f"cannot be read as the run's keyframe keypoints ({e.__class__.__name__}: {e})", path) \
            from None
    if offsets.shape != (len(stamps) + 1,) or xy.ndim != 2 or (len(xy) and xy.shape[1] != 2) \
            or int(offsets[-1]) != len(xy):
        raise InputError("the run's keyframe keypoints do not fit together (damaged?)", path)
    pts = xy.astype(np.float32) / QUARTER
    return {int(s): pts[int(offsets[i]):int(offsets[i + 1])] for i, s in enumerate(stamps)}
