"""A map's graph in the forms its users take: loops for the joint solve, sessions' poses, a GTSAM graph.

Functions of the map's arrays (:class:`~slam_lcd.map.store.SessionKeyframes`,
:class:`~slam_lcd.map.store.MapGraph`), kept apart from :class:`~slam_lcd.map.session_map.Map` so
that the map object stays about opening, appending and saving.
"""
from __future__ import annotations

import numpy as np

from ..geometry import inv
from .config import MapConfig
from .contents import MapGraph, SessionKeyframes
from .joint_graph import JointLoop, SessionPoses, solve_lm
from .joint_types import is_link
from .session_factors import between, information_noise, odometry_covariance, odometry_factors

BUILTIN_VO = "visual odometry (built in)"  # a session's odometry source when slam-lcd's own VO made it


def odometry_independent(meta: dict) -> bool | None:
    """Whether a session's odometry is independent of its camera (the built-in VO is not; a topic: unknown)."""
    return False if meta.get("odometry_source") == BUILTIN_VO else None


def existing_loops(sessions: list[SessionKeyframes], graph: MapGraph) -> list[JointLoop]:
    """Every loop the map holds (within and between sessions, visual links too), as the joint solve takes them."""
    sess_of = {int(k): si for si, s in enumerate(sessions) for k in s.ids}
    out = []
    for q, m_, T, info, acc, why in zip(graph.loop_query, graph.loop_match, graph.loop_T, graph.loop_info,
                                        graph.loop_accepted, graph.loop_reason, strict=True):
        inter = sess_of.get(int(q)) != sess_of.get(int(m_))
        out.append(JointLoop(int(q), int(m_), T, info, inter, bool(acc), str(why)))
    return out


def loop_arrays(loops: list[JointLoop]) -> dict[str, np.ndarray]:
    """The graph file's loop arrays of ``loops`` (:func:`existing_loops` read back); a loop between sessions that
    GNC rejected is stored as not accepted."""
    return {"loop_query": np.array([lp.query for lp in loops], np.int64),
            "loop_match": np.array([lp.match for lp in loops], np.int64),
            "loop_T": np.array([lp.T for lp in loops], float).reshape(-1, 4, 4),
            "loop_info": np.array([lp.info for lp in loops], float).reshape(-1, 6, 6),
            "loop_accepted": np.array([lp.accepted and not (lp.inter and lp.reason.startswith("gnc")) for lp in loops],
                                      bool),
            "loop_reason": np.array([lp.reason for lp in loops], dtype="<U160")}


def own_estimate(s: SessionPoses, loops: list[JointLoop], conf: MapConfig | None = None) -> np.ndarray:
    """(n, 4, 4) a session's own estimate where the map did not record it: its odometry and its own accepted loops
    and links (``loops``: within the session), solved alone in its odometry frame (``conf``: the map's settings,
    for the allowance of modelled steps)."""
    import gtsam

    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for i, k in enumerate(s.ids):
        values.insert(int(k), gtsam.Pose3(s.T_odom[i]))
    for f in odometry_factors(s, conf or MapConfig()):
        graph.add(f)
    graph.add(gtsam.PriorFactorPose3(int(s.ids[0]), gtsam.Pose3(s.T_odom[0]),
                                     gtsam.noiseModel.Diagonal.Sigmas(np.full(6, 1e-6))))
    mine = [lp for lp in loops if lp.accepted and values.exists(int(lp.query)) and values.exists(int(lp.match))]
    if not mine:
        return np.asarray(s.T_odom, float).copy()
    for lp in mine:
        graph.add(between(lp))
    out = solve_lm(graph, values)
    return np.array([out.atPose3(int(k)).matrix() for k in s.ids])


def session_poses(table: list[dict], sessions: list[SessionKeyframes], poses: dict[int, np.ndarray],
                  loops: list[JointLoop] | None = None, conf: MapConfig | None = None,
                  folded: set[int] | frozenset[int] = frozenset()) -> list[SessionPoses]:
    """Each session with its best-known poses (the map frame's where the map has them), component, own estimate
    (recorded, else :func:`own_estimate` from ``loops``, the map's loops) and its keyframes in ``folded``."""
    out = []
    sess_of = {int(k): si for si, s in enumerate(sessions) for k in s.ids}
    own: dict[int, list[JointLoop]] = {}
    for lp in loops or []:
        if not lp.inter and sess_of.get(int(lp.query)) is not None:
            own.setdefault(sess_of[int(lp.query)], []).append(lp)
    for si, (meta, s) in enumerate(zip(table, sessions, strict=True)):
        T = np.array([poses[int(k)] for k in s.ids]) if poses else s.T_odom.copy()
        sp = SessionPoses(meta["name"], s.ids, s.T_odom, s.cov, T.reshape(-1, 4, 4), int(meta["component"]),
                          odometry_independent=odometry_independent(meta), cov_modelled=s.cov_modelled())
        sp.T_own = s.T_own if s.T_own is not None else own_estimate(sp, own.get(si, []), conf)
        if folded:
            sp.folded = np.isin(s.ids, list(folded))
        out.append(sp)
    return out


def factor_graph(table: list[dict], sessions: list[SessionKeyframes], graph: MapGraph, poses: dict[int, np.ndarray],
                 key=None, conf: MapConfig | None = None):
    """(``gtsam.NonlinearFactorGraph``, ``gtsam.Values``) of a map: see :meth:`Map.factor_graph`.

    The factors are the joint solve's: a session on the built-in visual odometry has its linked
    odometry steps and their links at half their information (:func:`slam_lcd.map.links.shared_weight`);
    keyframes folded out of the graph (:mod:`slam_lcd.map.fold`) have no variable, their folded factors
    stand in for their steps and loops."""
    import gtsam

    key = key or (lambda k: int(k))
    half = {int(k) for meta, s in zip(table, sessions, strict=True) if odometry_independent(meta) is False
            for k in s.ids}
    gone = graph.folded_ids()
    loops = [lp for lp in existing_loops(sessions, graph) if lp.accepted]
    linked = {max(int(lp.query), int(lp.match)) for lp in loops if is_link(lp)}  # consecutive ids: the later one
    g, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for s in sessions:
        modelled = s.cov_modelled()
        for i, k in enumerate(s.ids):
            if int(k) in gone:
                continue
            values.insert(key(int(k)), gtsam.Pose3(poses.get(int(k), s.T_odom[i])))
            if i and int(s.ids[i - 1]) not in gone:
                step = inv(s.T_odom[i - 1]) @ s.T_odom[i]
                cov = odometry_covariance(s.cov[i], bool(modelled[i]), step, conf)
                cov = cov * (2.0 if int(k) in half and int(k) in linked else 1.0)
                g.add(gtsam.BetweenFactorPose3(key(int(s.ids[i - 1])), key(int(k)), gtsam.Pose3(step),
                                               gtsam.noiseModel.Gaussian.Covariance(cov)))
    for lp in loops:
        w = 0.5 if is_link(lp) and int(lp.query) in half else 1.0
        g.add(gtsam.BetweenFactorPose3(key(int(lp.match)), key(int(lp.query)), gtsam.Pose3(lp.T),
                                       information_noise(lp.info, w)))
    return g, values
