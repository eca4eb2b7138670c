"""What a :class:`~slam_lcd.backend.pose_graph.PoseGraph` gives out: estimates, trajectories, g2o.

A mixin so the graph's bookkeeping module stays about iSAM2; it reads the graph's lists
(``_ids``, ``_keys``, ``_stamps``, ``_chain``, ``_loops``, ``_base_edges``) and ``_values()``.
"""
from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import gtsam
import numpy as np

from ..types import Trajectory
from .g2o import G2oEdge, write_g2o
from .poses import values_to_array
from .records import ACCEPTED

if TYPE_CHECKING:
    from .gate import ChainRelatives
    from .records import LoopEntry


class GraphOutputs:
    # set by PoseGraph (annotations only: no class attribute is created)
    _ids: list[int]
    _keys: list[int]
    _stamps: list[int]
    _chain: ChainRelatives
    _loops: list[LoopEntry]
    _base_edges: list[G2oEdge]
    _key_fn: Callable[[int], int] | None
    _user_graph: bool
    _values: Callable[[], gtsam.Values]

    def estimate(self) -> dict[int, np.ndarray]:
        """Current estimate: keyframe id -> corrected ``T_world_body`` (4x4)."""
        if not self._ids:
            return {}
        poses = self.estimate_array()
        return {kid: poses[k] for k, kid in enumerate(self._ids)}

    def estimate_array(self) -> np.ndarray:
        """(N, 4, 4) corrected poses in keyframe insertion order."""
        values = self._values()
        if self._key_fn is None and not self._user_graph:
            return values_to_array(values, len(self._ids))
        return np.array([values.atPose3(k).matrix() for k in self._keys]).reshape(-1, 4, 4)

    def current_values(self) -> gtsam.Values:
        return self._values()

    def odometry_values(self) -> gtsam.Values:
        """The keyframes' odometry poses as GTSAM Values (keys as in the graph)."""
        v = gtsam.Values()
        for k, key in enumerate(self._keys):
            v.insert(key, gtsam.Pose3(self._chain.pose(k)))
        return v

    def odometry_array(self) -> np.ndarray:
        return np.array([self._chain.pose(k) for k in range(len(self._chain))])

    def keyframe_trajectory(self) -> Trajectory:
        poses = self.estimate_array()
        stamps = np.asarray(self._stamps, dtype=np.int64)
        order = np.argsort(stamps, kind="stable")
        return Trajectory(stamps[order], poses[order])

    def write_g2o(self, path: str | Path, include_rejected: bool = False) -> None:
        """Current estimate + odometry + (accepted) loops as g2o; vertex ids are keyframe ids.

        On a user's graph there is no odometry of ours: the file holds the loops only.
        """
        est = self.estimate()
        ids = self._ids
        edges = [G2oEdge(ids[e.i], ids[e.j], e.T_i_j, e.information) for e in self._base_edges]
        for lp in self._loops:
            if include_rejected or lp.record.verdict == ACCEPTED:
                edges.append(G2oEdge(ids[lp.a], ids[lp.b], lp.Z, np.linalg.inv(lp.cov)))
        write_g2o(path, est, edges)
