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

1. **Visual links** of a new session are tested against the odometry step they span, weighed
   once where they and the odometry share the camera (:mod:`.links`), and re-checked by GNC in
   the session's own graph (:func:`.pair_verdicts.judge_links`).
2. **Joins.** Each pair of sessions with loops between them that has no verdict yet is judged
   from the two sessions alone (:mod:`.pair_verdicts`): the largest pairwise-consistent set of
   loops (PCM with covariances propagated through the adjoints, :mod:`.pcm`; the exact maximum
   clique, :mod:`.cliques`) joins them when it is big enough, spans distinct places in both
   sessions and has no rival of similar size (:mod:`.joins`); a GNC re-check in the two
   sessions' graph and the rules again on its survivors. A single loop between two unconnected
   graphs cannot be tested against anything, and a false one would fold one map onto another.
   A pair judged at an earlier append keeps its verdict (``judged``): its accepted loops are
   known inliers.
3. **Joint solve.** Levenberg-Marquardt over every session's odometry, own loops, accepted links
   and the accepted loops of every joined pair.
4. **Contradictions.** A joined pair whose loops the joint solution mostly rejects is judged
   again: a GNC over its loops as candidates in the joint graph, then the join rules on the
   survivors; a pair that fails is undone ("undone by gnc"), the components are recomputed and
   steps 3-4 run again (each round undoes one join at least).

Why per pair: a verdict that reads only its two sessions does not depend on the order in which
logs joined the map nor on sessions unrelated to it, and an append costs what its own pairs
cost, not what the whole history does. Why batch: an append joins sessions once; a batch solve
is exact at that moment, and the sessions' own iSAM2 graphs stay as they were.
"""
from __future__ import annotations

import logging

import gtsam
import numpy as np

from ..backend.poses import levenberg_marquardt
from ..geometry import inv
from . import pair_verdicts as pv
from .config import MapConfig
from .fold import fill_folded
from .joins import recheck
from .joint_types import FOLD, JOINED, LINK, JointLoop, JointResult, PairDecision, SessionPoses
from .pcm import SessionChains
from .session_factors import between

log = logging.getLogger(__name__)

__all__ = ["LINK", "JointLoop", "JointResult", "PairDecision", "SessionPoses", "solve", "solve_lm"]


def solve_lm(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> gtsam.Values:
    """Levenberg-Marquardt to tight tolerances (the map's and a localisation's final solves): the back end's."""
    return levenberg_marquardt(graph, values)


def _pairs(loops: list[JointLoop], chains: SessionChains) -> dict[tuple[int, int], list[JointLoop]]:
    """The loops between sessions, by pair of sessions (a loop with both ends in one session is refused)."""
    by_pair: dict[tuple[int, int], list[JointLoop]] = {}
    for lp in loops:
        if not lp.inter or lp.reason == FOLD:
            continue
        s, t = chains.session_of(lp.query), chains.session_of(lp.match)
        if s == t:
            lp.accepted, lp.reason = False, "pcm: both ends in one session"
            continue
        by_pair.setdefault((min(s, t), max(s, t)), []).append(lp)
    return by_pair


def _folded_between(loops: list[JointLoop], chains: SessionChains) -> dict[tuple[int, int], list[JointLoop]]:
    """The folded factors between sessions, by pair of sessions: they join sessions as accepted loops do."""
    out: dict[tuple[int, int], list[JointLoop]] = {}
    for lp in loops:
        if lp.inter and lp.reason == FOLD:
            s, t = chains.session_of(lp.query), chains.session_of(lp.match)
            out.setdefault((min(s, t), max(s, t)), []).append(lp)
    return out


def _earlier(pair: tuple[int, int], group: list[JointLoop], sessions: list[SessionPoses], judged: dict,
             rule: str) -> PairDecision | None:
    """The pair's recorded verdict when it still holds: made under the same rules, on the same loops (less those
    folded since: a folded pair's verdict stands)."""
    names = (sessions[pair[0]].name, sessions[pair[1]].name)
    rec = judged.get(names) or judged.get(names[::-1])
    if rec is None or (rec.get("rule") != rule and not rec.get("folded")) \
            or int(rec.get("offered", -1)) - int(rec.get("folded", 0)) != len(group):
        return None
    d = pv.from_record(rec)
    d.sessions = names
    return d


def solve(sessions: list[SessionPoses], loops: list[JointLoop], conf: MapConfig | None = None,
          gnc_inlier_probability: float = 0.99, judged: dict | None = None) -> JointResult:
    """Judge the inter-session loops and links, connect sessions, and solve the joint graph (module docstring).

    ``judged``: the verdicts of earlier appends (``(name, name) -> record``, :func:`.pair_verdicts.record`),
    taken as they were; the visual links of sessions an earlier solve placed (``prev_component`` set) keep
    their verdicts. :attr:`JointResult.rule` fingerprints the rules, for the records."""
    conf = conf or MapConfig()
    chains = SessionChains(sessions, conf)
    graphs = pv.SessionGraphs(sessions, loops, chains)
    failed = sum(pv.judge_links(si, graphs, chains, conf, gnc_inlier_probability)
                 for si, s in enumerate(sessions) if s.prev_component is None)
    if failed:
        log.info("%d visual links disagree with the odometry and are left out", failed)
    rule = pv.rule_key(conf, gnc_inlier_probability)
    decisions: dict[tuple[int, int], PairDecision] = {}
    joins: dict[tuple[int, int], list[JointLoop]] = {}
    folded = _folded_between(loops, chains)
    groups = _pairs(loops, chains)
    for pair in folded:  # every raw loop of the pair folded: its verdict stands as recorded
        groups.setdefault(pair, [])
    for pair, group in sorted(groups.items()):
        d = _earlier(pair, group, sessions, judged or {}, rule)
        if d is None and not group:
            continue
        if d is None:
            for lp in group:
                lp.accepted = False
            d = pv.judge(pair, group, graphs, chains, conf, gnc_inlier_probability)
        decisions[pair] = d
        if d.decision == JOINED and any(lp.accepted for lp in group):
            joins[pair] = group
    while True:
        comp, init = _components(sessions, joins, folded, chains)
        graph = _joint_graph(sessions, graphs, joins, folded, comp, init)
        values = solve_lm(graph, pv.values_of(init))
        against = pv.contradicted(joins, values, gnc_inlier_probability)
        if not against:
            break
        undone = _rejudge(against, sessions, graphs, joins, folded, decisions, comp, init, chains, conf,
                          gnc_inlier_probability)
        if not undone:
            graph = _joint_graph(sessions, graphs, joins, folded, comp, init)
            values = solve_lm(graph, values)
            break
    poses = {int(k): values.atPose3(int(k)).matrix() for s in sessions for k in s.ids[s.in_graph()]}
    fill_folded(sessions, comp, poses)
    # a component that the solve left isolated keeps its first session's frame
    anchors = {s.name: poses[int(s.ids[0])] @ inv(s.T_odom[0]) for s in sessions}
    return JointResult(poses, {s.name: comp[si] for si, s in enumerate(sessions)}, anchors, list(loops),
                       [decisions[p] for p in sorted(decisions)], rule)


def _joint_graph(sessions, graphs: pv.SessionGraphs, joins, folded, comp, init) -> gtsam.NonlinearFactorGraph:
    """Every session's known inliers, a prior per component, the accepted loops of the joined pairs and the
    folded factors between sessions."""
    roots: dict[int, int] = {}
    for si in range(len(sessions)):
        if sessions[si].in_graph().any():
            roots.setdefault(comp[si], si)
    graph = graphs.known(list(range(len(sessions))), list(roots.values()), init)
    for group in joins.values():
        for lp in group:
            if lp.accepted:
                graph.add(between(lp))
    for group in folded.values():
        for lp in group:
            graph.add(between(lp))
    return graph


def _rejudge(against, sessions, graphs, joins, folded, decisions, comp, init, chains, conf, p_inlier) -> list:
    """Judge the contradicted pairs again in the joint graph: their loops as GNC candidates (the rest known
    inliers), then the join rules on the survivors. Returns the pairs undone (removed from ``joins``)."""
    cands = [lp for pair in against for lp in joins[pair] if lp.accepted or lp.reason.startswith("gnc")]
    for lp in cands:
        lp.accepted = True
    others = {p: g for p, g in joins.items() if p not in against}  # the candidates are not known inliers
    known = _joint_graph(sessions, graphs, others, folded, comp, init)
    pv.gnc_check(known, cands, chains, pv.values_of(init), p_inlier)
    undone = []
    for pair in against:
        d = decisions[pair]
        d.status = pv.REJUDGED
        gone = recheck(d, pair, joins[pair], chains, conf)
        why = "re-judged: the joint graph of every session contradicted its loops"
        d.reason = f"{d.reason}; {why}" if d.reason else why
        if gone:
            log.info("%s", d.reason)
            del joins[pair]
            undone.append(pair)
    return undone


def _components(sessions, joins, folded, chains) -> tuple[dict[int, int], dict[int, np.ndarray]]:
    """Components of the joined sessions (by accepted loops or folded factors) and initial values, breadth-first
    from each component's first session."""
    edges = {p: [lp for lp in g if lp.accepted] for p, g in joins.items()}
    for p, g in folded.items():
        edges[p] = edges.get(p, []) + g
    comp = {si: -1 for si in range(len(sessions))}
    init: dict[int, np.ndarray] = {}
    n_comp = 0
    for root in range(len(sessions)):
        if comp[root] >= 0 or not sessions[root].in_graph().any():
            continue
        comp[root] = n_comp
        _place(sessions[root], np.eye(4), init)
        queue = [root]
        while queue:
            s = queue.pop(0)
            for (p, q), group in sorted(edges.items()):
                if s not in (p, q) or not group:
                    continue
                t = q if s == p else p
                if comp[t] >= 0:
                    continue
                comp[t] = n_comp
                prev = sessions[t].prev_component
                if prev is not None and prev == sessions[root].prev_component:  # together before too
                    _place(sessions[t], np.eye(4), init)
                else:
                    _place(sessions[t], pv.alignment(group, chains, init, t, sessions[t].T_init), init)
                queue.append(t)
        n_comp += 1
    for si, s in enumerate(sessions):  # a session folded whole: in the component of its earlier one
        if comp[si] < 0:
            same = [comp[o] for o, x in enumerate(sessions) if comp[o] >= 0 and s.prev_component is not None
                    and x.prev_component == s.prev_component]
            comp[si] = same[0] if same else n_comp
            n_comp += 0 if same else 1
    return comp, init


def _place(s: SessionPoses, A: np.ndarray, init: dict[int, np.ndarray]) -> None:
    init.update(s.graph_init(s.T_init, A))
