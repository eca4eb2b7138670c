"""slam_lcd.features: SuperPoint (and an ORB baseline) behind one extractor interface.

Also the weights, the feature cache and matching.
May import: torch, cv2, vision.gray and the base modules; never io or another stage.

``load_extractor(conf, weights=..., device=...)`` returns an :class:`Extractor` whose
``extract(image)`` gives a :class:`slam_lcd.types.Features` record.

Names are imported lazily (PEP 562): importing the configuration, or running a CLI command
that needs no network (``slam-lcd info``), must not pay torch's import time.
"""
from __future__ import annotations

from ..runtime.lazy_names import lazy_getattr
from .config import FeaturesConfig

_LAZY = {
    "FeatureCache": ".cache",
    "Extractor": ".extract",
    "OrbExtractor": ".extract",
    "SuperPointExtractor": ".superpoint_extractor",
    "load_extractor": ".loading",
    "SuperPoint": ".superpoint",
    "resolve_weights": ".weights",
}

__all__ = ["FeaturesConfig", *_LAZY]


__getattr__ = lazy_getattr(__name__, _LAZY, globals())
