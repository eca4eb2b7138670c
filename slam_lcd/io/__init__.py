"""slam_lcd.io: read ROS1 bags, rosbag2 directories and MCAP files; decode messages; trajectory files; write new logs.
May import: rosbags, mcap and the base modules (types, errors, geometry, atomic); never a stage, sensors or outputs.

See docs/io.md. Public API: :func:`open_log`, :class:`LogMessage`, :class:`TopicInfo`,
:func:`read_trajectory_from_log`, :mod:`.decode`, :mod:`.tf`, :mod:`.message_builders`, :mod:`.writers`,
and the trajectory-file functions of :mod:`.trajectory_files`.

Names are imported on first use (PEP 562): the configuration imports this package, and a
command that needs none of these must not pay numpy, scipy or OpenCV for them.
"""
from __future__ import annotations

from ..runtime.lazy_names import lazy_getattr

_LAZY = {
    "read_trajectory_from_log": ".log_trajectory",
    "LogMessage": ".reader",
    "LogReader": ".reader",
    "RawMessage": ".reader",
    "TopicInfo": ".reader",
    "open_log": ".reader",
    "FORMATS": ".trajectory_formats",
    "detect_trajectory_format": ".trajectory_files",
    "read_euroc": ".trajectory_files",
    "read_kitti": ".trajectory_files",
    "read_kitti_times": ".trajectory_files",
    "read_trajectory": ".trajectory_files",
    "read_tum": ".trajectory_files",
    "write_euroc": ".trajectory_files",
    "write_kitti": ".trajectory_files",
    "write_trajectory": ".trajectory_files",
    "write_tum": ".trajectory_files",
}

__all__ = [*_LAZY]

__getattr__ = lazy_getattr(__name__, _LAZY, globals())
