"""Whole-graph solvers for pose graphs read from g2o: batch LM, GNC, iSAM2 fed edge by edge.

Used to check the optimiser on standard graphs (``sphere2500``) and by the benchmark.
"""
from __future__ import annotations

import time

import gtsam
import numpy as np

from slam_lcd.backend.config import BackendConfig
from slam_lcd.backend.g2o import G2oEdge, chain_initial_estimate
from slam_lcd.backend.pose_graph import isam2_params


def between_factor(e: G2oEdge) -> gtsam.BetweenFactorPose3:
    return gtsam.BetweenFactorPose3(e.i, e.j, gtsam.Pose3(e.T_i_j),
                                    gtsam.noiseModel.Gaussian.Information(e.information))


def prior_factor(key: int, T: np.ndarray, sigma: float = 1e-4) -> gtsam.PriorFactorPose3:
    return gtsam.PriorFactorPose3(key, gtsam.Pose3(T), gtsam.noiseModel.Isotropic.Sigma(6, sigma))


def to_values(poses: dict[int, np.ndarray]) -> gtsam.Values:
    v = gtsam.Values()
    for k, T in poses.items():
        v.insert(int(k), gtsam.Pose3(T))
    return v


def from_values(values: gtsam.Values) -> dict[int, np.ndarray]:
    flat = np.asarray(gtsam.utilities.extractPose3(values))
    out = {}
    for row, k in zip(flat, values.keys(), strict=True):
        T = np.eye(4)
        T[:3, :3] = row[:9].reshape(3, 3)
        T[:3, 3] = row[9:12]
        out[int(k)] = T
    return out


def batch_graph(edges: list[G2oEdge], anchor: int, T_anchor: np.ndarray) -> gtsam.NonlinearFactorGraph:
    g = gtsam.NonlinearFactorGraph()
    g.add(prior_factor(anchor, T_anchor))
    for e in edges:
        g.add(between_factor(e))
    return g


def solve_lm(
    graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values, max_iterations: int = 100
) -> tuple[gtsam.Values, float]:
    """Plain batch Levenberg-Marquardt; returns (values, seconds)."""
    p = gtsam.LevenbergMarquardtParams()
    p.setMaxIterations(max_iterations)
    t0 = time.perf_counter()
    out = gtsam.LevenbergMarquardtOptimizer(graph, initial, p).optimize()
    return out, time.perf_counter() - t0


def solve_gnc(
    graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values, known_inliers: list[int], probability: float = 0.99
) -> tuple[gtsam.Values, np.ndarray, float]:
    """Batch GNC with truncated least squares; returns (values, weights, seconds)."""
    p = gtsam.GncLMParams()
    p.setLossType(gtsam.GncLossType.TLS)
    p.setKnownInliers(list(known_inliers))
    t0 = time.perf_counter()
    gnc = gtsam.GncLMOptimizer(graph, initial, p)
    gnc.setInlierCostThresholdsAtProbability(probability)
    out = gnc.optimize()
    return out, np.asarray(gnc.getWeights()), time.perf_counter() - t0


def isam2_edge_by_edge(
    edges: list[G2oEdge], conf: BackendConfig | None = None, first: int = 0, n_poses: int | None = None,
    final_updates: int = 3,
) -> tuple[dict[int, np.ndarray], list[float]]:
    """Feed a g2o graph into iSAM2 one pose at a time (its odometry edge + the loops closing at it).

    Poses are initialised by composing the odometry edge onto the current estimate of the
    previous pose. ``n_poses`` stops after that many poses (a prefix of the graph); ``final_updates``
    extra iSAM2 iterations run at the end.
    Returns (estimate id -> 4x4, seconds per update).
    """
    conf = conf or BackendConfig()
    isam = gtsam.ISAM2(isam2_params(conf))
    by_last: dict[int, list[G2oEdge]] = {}
    for e in edges:
        by_last.setdefault(max(e.i, e.j), []).append(e)
    odo = {e.j: e for e in edges if e.j == e.i + 1}
    g = gtsam.NonlinearFactorGraph()
    g.add(prior_factor(first, np.eye(4)))
    v = gtsam.Values()
    v.insert(first, gtsam.Pose3())
    isam.update(g, v)
    times = []
    k = first + 1
    last = max(by_last) if n_poses is None else first + n_poses - 1
    while k <= last and k in odo:
        g = gtsam.NonlinearFactorGraph()
        for e in by_last.get(k, ()):
            g.add(between_factor(e))
        v = gtsam.Values()
        v.insert(k, isam.calculateEstimatePose3(k - 1).compose(gtsam.Pose3(odo[k].T_i_j)))
        t0 = time.perf_counter()
        isam.update(g, v)
        times.append(time.perf_counter() - t0)
        k += 1
    for _ in range(final_updates):
        isam.update()
    return from_values(isam.calculateEstimate()), times


def initial_from_odometry(edges: list[G2oEdge], first: int = 0) -> dict[int, np.ndarray]:
    return chain_initial_estimate(edges, first)


def translation_rmse(est: dict[int, np.ndarray], ref: dict[int, np.ndarray]) -> float:
    """RMSE of positions over common ids (no alignment: both graphs anchor the same first pose)."""
    ids = sorted(set(est) & set(ref))
    d = np.array([est[i][:3, 3] - ref[i][:3, 3] for i in ids])
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
