"""slam_lcd.lcd: loop-closure detection and verification (BoW candidates, graph verification, RANSAC, metric pose).
Its evaluation (precision-recall, NEES) lives beside trajectory evaluation in :mod:`slam_lcd.eval`.
May import: vision, vocab, features and the base modules; never io or sensors (frames come in as arrays).

Public API (docs/CONTRACTS.md): :func:`verify_graph` -> :class:`GraphVerdict`,
:func:`estimate_loop_pose` -> :class:`PoseVerdict`, :func:`verify_epipolar`,
:class:`LoopDetector` (``add(keyframe) -> list[LoopClosure]``, ``records``).

Names are imported on first use (PEP 562): the configuration imports this package, and a
command that needs none of these must not pay numpy, scipy or OpenCV for them.
"""
from __future__ import annotations

from ..runtime.lazy_names import lazy_getattr
from .config import LcdConfig

_LAZY = {
    "VERIFY_MODES": ".detector",
    "CandidateRecord": ".detector",
    "LoopDetector": ".detector",
    "EpipolarVerdict": ".geometry",
    "PoseVerdict": ".geometry",
    "estimate_loop_pose": ".geometry",
    "keyframe_points3d": ".geometry",
    "verify_epipolar": ".geometry",
    "GraphVerdict": ".graph",
    "planar_graph": ".graph",
    "verify_graph": ".graph",
    "TemporalConsistency": ".temporal",
}

__all__ = ["LcdConfig", *_LAZY]

__getattr__ = lazy_getattr(__name__, _LAZY, globals())
