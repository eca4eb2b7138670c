"""The names of the trajectory file formats (TUM, KITTI, EuRoC CSV), as a plain tuple.

Why apart from :mod:`.trajectory_files`, which reads and writes them: ``slam-lcd ate`` and
``slam-lcd export`` offer these names as choices when their parsers are built, for every
command and ``--help``, without loading numpy or scipy.
"""
from __future__ import annotations

FORMATS = ("tum", "kitti", "euroc")
