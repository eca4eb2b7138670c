"""Configuration section `io` (owned by :mod:`slam_lcd.io`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..value_range import ranged


@dataclass
class IOConfig:
    # where a message's stamp comes from: its header (ROS convention) or the log's receive time
    stamp_source: Literal["header", "log_time"] = "header"
    # a truncated MCAP file (no footer): 'recover' reads what is readable and warns once, 'error' refuses it
    on_truncated: Literal["recover", "error"] = "recover"
    # chunk compression of MCAP files written by slam-lcd (single .mcap and rosbag2 mcap storage)
    mcap_compression: Literal["zstd", "lz4", "none"] = "zstd"
    # storage plugin of rosbag2 directories written by slam-lcd
    rosbag2_storage: Literal["mcap", "sqlite3"] = "mcap"
    # chunk compression of ROS1 bags written by slam-lcd
    rosbag1_compression: Literal["none", "lz4", "bz2"] = "none"
    # JPEG quality (0-100) of sensor_msgs/CompressedImage messages built by slam-lcd
    jpeg_quality: int = ranged(90, "[0, 100]")
    # how far (seconds) a TF lookup may reach past the first/last sample of a dynamic transform
    tf_extrapolation_s: float = ranged(0.0, "[0, inf)")
    # memory (MiB) for decompressed ROS1 bag chunks kept while streaming (bags whose chunks overlap in time)
    rosbag1_chunk_cache_mb: int = ranged(256, "[1, inf)")
