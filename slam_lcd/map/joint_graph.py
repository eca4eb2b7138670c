"""The joint pose graph of every session of a map: which loops join sessions, and the map-frame poses.

Design (McDonald, Kaess et al., "6-DOF multi-session visual SLAM using anchor nodes", in an
equivalent form): each session is its own relative pose graph (its odometry and the loops its
own run accepted, in its own odometry frame). A session's **anchor** ``T_map_session`` places
it in the map. Odometry and intra-session loop factors are invariant to moving a whole session
(left-multiplying all its poses by one transform), so solving for map-frame keyframe poses with
one prior per *connected component* is the anchor-node graph with the anchors eliminated; the
anchors are read back as ``T_map_first_keyframe @ inv(T_odom_first_keyframe)``.

Sessions that no accepted loop connects stay in separate components, each in the frame of its
first session, and the map says so. Two sessions are joined only by a **pairwise-consistent
set** of at least ``map.min_join_loops`` loops between them (PCM, Mangelson et al. 2018): a
single loop between two unconnected graphs cannot be tested against anything, and a false one
would fold one map onto another. Two loops (a->b, c->d) between sessions S and T are consistent
when the cycle a -> b (loop) -> d (T's own estimate) -> c (loop back) -> a (S's own estimate)
closes within a chi-square bound on its covariance (both loops' plus the odometry's between the
keyframes of each session). Then a batch GNC (TLS) re-check over all inter-session loops, and a
Levenberg-Marquardt solve of the final graph. Why batch here: an append joins sessions once; a
batch solve is exact at that moment, and the sessions' own iSAM2 graphs stay as they were.
"""
from __future__ import annotations

import logging

import gtsam
import numpy as np
from scipy.stats import chi2 as chi2_dist

from ..backend.gnc import gnc_loop_weights
from ..backend.loop_factors import valid_information
from ..geometry import inv
from .config import MapConfig
from .joint_types import JointLoop, JointResult, SessionPoses

log = logging.getLogger(__name__)

__all__ = ["JointLoop", "JointResult", "SessionPoses", "information_noise", "odometry_covariance", "solve", "solve_lm"]

ODOM_SIGMAS = np.r_[[0.01] * 3, [0.05] * 3]  # step noise when a session's odometry gave none


def information_noise(info: np.ndarray):
    """A Gaussian noise model from a (symmetrised) information matrix, GTSAM order."""
    info = 0.5 * (np.asarray(info, float) + np.asarray(info, float).T)
    return gtsam.noiseModel.Gaussian.Information(info)


def odometry_covariance(cov: np.ndarray | None) -> np.ndarray:
    """An odometry step's covariance as given when it is a valid one, else the default step noise."""
    return np.asarray(cov, float) if valid_information(cov) else np.diag(ODOM_SIGMAS ** 2)


def solve_lm(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> gtsam.Values:
    """Levenberg-Marquardt to tight tolerances (the map's and a localisation's final solves)."""
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-9)
    params.setAbsoluteErrorTol(1e-9)
    params.setMaxIterations(100)
    return gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()


class _Chain:
    """Relative covariance between two keyframes of one session from its odometry (a conservative sum)."""

    def __init__(self, s: SessionPoses, conf: MapConfig):
        n = len(s.ids)
        steps = np.zeros((n, 6, 6))
        for i in range(1, n):
            d = float(np.linalg.norm(s.T_odom[i, :3, 3] - s.T_odom[i - 1, :3, 3]))
            own = odometry_covariance(s.cov[i]) if np.all(np.isfinite(s.cov[i])) else np.zeros((6, 6))
            floor = np.diag(np.r_[[(conf.pcm_sigma_rot_per_m ** 2) * d] * 3,
                                  [(conf.pcm_sigma_trans_per_m ** 2) * d] * 3])
            steps[i] = own + floor
        self.prefix = np.cumsum(steps, axis=0)
        self.index = {int(k): i for i, k in enumerate(s.ids)}

    def cov(self, a: int, b: int) -> np.ndarray:
        i, j = sorted((self.index[a], self.index[b]))
        return self.prefix[j] - self.prefix[i] + np.diag([1e-6] * 3 + [1e-4] * 3)


def _session_of(sessions: list[SessionPoses]) -> dict[int, int]:
    return {int(k): si for si, s in enumerate(sessions) for k in s.ids}


def _pose_of(sessions, where, kf: int) -> np.ndarray:
    si, i = where[kf]
    return sessions[si].T_init[i]


def pairwise_consistent(l1: JointLoop, l2: JointLoop, sessions, where, chains, threshold: float) -> bool:
    """Do two loops between the same two sessions close a consistent cycle (chi-square test)?"""
    a, b = l1.match, l1.query  # a in S, b in T (x_b = x_a Z1)
    c, d = (l2.match, l2.query) if where[l2.match][0] == where[a][0] else (l2.query, l2.match)
    Z2 = l2.T if where[l2.match][0] == where[a][0] else inv(l2.T)  # x_d = x_c Z2
    cov2 = np.linalg.inv(l2.info) if where[l2.match][0] == where[a][0] else None
    T_ac = inv(_pose_of(sessions, where, a)) @ _pose_of(sessions, where, c)  # S's own estimate
    T_bd = inv(_pose_of(sessions, where, b)) @ _pose_of(sessions, where, d)  # T's own estimate
    # b -> a -> c -> d through the loops and S, against T's b -> d
    T_bd_loops = inv(l1.T) @ T_ac @ Z2
    err = gtsam.Pose3.Logmap(gtsam.Pose3(inv(T_bd) @ T_bd_loops))
    cov1 = np.linalg.inv(l1.info)
    if cov2 is None:  # the loop seen from its other end: its covariance moved to that frame
        Ad = gtsam.Pose3(l2.T).AdjointMap()
        cov2 = Ad @ np.linalg.inv(l2.info) @ Ad.T
    sa, sb = where[a][0], where[b][0]
    cov = cov1 + cov2 + chains[sa].cov(a, c) + chains[sb].cov(b, d)
    try:
        m = float(err @ np.linalg.solve(cov, err))
    except np.linalg.LinAlgError:
        return False
    return m <= threshold


def _max_consistent_set(loops: list[JointLoop], ok) -> list[int]:
    """Largest set of loops that are pairwise consistent (greedy clique growth from every seed)."""
    n = len(loops)
    adj = np.zeros((n, n), bool)
    for i in range(n):
        for j in range(i + 1, n):
            adj[i, j] = adj[j, i] = ok(loops[i], loops[j])
    best: list[int] = []
    for seed in np.argsort(-adj.sum(1)):
        clique = [int(seed)]
        cand = [int(k) for k in np.argsort(-adj.sum(1)) if k != seed and adj[seed, k]]
        for k in cand:
            if all(adj[k, m] for m in clique):
                clique.append(k)
        if len(clique) > len(best):
            best = clique
        if len(best) == n:
            break
    return sorted(best)


def solve(sessions: list[SessionPoses], loops: list[JointLoop], conf: MapConfig | None = None,
          gnc_inlier_probability: float = 0.99) -> JointResult:
    """Judge the inter-session loops, connect sessions, and solve the joint graph (see module docstring)."""
    conf = conf or MapConfig()
    sess_of = _session_of(sessions)
    where = {int(k): (si, i) for si, s in enumerate(sessions) for i, k in enumerate(s.ids)}
    chains = [_Chain(s, conf) for s in sessions]
    threshold = float(chi2_dist.ppf(conf.pcm_probability, 6))

    # 1. per pair of sessions: the largest pairwise-consistent set of loops joins them, if big enough
    by_pair: dict[tuple[int, int], list[JointLoop]] = {}
    for lp in loops:
        if lp.inter:
            by_pair.setdefault(tuple(sorted((sess_of[lp.query], sess_of[lp.match]))), []).append(lp)
            lp.accepted = False
    joins: dict[tuple[int, int], list[JointLoop]] = {}
    for pair, group in sorted(by_pair.items()):
        chosen = _max_consistent_set(group, lambda x, y: pairwise_consistent(x, y, sessions, where, chains, threshold))
        names = f"{sessions[pair[0]].name} and {sessions[pair[1]].name}"
        if len(chosen) >= conf.min_join_loops:
            keep = set(chosen)
            for k, lp in enumerate(group):
                lp.accepted = k in keep
                lp.reason = "ok" if k in keep else f"pcm: inconsistent with the {len(chosen)} loops joining {names}"
            joins[pair] = [group[k] for k in chosen]
        else:
            for lp in group:
                lp.reason = (f"pcm: {len(chosen)} consistent loop(s) between {names}, "
                             f"{conf.min_join_loops} needed to join them")

    # 2. components and initial values (breadth-first from each component's first session)
    comp = {si: -1 for si in range(len(sessions))}
    init: dict[int, np.ndarray] = {}
    n_comp = 0
    for root in range(len(sessions)):
        if comp[root] >= 0:
            continue
        comp[root] = n_comp
        _place(sessions[root], np.eye(4), init)
        queue = [root]
        while queue:
            s = queue.pop(0)
            for (p, q), group in joins.items():
                if s not in (p, q):
                    continue
                t = q if s == p else p
                if comp[t] >= 0:
                    continue
                comp[t] = n_comp
                prev = sessions[t].prev_component
                if prev is not None and prev == sessions[root].prev_component:  # together before too
                    _place(sessions[t], np.eye(4), init)
                else:
                    _place(sessions[t], _alignment(group, sessions, where, init, t), init)
                queue.append(t)
        n_comp += 1

    # 3. the graph: odometry and own loops of each session, inter-session loops; a prior per component
    known = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    for s in sessions:
        for i, k in enumerate(s.ids):
            values.insert(int(k), gtsam.Pose3(init[int(k)]))
            if i:
                step = inv(s.T_odom[i - 1]) @ s.T_odom[i]
                known.add(gtsam.BetweenFactorPose3(int(s.ids[i - 1]), int(k), gtsam.Pose3(step),
                                                   gtsam.noiseModel.Gaussian.Covariance(odometry_covariance(s.cov[i]))))
    roots = {}
    for si in range(len(sessions)):
        roots.setdefault(comp[si], si)
    for si in roots.values():
        k0 = int(sessions[si].ids[0])
        known.add(gtsam.PriorFactorPose3(k0, gtsam.Pose3(init[k0]),
                                         gtsam.noiseModel.Diagonal.Sigmas(np.r_[[1e-6] * 3, [1e-6] * 3])))
    for lp in loops:
        if not lp.inter and lp.accepted:
            known.add(gtsam.BetweenFactorPose3(lp.match, lp.query, gtsam.Pose3(lp.T), information_noise(lp.info)))
    inter = [lp for lp in loops if lp.inter and lp.accepted]
    if inter:
        factors = [gtsam.BetweenFactorPose3(lp.match, lp.query, gtsam.Pose3(lp.T), information_noise(lp.info))
                   for lp in inter]
        # GNC starts from the optimum with every PCM-consistent loop: the initial values (each session's
        # own estimate, placed by one loop) can be far from what the visual links say, and TLS started
        # there turned every loop of a consistent set into an outlier
        start = gtsam.NonlinearFactorGraph(known)
        for f in factors:
            start.add(f)
        values = solve_lm(start, values)
        res = gnc_loop_weights(known, factors, values, inlier_probability=gnc_inlier_probability)
        for lp, w, c2 in zip(inter, res.weights, res.residual_chi2, strict=True):
            if w < 0.5:
                lp.accepted = False
                lp.reason = f"gnc: outlier of the joint graph (weight {w:.2f}, residual chi2 {c2:.1f})"
        values = res.values
    graph = gtsam.NonlinearFactorGraph(known)
    for lp in inter:
        if lp.accepted:
            graph.add(gtsam.BetweenFactorPose3(lp.match, lp.query, gtsam.Pose3(lp.T), information_noise(lp.info)))
    values = solve_lm(graph, values)
    poses = {int(k): values.atPose3(int(k)).matrix() for s in sessions for k in s.ids}
    # a component that the solve left isolated keeps its first session's frame
    anchors = {s.name: poses[int(s.ids[0])] @ inv(s.T_odom[0]) for s in sessions}
    return JointResult(poses, {s.name: comp[si] for si, s in enumerate(sessions)}, anchors, list(loops))


def _place(s: SessionPoses, A: np.ndarray, init: dict[int, np.ndarray]) -> None:
    for k, T in zip(s.ids, s.T_init, strict=True):
        init[int(k)] = A @ T


def _alignment(group: list[JointLoop], sessions, where, init, t: int) -> np.ndarray:
    """Transform that places session ``t`` (own frame) next to its already-placed partner through the loops.

    Each loop gives one candidate ``A = T_map_a Z T_t_b^-1``; the one closest to the others (medoid
    by translation) is taken: robust to a loop that PCM let through by a small margin.
    """
    cands = []
    for lp in group:
        if where[lp.query][0] == t:  # match placed, query in t
            other, mine, Z = lp.match, lp.query, lp.T
        else:
            other, mine, Z = lp.query, lp.match, inv(lp.T)
        cands.append(init[other] @ Z @ inv(_pose_of(sessions, where, mine)))
    ts = np.array([A[:3, 3] for A in cands])
    med = int(np.argmin(np.linalg.norm(ts[:, None] - ts[None], axis=2).sum(1)))
    return cands[med]
