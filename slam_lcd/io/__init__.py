"""slam_lcd.io: read ROS1 bags, rosbag2 directories and MCAP files; decode messages; trajectory files; write new logs.
May import: rosbags, mcap and the base modules (types, errors, geometry, atomic); never a stage, sensors or outputs.

See docs/io.md. Public API: :func:`open_log`, :class:`LogMessage`, :class:`TopicInfo`,
:func:`read_trajectory_from_log`, :mod:`.decode`, :mod:`.tf`, :mod:`.message_builders`, :mod:`.writers`,
and the trajectory-file functions of :mod:`.trajectory_files`.
"""
from . import trajectory_files as _tf_files
from .log_trajectory import read_trajectory_from_log
from .reader import LogMessage, LogReader, RawMessage, TopicInfo, open_log
from .trajectory_files import *  # noqa: F403

__all__ = ["open_log", "LogReader", "LogMessage", "RawMessage", "TopicInfo", "read_trajectory_from_log",
           *_tf_files.__all__]
