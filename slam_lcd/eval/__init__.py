"""slam_lcd.eval: trajectory evaluation (association, alignment: the one Umeyama, ATE, RPE, plots) and loop
evaluation (precision-recall and recall measures: :mod:`.loop_detection`; NEES of loop information: :mod:`.nees`).
May import: numpy, matplotlib (plots, on demand), the base modules and files; lcd for its loop records, sim (on
demand) for the NEES demo; never io (files are read by io and sensors).

A pure library: functions take :class:`slam_lcd.types.Trajectory` objects (or a detector's records) and
return result dataclasses; reading trajectory files lives in :mod:`slam_lcd.io.trajectory_files`, figures in
:mod:`slam_lcd.eval.plots` (imported on demand, so matplotlib is not loaded here). The loop modules are not
imported here: they bring the loop detector's modules, which trajectory evaluation does not need.
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
