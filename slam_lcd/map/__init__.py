"""Multi-session maps: several logs of one place joined into one map, saved, and localised against.

Owns the persistent map folder (format, sessions, anchors, locking), the joint pose graph of
all sessions and localisation against a fixed map. May import ``vocab``, ``lcd``, ``backend``,
``features`` and the shared types; never ``io``, ``outputs`` or ``cli``.
"""
from __future__ import annotations

from .config import MapConfig


def __getattr__(name):  # the heavy parts (gtsam, the loop detector) load on first use
    if name in ("Map", "extractor_meta"):
        from . import session_map

        return getattr(session_map, name)
    if name in ("MapError", "MapLockedError", "LogAlreadyInMapError"):
        from . import store

        return getattr(store, name)
    raise AttributeError(name)


__all__ = ["LogAlreadyInMapError", "Map", "MapConfig", "MapError", "MapLockedError", "extractor_meta"]
