"""Where a trajectory to evaluate comes from: a TUM/KITTI/EuRoC file or ``LOG:TOPIC``.

``LOG:TOPIC`` (``run.mcap:/odom``, ``data.bag:/groundtruth``) names a pose topic of a ROS1
bag, rosbag2 folder or MCAP file; the part before the first ``:`` that names an existing
path is the log. A TF frame pair is ``LOG:/tf:PARENT:CHILD`` (``run.bag:/tf:map:base_link``) or, as evo
spells it, ``LOG:/tf:PARENT.CHILD``.
Reading topics is delegated to :func:`slam_lcd.io.read_trajectory_from_log`.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import FileMissingError, InputError
from ..io import read_trajectory_from_log
from ..io.trajectory_files import read_trajectory
from ..types import Trajectory


def split_log_topic(spec: str) -> tuple[str, str] | None:
    """``(log, topic)`` when ``spec`` is ``LOG:TOPIC`` and not itself an existing file, else None."""
    if Path(spec).exists() or ":" not in spec:
        return None
    # prefer the split whose log part exists (paths may contain ':' themselves)
    positions = [i for i, c in enumerate(spec) if c == ":"]
    for i in positions:
        if Path(spec[:i]).exists() and spec[i + 1 :]:
            return spec[:i], spec[i + 1 :]
    i = positions[0]
    if spec[i + 1 :].startswith("/"):
        return spec[:i], spec[i + 1 :]
    return None


def load_trajectory_source(spec: str, fmt: str | None = None, times_path: str | None = None, *,
                           file_rotations: bool = False) -> Trajectory:
    """Read a trajectory from a file (format ``fmt`` or detected) or from ``LOG:TOPIC``
    (``file_rotations``: KITTI matrices as written, see :func:`slam_lcd.io.trajectory_files.read_kitti`)."""
    log_topic = split_log_topic(str(spec))
    if log_topic is None:
        if not Path(spec).exists():
            raise FileMissingError("trajectory file not found (give a trajectory file or LOG:TOPIC)", spec)
        return read_trajectory(spec, fmt, times_path=times_path, file_rotations=file_rotations)
    log, topic = log_topic
    if not Path(log).exists():
        raise FileMissingError("log not found (argument read as LOG:TOPIC)", log)
    reader = read_trajectory_from_log
    parts = topic.split(":")
    if len(parts) == 1:
        return reader(log, topic)
    if len(parts) == 2 and parts[1].count(".") == 1 and all(parts[1].split(".")):
        parent, child = parts[1].split(".")  # evo's spelling: /tf:PARENT.CHILD
        return reader(log, parts[0], parent_frame=parent, child_frame=child)
    if len(parts) == 3 and all(parts):
        return reader(log, parts[0], parent_frame=parts[1], child_frame=parts[2])
    raise InputError(f"cannot read {topic!r} as TOPIC or TOPIC:PARENT_FRAME:CHILD_FRAME", log)
