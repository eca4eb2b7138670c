"""Configuration section `features` (owned by :mod:`slam_lcd.features`)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass
class FeaturesConfig:
    pass
