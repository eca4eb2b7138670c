"""Configuration section `lcd` (owned by :mod:`slam_lcd.lcd`)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass
class LcdConfig:
    pass
