"""slam_lcd.backend: the GTSAM iSAM2 pose graph, robust loop handling (gates, GNC re-check), full-rate correction,
g2o files.
May import: gtsam and the base modules (types, errors, geometry, atomic); never io, sensors or another stage.

Public API (see docs/CONTRACTS.md and docs/backend.md):

- :class:`PoseGraph` (``add_keyframe``, ``add_loop``, ``estimate``, ``keyframe_trajectory``,
  ``loop_records``, ``finalize``, ``write_g2o``) and :class:`LoopRecord`;
- :func:`correct_full_rate` (corrected pose for every odometry stamp);
- :func:`read_g2o` / :func:`write_g2o`.

Names are imported lazily so that ``slam_lcd.config`` (which imports
``slam_lcd.backend.config``) does not pull in GTSAM.
"""
from __future__ import annotations

from ..runtime.lazy_names import lazy_getattr

_EXPORTS = {
    "PoseGraph": ".pose_graph",
    "LoopRecord": ".records",
    "robust_kernel": ".loop_factors",
    "between_factor": ".loop_factors",
    "between_factors": ".loop_factors",
    "PcmGate": ".gate",
    "Chi2Gate": ".gate",
    "AcceptAllGate": ".gate",
    "GateLoop": ".gate",
    "MarginalRelatives": ".relatives",
    "correct_full_rate": ".full_rate",
    "read_g2o": ".g2o",
    "write_g2o": ".g2o",
    "G2oEdge": ".g2o",
    "BackendConfig": ".config",
}

__all__ = sorted(_EXPORTS)


__getattr__ = lazy_getattr(__name__, _EXPORTS, globals())
