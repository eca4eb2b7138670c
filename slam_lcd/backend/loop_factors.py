"""Loop closures as GTSAM factors for any graph (the plugin's output side): many closures as one
graph, a closure between camera frames, closures as g2o edges.

One loop's factor, its noise model and the robust kernels live in :mod:`slam_lcd.loop_factor`
(a base module, so that :meth:`slam_lcd.types.LoopClosure.between_factor` imports nothing
above it); they are re-exported here, where the back end and plugin users import them.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable

import gtsam
import numpy as np

from ..errors import InputError
from ..geometry import adjoint, inv
from ..loop_factor import KERNELS as KERNELS  # re-exported: the back end's and users' names
from ..loop_factor import between_factor as between_factor
from ..loop_factor import loop_noise as loop_noise
from ..loop_factor import robust_kernel as robust_kernel
from ..loop_factor import valid_information as valid_information
from .g2o import G2oEdge


def between_factors(closures: Iterable, key: Callable[[int], int], *, kernel=None,
                    kernel_width: float = 3.0) -> gtsam.NonlinearFactorGraph:
    """A graph of :func:`between_factor` for many closures; ``key(kf_id)`` maps keyframe ids to GTSAM keys."""
    g = gtsam.NonlinearFactorGraph()
    for c in closures:
        g.add(between_factor(c, key(int(c.match_id)), key(int(c.query_id)), kernel=kernel, kernel_width=kernel_width))
    return g


def camera_frame_closure(T_match_query: np.ndarray, information: np.ndarray, T_body_camera: np.ndarray):
    """A body-frame loop expressed between camera frames (same ``T_body_camera`` on both keyframes).

    ``T_cm_cq = B^-1 T_mq B``; with right perturbations ``xi_body = Ad(B) xi_cam``, so
    ``Info_cam = Ad(B)^T Info_body Ad(B)``.
    """
    B = np.asarray(T_body_camera, dtype=np.float64)
    A = adjoint(B)
    return inv(B) @ np.asarray(T_match_query) @ B, A.T @ np.asarray(information) @ A


def closure_edges(closures: Iterable, vertex: Callable[[int], int] = int) -> list[G2oEdge]:
    """Closures as g2o edges (``vertex(kf_id)`` -> vertex id) for :func:`~slam_lcd.backend.g2o.write_g2o`."""
    edges = []
    for c in closures:
        if not valid_information(c.information):
            raise InputError(f"loop {c.match_id}->{c.query_id}: information is not positive definite")
        edges.append(G2oEdge(vertex(int(c.match_id)), vertex(int(c.query_id)), np.asarray(c.T_match_query, float),
                             np.asarray(c.information, float)))
    return edges
