"""The names of evo's pose relations (``-r/--pose_relation``), as plain tuples.

Why apart from :mod:`.relations`, which measures them: ``slam-lcd ate`` offers these names as
choices when its parser is built, for every command and ``--help``, without loading numpy or scipy.
"""
from __future__ import annotations

APE_RELATIONS = ("full", "trans_part", "rot_part", "angle_deg", "angle_rad", "point_distance")
RPE_RELATIONS = (*APE_RELATIONS, "point_distance_error_ratio")
