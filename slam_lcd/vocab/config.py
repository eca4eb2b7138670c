"""Configuration section `vocab` (owned by :mod:`slam_lcd.vocab`)."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass
class VocabConfig:
    pass
