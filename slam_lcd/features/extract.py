"""Extractors: numpy images in, :class:`slam_lcd.types.Features` out.

Every stage calls features through this one interface, so SuperPoint (learned, float
descriptors) and ORB (OpenCV, binary descriptors, the DBoW2-style baseline) can be
swapped by ``features.kind``. SuperPoint lives in :mod:`.superpoint_extractor`, imported
only when it is asked for: an ORB run (the offline fallback, the baseline, a batch of ORB
logs) does not pay torch's import (~3 s on a 2-core machine) in each process.
"""
from __future__ import annotations

import hashlib
import json
from abc import ABC, abstractmethod
from collections.abc import Iterable

import cv2
import numpy as np

from ..types import Features
from ..vision.gray import to_gray_uint8
from .config import FeaturesConfig
from .resize import downscale, to_full_resolution


class Extractor(ABC):
    """Common interface of every feature extractor."""

    kind: str = ""
    descriptor_dim: int = 0
    descriptor_dtype: type[np.generic] = np.float32

    def __init__(self, conf: FeaturesConfig):
        self.conf = conf

    @abstractmethod
    def extract(self, image: np.ndarray) -> Features:
        """Keypoints, scores and descriptors of one image (strongest first)."""

    def extract_batch(self, images: Iterable[np.ndarray]) -> list[Features]:
        return [self.extract(im) for im in images]

    def identity(self) -> dict:
        """What determines the output: used as the feature-cache key (device excluded)."""
        return {"kind": self.kind}

    @property
    def fingerprint(self) -> str:
        text = json.dumps(self.identity(), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


class OrbExtractor(Extractor):
    """OpenCV ORB (oriented FAST + rotated BRIEF): the classical DBoW2-style baseline."""

    kind = "orb"
    descriptor_dim = 32
    descriptor_dtype = np.uint8

    def __init__(self, conf: FeaturesConfig):
        super().__init__(conf)
        # OpenCV's stubs leave this factory out
        self.orb = cv2.ORB_create(  # type: ignore[attr-defined]
            nfeatures=conf.orb_n_features,
            scaleFactor=conf.orb_scale_factor,
            nlevels=conf.orb_n_levels,
            fastThreshold=conf.orb_fast_threshold,
        )

    def identity(self) -> dict:
        c = self.conf
        return {
            "kind": self.kind,
            "n_features": c.orb_n_features,
            "scale_factor": c.orb_scale_factor,
            "n_levels": c.orb_n_levels,
            "fast_threshold": c.orb_fast_threshold,
            "opencv": cv2.__version__,
            **({"resize_max": c.resize_max} if c.resize_max is not None else {}),
        }

    def extract(self, image: np.ndarray) -> Features:
        full = to_gray_uint8(image)
        gray = downscale(full, self.conf.resize_max)
        kps, desc = self.orb.detectAndCompute(gray, None)
        h, w = full.shape
        if desc is None or not kps:
            return Features(np.zeros((0, 2), np.float32), np.zeros(0, np.float32),
                            np.zeros((0, 32), np.uint8), (w, h), kind=self.kind)
        xy = to_full_resolution(np.array([k.pt for k in kps], np.float32), gray.shape[::-1], (w, h))
        scores = np.array([k.response for k in kps], np.float32)
        order = np.argsort(-scores, kind="stable")
        return Features(xy[order], scores[order], np.ascontiguousarray(desc[order]), (w, h), kind=self.kind)
