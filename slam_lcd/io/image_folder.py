"""Image folders as a source of frames: which files are frames, in which order, their stamps and pixels.

Why one module: ``vocab train`` and ``eval-lcd`` both read image folders, and both must agree on
what a frame is. A frame is a file with an image extension whose header an OpenCV decoder
recognises, in natural name order (``2.jpg`` before ``10.jpg``, TUM stamps numerically).
Ground-truth files kept beside the frames are never frames: a file passed as ground truth
(``exclude``) and any file whose name marks it as ground truth (``samples_GT.bmp``,
``groundtruth.png``, ``gt.png``: a ``GT`` word, or "groundtruth" / "ground_truth") are
left out. A file with an image extension that no decoder recognises is an error naming it,
not a silent skip: skipping would shift every later frame's index against a loop matrix.

Frames are numbered 0..N-1 in that order (the positions index the ground-truth loop matrix).
Stamps: a folder whose file stems are all numbers larger than 1e6 (TUM style seconds) uses
them; otherwise frames are spaced 1 s apart. One file is read by
:func:`slam_lcd.files.image_files.read_image`, which names a damaged or unreadable file.
"""
from __future__ import annotations

import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FileMissingError, InputError
from ..files.image_files import IMAGE_SUFFIXES, read_image
from ..types import CameraModel

# a 'GT' word in the stem (samples_GT, gt, loops-gt, GT_matrix), case-insensitive, or
# 'groundtruth' / 'ground_truth' / 'ground-truth' anywhere
_GT_WORD = re.compile(r"(?:^|[^a-z0-9])gt(?:$|[^a-z0-9])", re.IGNORECASE)
_GT_LONG = re.compile(r"ground[_\- ]?truth", re.IGNORECASE)


@dataclass
class Frame:
    """One frame of an image source (a folder here, an image topic of a log in
    :func:`slam_lcd.sensors.frames.log_frames`): its name, stamp in ns, pixels and camera when known."""

    name: str
    stamp: int
    image: np.ndarray
    camera: CameraModel | None = None


def natural_key(name: str):
    """Sort '2.jpg' before '10.jpg' (and timestamps numerically)."""
    parts = re.split(r"(\d+(?:\.\d+)?)", name)
    return [(0, float(t), "") if re.fullmatch(r"\d+(\.\d+)?", t) else (1, 0.0, t) for t in parts if t]


def is_ground_truth_name(path: str | Path) -> bool:
    """True for a file whose name says it is ground truth (``samples_GT.bmp``), not a frame."""
    stem = Path(path).stem
    return bool(_GT_WORD.search(stem) or _GT_LONG.search(stem))


def list_image_files(folder: str | Path, exclude: Iterable[str | Path | None] = ()) -> list[Path]:
    """The frames of ``folder`` in natural order (see the module docstring for what is left out)."""
    import cv2

    folder = Path(folder)
    if not folder.is_dir():
        raise FileMissingError("image folder not found", folder)
    skip = {Path(e).resolve() for e in exclude if e is not None}
    files = [p for p in folder.iterdir()
             if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES and p.resolve() not in skip
             and not is_ground_truth_name(p)]
    for p in files:
        if not cv2.haveImageReader(str(p)):
            raise InputError(f"has an image extension but no image decoder recognises its contents "
                             f"(move it out of the folder {folder})", p)
    files.sort(key=lambda p: natural_key(p.name))
    return files


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


def read_frame(path: str | Path):
    """One frame as eval-lcd's folder reader gives it (:func:`folder_frames`):
    the file's own channels, colour as RGB. Unreadable → InputError, damaged → DamagedImageError
    (:func:`slam_lcd.files.image_files.read_image`), each naming the file."""
    import cv2

    img = read_image(path, cv2.IMREAD_UNCHANGED)
    if img.ndim == 3:
        img = cv2.cvtColor(img[:, :, :3], cv2.COLOR_BGR2RGB)
    return img
