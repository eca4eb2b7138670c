"""Multi-session maps: several logs of one place joined into one map, saved, and localised against.

Owns the persistent map folder (format, sessions, anchors, locking), the joint pose graph of
all sessions and localisation against a fixed map. May import ``vocab``, ``lcd``, ``backend``,
``features`` and the shared types; never ``io``, ``outputs`` or ``cli``.
"""
from __future__ import annotations

from .config import MapConfig

__all__ = ["MapConfig"]
