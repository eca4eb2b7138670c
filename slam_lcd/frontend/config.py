"""Configuration section `frontend` (owned by :mod:`slam_lcd.frontend`)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass
class FrontendConfig:
    pass
