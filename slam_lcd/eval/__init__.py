"""slam_lcd.eval: trajectory evaluation: association, alignment (the one Umeyama), ATE, RPE, plots.
May import: numpy, matplotlib (plots, on demand) and the base modules; never io (files are read by io and sensors).

A pure library: functions take :class:`slam_lcd.types.Trajectory` objects and return
result dataclasses; reading files lives in :mod:`slam_lcd.io.trajectory_files`, figures in
:mod:`slam_lcd.eval.plots` (imported on demand, so matplotlib is not loaded here).
"""
from .align import ALIGN_MODES, Alignment, align_mode_from_flags, fit_alignment, umeyama
from .associate import associate, associate_indices
from .errors import AlignmentError, AssociationError
from .metrics import (
    AteResult,
    ErrorStats,
    RpeResult,
    ate,
    ate_before_after,
    ate_with_config,
    rotation_angle_deg,
    rpe,
)

__all__ = [
    "ALIGN_MODES",
    "Alignment",
    "AlignmentError",
    "AssociationError",
    "AteResult",
    "ErrorStats",
    "RpeResult",
    "align_mode_from_flags",
    "associate",
    "associate_indices",
    "ate",
    "ate_before_after",
    "ate_with_config",
    "fit_alignment",
    "rotation_angle_deg",
    "rpe",
    "umeyama",
]
