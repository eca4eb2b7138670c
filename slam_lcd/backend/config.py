"""Configuration section `backend` (owned by :mod:`slam_lcd.backend`)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass
class BackendConfig:
    pass
