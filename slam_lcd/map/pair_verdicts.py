"""The verdict on one pair of sessions, a function of those two sessions and their loops alone.

Why: the joint graph's answer must not depend on the order in which logs joined the map, and an
append must not re-judge what earlier appends judged. So each pair of sessions is judged once,
at the append that brings its later session (that is when all its loops exist), from the two
sessions' own estimates (odometry corrected by their own loops) and the loops between them:

1. PCM and the join rules (:func:`.joins.judge_pair`);
2. a GNC (TLS) re-check of the chosen loops in the graph of the two sessions alone (their
   odometry, own loops and accepted visual links as known inliers), started from the optimum
   with every chosen loop;
3. the join rules again on the survivors (:func:`.joins.recheck`).

The verdict is recorded (:func:`record`) with a fingerprint of the rules that made it
(:func:`rule_key`); a later append takes it as it was while the rules are the same, and its
accepted loops enter the joint graph as known inliers. Only when the joint graph contradicts a
pair (:func:`contradicted`: most of its loops fail the inlier bound in the joint solution) is it
judged again, with every loop of the pair as a GNC candidate, and the pair says so.

A session's visual links are likewise judged once, when the session is new: each against its
odometry step (:func:`.links.gate_links`), then a GNC re-check in the session's own graph.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, fields

import gtsam
import numpy as np

from ..backend.gate import chi2_quantile
from ..backend.gnc import gnc_loop_weights
from ..backend.poses import levenberg_marquardt
from ..geometry import inv
from .config import MapConfig
from .joins import judge_pair, recheck
from .joint_types import LINK, JointLoop, PairDecision, SessionPoses, is_link
from .links import gate_links, link_weight, linked_steps, shared_weight
from .pcm import SessionChains
from .session_factors import between, odometry_factors

KEPT = "kept"
REJUDGED = "re-judged"
RULE_PREFIXES = ("pcm_", "min_join", "join_")  # the MapConfig fields a pair's verdict depends on


def rule_key(conf: MapConfig, inlier_probability: float) -> str:
    """A short fingerprint of the rules a pair's verdict depends on: a recorded verdict made under other
    rules is judged again."""
    rules = {f.name: getattr(conf, f.name) for f in fields(conf) if f.name.startswith(RULE_PREFIXES)}
    rules["gnc_inlier_probability"] = inlier_probability
    return hashlib.sha256(json.dumps(rules, sort_keys=True).encode()).hexdigest()[:16]


def record(d: PairDecision, rule: str) -> dict:
    """A pair's verdict as the map's session table keeps it (JSON)."""
    out = asdict(d)
    out["sessions"], out["rule"] = list(d.sessions), rule
    out["status"] = d.recorded if d.status == KEPT else d.status  # how the verdict was made
    out.pop("recorded", None)
    out["span_m"], out["span_deg"] = [float(x) for x in d.span_m], [float(x) for x in d.span_deg]
    return out


def from_record(rec: dict) -> PairDecision:
    """The verdict a record keeps, taken as it was (``status`` "kept")."""
    known = {f.name for f in fields(PairDecision)}
    d = PairDecision(**{k: v for k, v in rec.items() if k in known})
    d.sessions, d.status = (str(rec["sessions"][0]), str(rec["sessions"][1])), KEPT
    d.recorded = str(rec.get("status") or "judged")
    d.folded = int(rec.get("folded", 0))
    d.span_m = (float(rec["span_m"][0]), float(rec["span_m"][1]))
    spread = rec.get("span_deg") or (0.0, 0.0)
    d.span_deg = (float(spread[0]), float(spread[1]))
    return d


def judged_pairs(table: list[dict]) -> dict[tuple[str, str], dict]:
    """The recorded verdicts of a map's session table: ``(name, name) -> record`` (a map without them: none)."""
    out = {}
    for meta in table:
        for rec in meta.get("pairs", []):
            out[(str(rec["sessions"][0]), str(rec["sessions"][1]))] = rec
    return out


def keep_pairs(table: list[dict], result) -> None:
    """Record each pair's verdict in the session table, with the later of its two sessions (the append that
    brought the pair's loops)."""
    order = {m["name"]: i for i, m in enumerate(table)}
    by_later: dict[int, list[dict]] = {}
    for d in result.pairs:
        by_later.setdefault(max(order[d.sessions[0]], order[d.sessions[1]]), []).append(record(d, result.rule))
    for i, m in enumerate(table):
        m.pop("pairs", None)
        if i in by_later:
            m["pairs"] = by_later[i]


class SessionGraphs:
    """Each session's known-inlier factors (odometry weighed with its accepted links, own loops), and
    graphs of any set of sessions built from them: a pair's graph reads two sessions, not the map."""

    def __init__(self, sessions: list[SessionPoses], loops: list[JointLoop], chains: SessionChains):
        self.sessions, self.chains = sessions, chains
        self._odometry: dict[tuple[int, frozenset], list] = {}
        self.own: dict[int, list[JointLoop]] = {}
        self.links: dict[int, list[JointLoop]] = {}
        for lp in loops:
            if lp.inter:
                continue
            si = chains.session_of(lp.query)
            (self.links if is_link(lp) else self.own).setdefault(si, []).append(lp)

    def factors_of(self, si: int, links_known: bool = True) -> list:
        """Session ``si``'s known-inlier factors: odometry steps between its variables (weighed with the accepted
        links), own accepted loops and folded factors, the accepted links unless they are the candidates."""
        s = self.sessions[si]
        shared = frozenset(linked_steps(self.links.get(si, []), self.chains))
        w = shared_weight(s)
        if (si, shared) not in self._odometry:
            weights = np.array([w if int(k) in shared else 1.0 for k in s.ids])
            self._odometry[(si, shared)] = odometry_factors(s, self.chains.conf, weights)
        out = list(self._odometry[(si, shared)])
        out += [between(lp) for lp in self.own.get(si, []) if lp.accepted]
        out += [between(lp, w) for lp in (self.links.get(si, []) if links_known else []) if lp.accepted]
        return out

    def known(self, subset: list[int], roots: list[int], init: dict[int, np.ndarray],
              links_known: bool = True) -> gtsam.NonlinearFactorGraph:
        """Known inliers of ``subset`` (:meth:`factors_of`); a tight prior at the first keyframe of each session
        of ``roots``."""
        graph = gtsam.NonlinearFactorGraph()
        for si in subset:
            for f in self.factors_of(si, links_known):
                graph.add(f)
        for si in roots:
            s = self.sessions[si]
            k0 = int(s.ids[np.argmax(s.in_graph())])  # its first variable
            tight = gtsam.noiseModel.Diagonal.Sigmas(np.full(6, 1e-6))
            graph.add(gtsam.PriorFactorPose3(k0, gtsam.Pose3(init[k0]), tight))
        return graph


def values_of(init: dict[int, np.ndarray]) -> gtsam.Values:
    values = gtsam.Values()
    for k, T in init.items():
        values.insert(int(k), gtsam.Pose3(T))
    return values


def gnc_check(known: gtsam.NonlinearFactorGraph, cands: list[JointLoop], chains: SessionChains,
              values: gtsam.Values, inlier_probability: float, graph_name: str = "the joint graph") -> gtsam.Values:
    """GNC (TLS) over ``cands`` with ``known`` as known inliers; marks the outliers (their reason names
    ``graph_name``). Its solution.

    GNC starts from the optimum with every candidate: the initial values (each session's own estimate,
    placed by one loop) can be far from what the loops say, and TLS started there turned every loop of
    a consistent set into an outlier."""
    if not cands:
        return levenberg_marquardt(known, values)
    factors = [between(lp, link_weight(lp, chains) if is_link(lp) else 1.0) for lp in cands]
    start = gtsam.NonlinearFactorGraph(known)
    for f in factors:
        start.add(f)
    res = gnc_loop_weights(known, factors, levenberg_marquardt(start, values), inlier_probability=inlier_probability)
    for lp, w, c2 in zip(cands, res.weights, res.residual_chi2, strict=True):
        if w < 0.5:
            lp.accepted = False
            what = f"outlier of {graph_name} (weight {w:.2f}, residual chi2 {c2:.1f})"
            lp.reason = f"{LINK}: gnc: {what}" if is_link(lp) else f"gnc: {what}"
    return res.values


def judge_links(si: int, graphs: SessionGraphs, chains: SessionChains, conf: MapConfig,
                inlier_probability: float) -> int:
    """A new session's visual links: the odometry gate, then GNC in the session's own graph. Returns how many
    the gate failed."""
    links = graphs.links.get(si, [])
    failed = gate_links(links, chains, conf.link_probability)
    cands = [lp for lp in links if lp.accepted]
    if cands:
        s = graphs.sessions[si]
        init = s.graph_init(s.own())
        known = graphs.known([si], [si], init, links_known=False)
        gnc_check(known, cands, chains, values_of(init), inlier_probability, "the session's own graph")
    return failed


def alignment(group: list[JointLoop], chains: SessionChains, init: dict[int, np.ndarray], t: int,
              poses: np.ndarray) -> np.ndarray:
    """Transform that places session ``t`` (``poses``: its poses in some frame) next to its placed partner.

    Each loop gives one candidate ``A = T_map_a Z T_t_b^-1``; the one closest to the others (medoid
    by translation) is taken: robust to a loop that PCM let through by a small margin.
    """
    cands = []
    for lp in group:
        if chains.session_of(lp.query) == t:  # match placed, query in t
            other, mine, Z = lp.match, lp.query, lp.T
        else:
            other, mine, Z = lp.query, lp.match, inv(lp.T)
        cands.append(init[other] @ Z @ inv(poses[chains.where[int(mine)][1]]))
    ts = np.array([A[:3, 3] for A in cands])
    med = int(np.argmin(np.linalg.norm(ts[:, None] - ts[None], axis=2).sum(1)))
    return cands[med]


def judge(pair: tuple[int, int], group: list[JointLoop], graphs: SessionGraphs, chains: SessionChains,
          conf: MapConfig, inlier_probability: float) -> PairDecision:
    """The verdict on one pair from the two sessions alone (module docstring); sets each loop's verdict."""
    d, chosen = judge_pair(pair, group, chains, conf)
    if not chosen:
        return d
    p, q = pair
    sp, sq = graphs.sessions[p], graphs.sessions[q]
    init = sp.graph_init(sp.own())
    A = alignment(chosen, chains, init, q, sq.own())
    init.update(sq.graph_init(sq.own(), A))
    gnc_check(graphs.known([p, q], [p], init), chosen, chains, values_of(init), inlier_probability,
              "the two sessions' graph")
    recheck(d, pair, chosen, chains, conf)
    return d


def contradicted(joins: dict[tuple[int, int], list[JointLoop]], values: gtsam.Values,
                 inlier_probability: float) -> list[tuple[int, int]]:
    """Joined pairs whose accepted loops the joint solution mostly rejects (median residual chi-square above
    GNC's inlier bound): other pairs' loops place the two sessions elsewhere than their own loops do."""
    bound = chi2_quantile(inlier_probability, 6)
    out = []
    for pair, group in sorted(joins.items()):
        alive = [lp for lp in group if lp.accepted]
        if alive and float(np.median([2.0 * between(lp).error(values) for lp in alive])) > bound:
            out.append(pair)
    return out
