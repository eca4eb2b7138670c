"""Which pairs of sessions the loops between them join, and the verdict on every such loop.

For each pair of sessions with loops between them (the rules, in order):

1. the largest pairwise-consistent set (:mod:`.pcm` test, exact :mod:`.cliques` search) must
   hold ``map.min_join_loops`` loops, else "too few";
2. it must span distinct places in **both** sessions: its keyframes in each session (own
   estimate) must lie at least ``map.min_join_span_m`` apart **or** look in directions at least
   ``map.min_join_view_angle_deg`` apart, else "too short a span". A look-alike place seen from a
   few consecutive keyframes gives loops that agree with each other as well as true ones do; those
   keyframes lie close together and look the same way. Two sessions that meet only where they
   turn in place (a full circle each, no travel) still see distinct walls: their loops span many
   directions and no distance. The angle between two viewing directions is the angle of the
   rotation between the two keyframes' orientations (:func:`view_extent_deg`): it needs no camera
   mounting, is the angle between the optical axes for a turn about an axis square to them (a
   level camera turning), and otherwise bounds it from above;
3. the largest consistent set among the other loops (disjoint from the first) must not be a
   rival: one that could join on its own (rules 1 and 2) and holds at least
   ``map.join_ambiguity_ratio`` times as many loops, else "ambiguous" (two places explain the
   loops about equally well: neither is trusted);
4. else "joined".

:func:`recheck` applies rules 1 and 2 again to the loops of a joined pair that survived the
joint graph's GNC re-check ("undone by gnc" when they fail).
"""
from __future__ import annotations

import logging

import numpy as np

from .cliques import maximum_clique
from .config import MapConfig
from .joint_types import AMBIGUOUS, JOINED, TOO_FEW, TOO_SHORT, UNDONE, JointLoop, PairDecision
from .pcm import SessionChains, consistency_matrix, pcm_threshold

log = logging.getLogger(__name__)


def extent_m(kfs: list[int], chains: SessionChains) -> float:
    """The largest distance between two of these keyframes (one session, its own estimate)."""
    if len(kfs) < 2:
        return 0.0
    p = np.array([chains.position(k) for k in kfs])
    return float(np.max(np.linalg.norm(p[:, None] - p[None], axis=2)))


def view_extent_deg(kfs: list[int], chains: SessionChains) -> float:
    """The largest angle (deg) between the viewing directions of two of these keyframes (one session, its own
    estimate): the angle of the rotation between their orientations."""
    kfs = sorted(set(kfs))
    if len(kfs) < 2:
        return 0.0
    flat = np.array([chains.own_pose(k)[:3, :3].ravel() for k in kfs])
    # the angle of R_a^T R_b from its trace, sum(R_a * R_b), for every two at once
    return float(np.degrees(np.arccos(np.clip((np.min(flat @ flat.T) - 1.0) / 2.0, -1.0, 1.0))))


def _ends(loops: list[JointLoop], pair: tuple[int, int], chains: SessionChains) -> tuple[list[int], list[int]]:
    """A set of loops' keyframes in the pair's first and in its second session."""
    ends: tuple[list[int], list[int]] = ([], [])
    for lp in loops:
        for k in (lp.query, lp.match):
            ends[0 if chains.session_of(k) == pair[0] else 1].append(int(k))
    return ends


def spans(loops: list[JointLoop], pair: tuple[int, int], chains: SessionChains) -> tuple[float, float]:
    """Extent of a set of loops' keyframes in the pair's first and in its second session."""
    ends = _ends(loops, pair, chains)
    return extent_m(ends[0], chains), extent_m(ends[1], chains)


def view_spans(loops: list[JointLoop], pair: tuple[int, int], chains: SessionChains) -> tuple[float, float]:
    """Angle (deg) between the most different viewing directions of a set of loops' keyframes, in the pair's first
    and in its second session."""
    ends = _ends(loops, pair, chains)
    return view_extent_deg(ends[0], chains), view_extent_deg(ends[1], chains)


def spans_places(loops: list[JointLoop], pair: tuple[int, int], chains: SessionChains, conf: MapConfig) -> bool:
    """Rule 2: in each session, the set's keyframes lie far enough apart or look in directions far enough apart."""
    return all(m >= conf.min_join_span_m or a >= conf.min_join_view_angle_deg
               for m, a in zip(spans(loops, pair, chains), view_spans(loops, pair, chains), strict=True))


def span_text(span_m: tuple[float, float], span_deg: tuple[float, float], conf: MapConfig) -> str:
    """How far a set spans in each session, and what rule 2 needs (for the reasons)."""
    return (f"{span_m[0]:.1f} m and {span_m[1]:.1f} m, viewing directions {span_deg[0]:.0f} deg and "
            f"{span_deg[1]:.0f} deg apart; {conf.min_join_span_m:g} m or {conf.min_join_view_angle_deg:g} deg "
            "needed in each")


def can_join(loops: list[JointLoop], pair: tuple[int, int], chains: SessionChains, conf: MapConfig) -> str | None:
    """None when the set may join the pair (rules 1 and 2), else the decision that says why not."""
    if len(loops) < conf.min_join_loops:
        return TOO_FEW
    if not spans_places(loops, pair, chains, conf):
        return TOO_SHORT
    return None


def judge_pair(pair: tuple[int, int], group: list[JointLoop], chains: SessionChains,
               conf: MapConfig) -> tuple[PairDecision, list[JointLoop]]:
    """The decision on one pair and the loops that join it (none unless joined); sets each loop's verdict."""
    names = (chains.sessions[pair[0]].name, chains.sessions[pair[1]].name)
    between = f"{names[0]} and {names[1]}"
    adj = consistency_matrix(group, chains, pcm_threshold(conf))
    first = maximum_clique(adj, conf.pcm_clique_budget)
    best = [group[i] for i in first.members]
    rest = np.ones(len(group), bool)
    rest[first.members] = False
    second = maximum_clique(adj, conf.pcm_clique_budget, allowed=rest) if rest.any() else None
    rival = [group[i] for i in second.members] if second is not None else []
    exact = first.exact and (second is None or second.exact)
    if not exact:
        log.warning("the clique search between %s ran out of its budget (%d nodes): the largest set found "
                    "so far (%d loops) is taken", between, conf.pcm_clique_budget, len(best))
    d = PairDecision(names, JOINED, len(group), len(best), len(rival), spans(best, pair, chains), exact)
    d.span_deg = view_spans(best, pair, chains)
    why_not = can_join(best, pair, chains, conf)
    if why_not == TOO_FEW:
        d.decision = TOO_FEW
        d.reason = (f"pcm: {len(best)} consistent loop(s) between {between}, "
                    f"{conf.min_join_loops} needed to join them")
    elif why_not == TOO_SHORT:
        d.decision = TOO_SHORT
        d.reason = (f"pcm: the {len(best)} consistent loops between {between} span too short a stretch "
                    f"({span_text(d.span_m, d.span_deg, conf)})")
    elif can_join(rival, pair, chains, conf) is None and len(rival) >= conf.join_ambiguity_ratio * len(best):
        d.decision = AMBIGUOUS
        d.reason = (f"pcm: ambiguous: two disjoint consistent sets of {len(best)} and {len(rival)} loops "
                    f"between {between}")
    if not exact:
        d.reason = (d.reason + "; " if d.reason else "") + "clique search over budget: largest set found taken"
    joined = d.decision == JOINED
    chosen = {id(lp) for lp in best}
    for lp in group:
        lp.accepted = joined and id(lp) in chosen
        if lp.accepted:
            lp.reason = "ok"
        elif joined:
            lp.reason = f"pcm: inconsistent with the {len(best)} loops joining {between}"
        else:
            lp.reason = d.reason
    d.kept = len(best) if joined else 0
    return d, (best if joined else [])


def recheck(d: PairDecision, pair: tuple[int, int], joining: list[JointLoop], chains: SessionChains,
            conf: MapConfig) -> bool:
    """After GNC: do the surviving loops of a joined pair still join it? If not, undo the pair (True)."""
    alive = [lp for lp in joining if lp.accepted]
    d.kept = len(alive)
    why_not = can_join(alive, pair, chains, conf)
    if why_not is None:
        return False
    detail = (f"{len(alive)} of its {len(joining)} loops survived, {conf.min_join_loops} needed"
              if why_not == TOO_FEW else
              f"its {len(alive)} surviving loops span "
              f"{span_text(spans(alive, pair, chains), view_spans(alive, pair, chains), conf)}")
    d.decision, d.kept = UNDONE, 0
    d.reason = f"gnc: join of {d.sessions[0]} and {d.sessions[1]} undone: {detail}"
    for lp in alive:
        lp.accepted = False
        lp.reason = d.reason
    return True
