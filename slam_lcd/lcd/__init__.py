"""slam_lcd.lcd: loop-closure detection and verification (BoW candidates, graph verification, RANSAC, metric pose).
Its evaluation (precision-recall, NEES) lives beside trajectory evaluation in :mod:`slam_lcd.eval`.
May import: vision, vocab, features and the base modules; never io or sensors (frames come in as arrays).

Public API (docs/CONTRACTS.md): :func:`verify_graph` -> :class:`GraphVerdict`,
:func:`estimate_loop_pose` -> :class:`PoseVerdict`, :func:`verify_epipolar`,
:class:`LoopDetector` (``add(keyframe) -> list[LoopClosure]``, ``records``).
"""
from .config import LcdConfig
from .detector import VERIFY_MODES, CandidateRecord, LoopDetector
from .geometry import EpipolarVerdict, PoseVerdict, estimate_loop_pose, keyframe_points3d, verify_epipolar
from .graph import GraphVerdict, planar_graph, verify_graph
from .temporal import TemporalConsistency

__all__ = [
    "LcdConfig", "VERIFY_MODES", "CandidateRecord", "LoopDetector", "EpipolarVerdict", "PoseVerdict",
    "estimate_loop_pose", "keyframe_points3d", "verify_epipolar", "GraphVerdict",
    "planar_graph", "verify_graph", "TemporalConsistency",
]
