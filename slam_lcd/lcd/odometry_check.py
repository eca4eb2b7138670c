"""Does a loop's relative pose agree with the odometry between its two keyframes, within drift?

Why: a loop accepted on little evidence (the tight-pose rule, fewer PnP inliers than
``pnp_min_inliers``) can be a look-alike place that is geometrically self-consistent: on the
10-lap demo log two such loops were tight by every measure of the pose and 90 deg / 8.3 m away
from where the odometry put the match. Odometry cannot say where a *true* revisit is after a
long drift, but it bounds how far the loop may disagree with it: a visual or wheel odometry
drifts by a few percent of the distance travelled (the KITTI odometry benchmark measures
translation error as a percentage of the path; wheel odometry 1-5 %) and a bounded number of
degrees per metre. Only the low-evidence loops are held to this bound (RTAB-Map and
Kimera-RPGO reject loops against odometry in the back end; here it is the detector's own
guard for the loops it accepts on a relaxed rule), so a first revisit after any drift is still
accepted on full evidence.

The disagreement ``D = T_odom^-1 T_loop`` is measured both ways (the translation of ``D`` and
of its inverse seen from the other keyframe differ), and the larger is used, so swapping query
and match gives the same verdict.
"""
from __future__ import annotations

import numpy as np

from ..geometry import inv, rotation_angle_deg
from .config import LcdConfig


def odometry_disagreement(T_match_query: np.ndarray, T_world_match: np.ndarray,
                          T_world_query: np.ndarray) -> tuple[float, float]:
    """(translation m, rotation deg) between a loop's ``T_match_query`` and the odometry's (larger of both ways)."""
    T_odom = inv(np.asarray(T_world_match, float)) @ np.asarray(T_world_query, float)
    D = inv(T_odom) @ np.asarray(T_match_query, float)
    D_other = T_odom @ inv(np.asarray(T_match_query, float))  # the same disagreement from the query's side
    t = max(float(np.linalg.norm(D[:3, 3])), float(np.linalg.norm(D_other[:3, 3])))
    return t, rotation_angle_deg(D)


def drift_budget(path_m: float, conf: LcdConfig) -> tuple[float, float]:
    """(translation m, rotation deg) the odometry may have drifted over ``path_m`` metres of travel."""
    path_m = abs(float(path_m))
    return (conf.odometry_drift_floor_m + conf.odometry_max_drift * path_m,
            conf.odometry_drift_floor_deg + conf.odometry_max_drift_deg_per_m * path_m)


def odometry_drift_reason(T_match_query: np.ndarray, T_world_match: np.ndarray, T_world_query: np.ndarray,
                          path_m: float, conf: LcdConfig) -> tuple[str, dict]:
    """('' when the loop agrees with odometry within the drift budget, else why not; the figures)."""
    t, r = odometry_disagreement(T_match_query, T_world_match, T_world_query)
    bt, br = drift_budget(path_m, conf)
    figures = {"odometry_disagreement_m": round(t, 4), "odometry_disagreement_deg": round(r, 3),
               "odometry_path_m": round(abs(float(path_m)), 3)}
    if not (np.isfinite(t) and np.isfinite(r)):
        return "odometry_unknown", figures
    if t > bt or r > br:
        return "odometry_disagrees", figures
    return "", figures
