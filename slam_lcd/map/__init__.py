"""Multi-session maps: several logs of one place joined into one map, saved, and localised against.

Owns the persistent map folder (format, sessions, anchors, locking), the joint pose graph of
all sessions and localisation against a fixed map. May import ``vocab``, ``lcd``, ``backend``,
``features`` and the shared types; never ``io``, ``outputs`` or ``cli``.
"""
from __future__ import annotations

from ..runtime.lazy_names import lazy_getattr
from .config import MapConfig

# the heavy parts (gtsam, the loop detector) load on first use
_LAZY = {
    "Map": ".session_map",
    "extractor_meta": ".session_map",
    "MapError": ".store",
    "MapLockedError": ".store",
    "LogAlreadyInMapError": ".store",
}

__all__ = ["LogAlreadyInMapError", "Map", "MapConfig", "MapError", "MapLockedError", "extractor_meta"]

__getattr__ = lazy_getattr(__name__, _LAZY, globals())
