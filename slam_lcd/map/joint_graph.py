"""The joint pose graph of every session of a map: which loops join sessions, and the map-frame poses.

Design (McDonald, Kaess et al., "6-DOF multi-session visual SLAM using anchor nodes", in an
equivalent form): each session is its own relative pose graph (its odometry and the loops its
own run accepted, in its own odometry frame). A session's **anchor** ``T_map_session`` places
it in the map. Odometry and intra-session loop factors are invariant to moving a whole session
(left-multiplying all its poses by one transform), so solving for map-frame keyframe poses with
one prior per *connected component* is the anchor-node graph with the anchors eliminated; the
anchors are read back as ``T_map_first_keyframe @ inv(T_odom_first_keyframe)``.

Sessions that no accepted loop connects stay in separate components, each in the frame of its
first session, and the map says so. The steps of :func:`solve`:

1. **Visual links** are tested against the odometry step they span and weighed once where they
   and the odometry share the camera (:mod:`.links`).
2. **Joins.** Per pair of sessions, the largest pairwise-consistent set of loops (PCM with
   covariances propagated through the adjoints, :mod:`.pcm`; the exact maximum clique with a
   node budget, :mod:`.cliques`) joins them when it is big enough, spans distinct places in both
   sessions and has no rival of similar size (:mod:`.joins`). A single loop between two
   unconnected graphs cannot be tested against anything, and a false one would fold one map
   onto another.
3. **GNC.** A batch GNC (TLS) re-check over every loop between sessions and every link, with
   each session's odometry and own loops as known inliers.
4. **Re-check.** The surviving loops of each joined pair must still join it (rules 1 and 2 of
   :mod:`.joins`); a pair that fails is undone ("undone by gnc"), the components are recomputed
   (a component that lost its join gets its own prior and frame) and steps 3-4 run again, until
   no join is undone (each round undoes one join at least, so at most one round per pair).
5. A Levenberg-Marquardt solve of the final graph.

Why batch here: an append joins sessions once; a batch solve is exact at that moment, and the
sessions' own iSAM2 graphs stay as they were.
"""
from __future__ import annotations

import logging

import gtsam
import numpy as np

from ..backend.gnc import gnc_loop_weights
from ..backend.loop_factors import valid_information
from ..backend.poses import levenberg_marquardt
from ..geometry import inv
from .config import MapConfig
from .joins import judge_pair, recheck
from .joint_types import LINK, JointLoop, JointResult, PairDecision, SessionPoses, is_link
from .links import gate_links, link_weight, linked_steps, shared_weight
from .pcm import SessionChains, allowance, is_modelled

log = logging.getLogger(__name__)

__all__ = ["LINK", "JointLoop", "JointResult", "PairDecision", "SessionPoses", "information_noise",
           "odometry_covariance", "solve", "solve_lm"]

ODOM_SIGMAS = np.r_[[0.01] * 3, [0.05] * 3]  # step noise when a session's odometry gave none


def information_noise(info: np.ndarray, scale: float = 1.0):
    """A Gaussian noise model from a (symmetrised) information matrix, GTSAM order, times ``scale``."""
    info = 0.5 * (np.asarray(info, float) + np.asarray(info, float).T)
    return gtsam.noiseModel.Gaussian.Information(scale * info)


def odometry_covariance(cov: np.ndarray | None, modelled: bool = False, T_step: np.ndarray | None = None,
                        conf: MapConfig | None = None) -> np.ndarray:
    """An odometry step's covariance as given when it is a valid one, else the default step noise; one the
    front end ``modelled`` is replaced by the map's per-metre allowance for ``T_step`` (:func:`.pcm.allowance`)."""
    if modelled and T_step is not None:
        return allowance(T_step, conf or MapConfig())
    return np.asarray(cov, float) if valid_information(cov) else np.diag(ODOM_SIGMAS ** 2)


def solve_lm(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> gtsam.Values:
    """Levenberg-Marquardt to tight tolerances (the map's and a localisation's final solves): the back end's."""
    return levenberg_marquardt(graph, values)


def _between(lp: JointLoop, scale: float = 1.0) -> gtsam.BetweenFactorPose3:
    return gtsam.BetweenFactorPose3(lp.match, lp.query, gtsam.Pose3(lp.T), information_noise(lp.info, scale))


def _judge_pairs(sessions, loops, chains, conf):
    """Every pair of sessions with loops between them: its decision and the loops that join it."""
    by_pair: dict[tuple[int, int], list[JointLoop]] = {}
    for lp in loops:
        if not lp.inter:
            continue
        s, t = chains.session_of(lp.query), chains.session_of(lp.match)
        lp.accepted = False
        if s == t:
            lp.reason = "pcm: both ends in one session"
            continue
        by_pair.setdefault((min(s, t), max(s, t)), []).append(lp)
    decisions: dict[tuple[int, int], PairDecision] = {}
    joins: dict[tuple[int, int], list[JointLoop]] = {}
    for pair, group in sorted(by_pair.items()):
        decisions[pair], chosen = judge_pair(pair, group, chains, conf)
        if chosen:
            joins[pair] = chosen
    return decisions, joins


def solve(sessions: list[SessionPoses], loops: list[JointLoop], conf: MapConfig | None = None,
          gnc_inlier_probability: float = 0.99) -> JointResult:
    """Judge the inter-session loops and links, connect sessions, and solve the joint graph (module docstring)."""
    conf = conf or MapConfig()
    chains = SessionChains(sessions, conf)
    links = [lp for lp in loops if is_link(lp)]
    failed = gate_links(links, chains, conf.link_probability)
    if failed:
        log.info("%d of %d visual links disagree with the odometry and are left out", failed, len(links))
    decisions, joins = _judge_pairs(sessions, loops, chains, conf)
    while True:
        comp, init = _components(sessions, joins, chains)
        values = _gnc_round(sessions, loops, links, comp, init, chains, gnc_inlier_probability)
        undone = [p for p in sorted(joins) if recheck(decisions[p], p, joins[p], chains, conf)]
        if not undone:
            break
        for p in undone:
            log.info("%s", decisions[p].reason)
            del joins[p]
    graph = _known_graph(sessions, loops, links, comp, init, chains)
    for lp in loops:
        if lp.accepted and (lp.inter or is_link(lp)):
            graph.add(_between(lp, link_weight(lp, chains) if is_link(lp) else 1.0))
    values = solve_lm(graph, values)
    poses = {int(k): values.atPose3(int(k)).matrix() for s in sessions for k in s.ids}
    # a component that the solve left isolated keeps its first session's frame
    anchors = {s.name: poses[int(s.ids[0])] @ inv(s.T_odom[0]) for s in sessions}
    return JointResult(poses, {s.name: comp[si] for si, s in enumerate(sessions)}, anchors, list(loops),
                       [decisions[p] for p in sorted(decisions)])


def _known_graph(sessions, loops, links, comp, init, chains) -> gtsam.NonlinearFactorGraph:
    """Known inliers: every session's odometry (weighed with its accepted links), own loops, a prior per component."""
    shared = linked_steps(links, chains)
    graph = gtsam.NonlinearFactorGraph()
    for s in sessions:
        w = shared_weight(s)
        for i in range(1, len(s.ids)):
            step = inv(s.T_odom[i - 1]) @ s.T_odom[i]
            cov = odometry_covariance(s.cov[i], is_modelled(s, i), step, chains.conf)
            cov = cov / (w if int(s.ids[i]) in shared else 1.0)
            graph.add(gtsam.BetweenFactorPose3(int(s.ids[i - 1]), int(s.ids[i]), gtsam.Pose3(step),
                                               gtsam.noiseModel.Gaussian.Covariance(cov)))
    roots: dict[int, int] = {}
    for si in range(len(sessions)):
        roots.setdefault(comp[si], si)
    for si in roots.values():
        k0 = int(sessions[si].ids[0])
        graph.add(gtsam.PriorFactorPose3(k0, gtsam.Pose3(init[k0]), gtsam.noiseModel.Diagonal.Sigmas(np.full(6, 1e-6))))
    for lp in loops:
        if not lp.inter and lp.accepted and not is_link(lp):
            graph.add(_between(lp))
    return graph


def _gnc_round(sessions, loops, links, comp, init, chains, inlier_probability: float) -> gtsam.Values:
    """GNC over the accepted loops between sessions and the accepted links; marks its outliers. Its solution."""
    values = gtsam.Values()
    for k, T in init.items():
        values.insert(int(k), gtsam.Pose3(T))
    known = _known_graph(sessions, loops, links, comp, init, chains)
    cands = [lp for lp in loops if lp.accepted and (lp.inter or is_link(lp))]
    if not cands:
        return solve_lm(known, values)
    factors = [_between(lp, link_weight(lp, chains) if is_link(lp) else 1.0) for lp in cands]
    # GNC starts from the optimum with every candidate: the initial values (each session's own
    # estimate, placed by one loop) can be far from what the links say, and TLS started there
    # turned every loop of a consistent set into an outlier
    start = gtsam.NonlinearFactorGraph(known)
    for f in factors:
        start.add(f)
    res = gnc_loop_weights(known, factors, solve_lm(start, values), inlier_probability=inlier_probability)
    for lp, w, c2 in zip(cands, res.weights, res.residual_chi2, strict=True):
        if w < 0.5:
            lp.accepted = False
            what = f"outlier of the joint graph (weight {w:.2f}, residual chi2 {c2:.1f})"
            lp.reason = f"{LINK}: gnc: {what}" if is_link(lp) else f"gnc: {what}"
    return res.values


def _components(sessions, joins, chains) -> tuple[dict[int, int], dict[int, np.ndarray]]:
    """Components of the joined sessions and initial values, breadth-first from each component's first session."""
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
            for (p, q), group in sorted(joins.items()):
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
                    _place(sessions[t], _alignment(group, chains, init, t), init)
                queue.append(t)
        n_comp += 1
    return comp, init


def _place(s: SessionPoses, A: np.ndarray, init: dict[int, np.ndarray]) -> None:
    for k, T in zip(s.ids, s.T_init, strict=True):
        init[int(k)] = A @ T


def _alignment(group: list[JointLoop], chains: SessionChains, init, t: int) -> np.ndarray:
    """Transform that places session ``t`` (own frame) next to its already-placed partner through the loops.

    Each loop gives one candidate ``A = T_map_a Z T_t_b^-1``; the one closest to the others (medoid
    by translation) is taken: robust to a loop that PCM let through by a small margin.
    """
    cands = []
    for lp in group:
        if chains.session_of(lp.query) == t:  # match placed, query in t
            other, mine, Z = lp.match, lp.query, lp.T
        else:
            other, mine, Z = lp.query, lp.match, inv(lp.T)
        si, i = chains.where[int(mine)]
        cands.append(init[other] @ Z @ inv(chains.sessions[si].T_init[i]))
    ts = np.array([A[:3, 3] for A in cands])
    med = int(np.argmin(np.linalg.norm(ts[:, None] - ts[None], axis=2).sum(1)))
    return cands[med]
