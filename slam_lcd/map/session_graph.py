"""A map's graph in the forms its users take: loops for the joint solve, sessions' poses, a GTSAM graph.

Functions of the map's arrays (:class:`~slam_lcd.map.store.SessionKeyframes`,
:class:`~slam_lcd.map.store.MapGraph`), kept apart from :class:`~slam_lcd.map.session_map.Map` so
that the map object stays about opening, appending and saving.
"""
from __future__ import annotations

import numpy as np

from ..geometry import inv
from .contents import MapGraph, SessionKeyframes
from .joint_graph import JointLoop, SessionPoses


def existing_loops(sessions: list[SessionKeyframes], graph: MapGraph) -> list[JointLoop]:
    """Every loop the map holds (within and between sessions, visual links too), as the joint solve takes them."""
    sess_of = {int(k): si for si, s in enumerate(sessions) for k in s.ids}
    out = []
    for q, m_, T, info, acc, why in zip(graph.loop_query, graph.loop_match, graph.loop_T, graph.loop_info,
                                        graph.loop_accepted, graph.loop_reason, strict=True):
        inter = sess_of.get(int(q)) != sess_of.get(int(m_))
        out.append(JointLoop(int(q), int(m_), T, info, inter, bool(acc), str(why)))
    return out


def session_poses(table: list[dict], sessions: list[SessionKeyframes],
                  poses: dict[int, np.ndarray]) -> list[SessionPoses]:
    """Each session with its best-known poses (the map frame's where the map has them) and component."""
    out = []
    for meta, s in zip(table, sessions, strict=True):
        T = np.array([poses[int(k)] for k in s.ids]) if poses else s.T_odom.copy()
        out.append(SessionPoses(meta["name"], s.ids, s.T_odom, s.cov, T.reshape(-1, 4, 4), int(meta["component"])))
    return out


def factor_graph(sessions: list[SessionKeyframes], graph: MapGraph, poses: dict[int, np.ndarray], key=None):
    """(``gtsam.NonlinearFactorGraph``, ``gtsam.Values``) of a map: see :meth:`Map.factor_graph`."""
    import gtsam

    from .joint_graph import information_noise, odometry_covariance

    key = key or (lambda k: int(k))
    g, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for s in sessions:
        for i, k in enumerate(s.ids):
            values.insert(key(int(k)), gtsam.Pose3(poses.get(int(k), s.T_odom[i])))
            if i:
                g.add(gtsam.BetweenFactorPose3(key(int(s.ids[i - 1])), key(int(k)),
                                               gtsam.Pose3(inv(s.T_odom[i - 1]) @ s.T_odom[i]),
                                               gtsam.noiseModel.Gaussian.Covariance(odometry_covariance(s.cov[i]))))
    for q, mt, T, info, acc in zip(graph.loop_query, graph.loop_match, graph.loop_T, graph.loop_info,
                                   graph.loop_accepted, strict=True):
        if acc:
            g.add(gtsam.BetweenFactorPose3(key(int(mt)), key(int(q)), gtsam.Pose3(T), information_noise(info)))
    return g, values
