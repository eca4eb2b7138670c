"""Configuration section `eval` (owned by :mod:`slam_lcd.eval`)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass
class EvalConfig:
    pass
