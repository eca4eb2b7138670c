"""ORB for tracking: detection again with a lower FAST threshold when a frame gives too few corners.

ORB keeps the strongest ``orb_n_features`` corners that pass its FAST threshold. On a well-lit,
textured frame the usual threshold (20) passes plenty and a lower one would only add weak,
less repeatable corners (the TUM layout at 640x480 tracks less accurately with 7 throughout);
on a dim, low-contrast or small frame it passes too few to track (the EuRoC layout's turns
towards a plain wall at 320x240 give 60-250). So a frame is detected again with
``vo_orb_fallback_fast_threshold`` when the first pass gives fewer than
``vo_orb_fallback_below`` of ``vo_max_features``.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..features.config import FeaturesConfig
from ..features.extract import OrbExtractor
from ..types import Features


class TrackingOrbExtractor(OrbExtractor):
    """:class:`~slam_lcd.features.extract.OrbExtractor` with a second pass at a lower FAST threshold."""

    def __init__(self, conf: FeaturesConfig, fallback_fast_threshold: int, fallback_below: float):
        super().__init__(conf)
        self.fallback = OrbExtractor(dataclasses.replace(conf, orb_fast_threshold=fallback_fast_threshold))
        self.fallback_below = float(fallback_below)
        self.min_features = int(np.ceil(fallback_below * conf.orb_n_features))

    def identity(self) -> dict:
        return {**super().identity(), "fallback_fast_threshold": self.fallback.conf.orb_fast_threshold,
                "fallback_below": self.fallback_below}

    def extract(self, image: np.ndarray) -> Features:
        feats = super().extract(image)
        if len(feats) >= self.min_features:
            return feats
        return self.fallback.extract(image)
