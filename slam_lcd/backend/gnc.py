"""Batch GNC (truncated least squares) re-check of loop factors, leaving every other factor alone.

Why separate: the re-check is a pure function of (factors that are known inliers, candidate
loop factors, a starting estimate) -> one weight per candidate loop. The caller decides what
to do with the weights (:class:`~slam_lcd.backend.pose_graph.PoseGraph` removes the outliers
it added from iSAM2 and restores inliers); the known-inlier factors, which may be a user's
IMU, GPS or odometry factors, are never weighted, removed or changed.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import gtsam
import numpy as np

from .poses import lm_params


@dataclass
class GncResult:
    weights: np.ndarray  # (L,) one per candidate loop, 1 inlier .. 0 outlier
    values: gtsam.Values  # GNC's solution
    residual_chi2: np.ndarray  # (L,) whitened squared residual of each loop (Gaussian) at the solution


def gnc_loop_weights(known: gtsam.NonlinearFactorGraph, loops: Sequence, initial: gtsam.Values, *,
                     inlier_probability: float = 0.99, max_iterations: int = 100,
                     gaussian_loops: Sequence | None = None, qr: bool = False) -> GncResult:
    """GNC-TLS over ``known`` (all known inliers) + ``loops``; weights of the loop factors.

    ``gaussian_loops`` (same length as ``loops``): the loops without robust kernel, for the
    residual figures (default: ``loops``). A ``known`` graph may contain null slots (removed
    iSAM2 factors); they are skipped. ``qr``: QR factorisation (:func:`.poses.lm_params`).
    """
    graph = gtsam.NonlinearFactorGraph()
    for i in range(known.size()):
        f = known.at(i)
        if f is not None:
            graph.push_back(f)
    n_known = graph.size()
    for f in loops:
        graph.push_back(f)
    params = gtsam.GncLMParams(lm_params(qr)) if qr else gtsam.GncLMParams()
    params.setLossType(gtsam.GncLossType.TLS)
    params.setKnownInliers(list(range(n_known)))
    if max_iterations != 100:  # GTSAM prints a warning when it is changed
        params.setMaxIterations(int(max_iterations))
    gnc = gtsam.GncLMOptimizer(graph, initial, params)
    gnc.setInlierCostThresholdsAtProbability(inlier_probability)
    values = gnc.optimize()
    w = np.asarray(gnc.getWeights(), dtype=np.float64)[n_known:]
    plain = gaussian_loops if gaussian_loops is not None else loops
    chi2 = np.array([2.0 * f.error(values) for f in plain], dtype=np.float64)
    return GncResult(w, values, chi2)
