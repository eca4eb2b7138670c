"""``load_extractor``: the extractor ``features.kind`` names, SuperPoint imported only when chosen.

Its own module so that the extractors (:mod:`.extract`, :mod:`.superpoint_extractor`) never
import each other: SuperPoint alone needs torch (~3 s to import on a 2-core machine).
"""
from __future__ import annotations

from pathlib import Path

from ..errors import ConfigError
from .config import FeaturesConfig
from .extract import Extractor, OrbExtractor


def load_extractor(conf: FeaturesConfig | None = None, *, weights: str | Path | None = None,
                   device: str = "auto") -> Extractor:
    """Build the extractor named by ``conf.kind``.

    ``weights`` overrides ``conf.weights``; ``device`` overrides ``conf.device`` unless it is 'auto'.
    """
    conf = conf or FeaturesConfig()
    if conf.kind == "orb":
        return OrbExtractor(conf)
    if conf.kind == "superpoint":
        from .superpoint_extractor import SuperPointExtractor  # lazy: torch (ORB runs without it)

        return SuperPointExtractor(conf, weights=weights, device=device if device != "auto" else conf.device)
    raise ConfigError(f"features.kind must be 'superpoint' or 'orb', got {conf.kind!r}")
