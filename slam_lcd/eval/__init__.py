"""slam_lcd.eval: trajectory evaluation (association, alignment: the one Umeyama, ATE, RPE, plots) and loop
evaluation (precision-recall and recall measures: :mod:`.loop_detection`; NEES of loop information: :mod:`.nees`).
May import: numpy, matplotlib (plots, on demand), the base modules and files; lcd for its loop records; never
io (files are read by io and sensors) nor sim (the NEES of the demo world's loops is
:func:`slam_lcd.sim.keyframes.demo_loop_nees`).

A pure library: functions take :class:`slam_lcd.types.Trajectory` objects (or a detector's records) and
return result dataclasses; reading trajectory files lives in :mod:`slam_lcd.io.trajectory_files`, figures in
:mod:`slam_lcd.eval.plots` (imported on demand, so matplotlib is not loaded here). The loop modules are not
imported here: they bring the loop detector's modules, which trajectory evaluation does not need.

Names are imported on first use (PEP 562): the configuration imports this package, and a
command that needs none of these must not pay numpy, scipy or OpenCV for them.
"""
from __future__ import annotations

from ..runtime.lazy_names import lazy_getattr

_LAZY = {
    "ALIGN_MODES": ".align",
    "Alignment": ".align",
    "align_mode_from_flags": ".align",
    "fit_alignment": ".align",
    "umeyama": ".align",
    "associate": ".associate",
    "associate_indices": ".associate",
    "AlignmentError": ".errors",
    "AssociationError": ".errors",
    "AteResult": ".metrics",
    "ErrorStats": ".metrics",
    "RpeResult": ".metrics",
    "ate": ".metrics",
    "ate_before_after": ".metrics",
    "ate_with_config": ".metrics",
    "rotation_angle_deg": ".metrics",
    "rpe": ".metrics",
}

__all__ = [*_LAZY]

__getattr__ = lazy_getattr(__name__, _LAZY, globals())
