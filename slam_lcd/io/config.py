"""Configuration section `io` (owned by :mod:`slam_lcd.io`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass
class IOConfig:
    # where a message's stamp comes from: its header (ROS convention) or the log's receive time
    stamp_source: Literal["header", "log_time"] = "header"
