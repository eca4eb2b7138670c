"""Sessions and the loops between them appended in a chosen order, as a map appends them.

Why: a map's answer must not depend on the order in which its logs arrived. A run only finds
loops to the sessions the map holds when it runs, so end to end the loops offered differ by
order; this replays one fixed set of sessions and loops through the joint graph
(:func:`.joint_graph.solve`) in any order, carrying on what a map keeps between appends: the
recorded pair verdicts, each loop's state as the graph file stores it, and each session placed
where the previous solve put it. ``tests/map/test_map_order.py`` and
``tools/bench_map_odometry.py orders`` compare the orders.
"""
from __future__ import annotations

import copy
from collections.abc import Sequence

import numpy as np

from .config import MapConfig
from .joint_graph import JointLoop, JointResult, SessionPoses, solve
from .pair_verdicts import record


def fresh(lp: JointLoop) -> JointLoop:
    """A loop between sessions as a run offers it (no verdict yet); one within a session as it is."""
    out = copy.deepcopy(lp)
    if out.inter:
        out.accepted, out.reason = False, ""
    return out


def append_in_order(sessions: dict[str, SessionPoses], loops: Sequence[JointLoop], order: Sequence[str],
                    conf: MapConfig | None = None) -> tuple[list[JointResult], dict]:
    """Append ``sessions`` (by name) in ``order``: every solve's result, and each loop's final state
    ``(query, match) -> (accepted, reason)`` as the map's graph file keeps it."""
    where = {int(k): name for name, s in sessions.items() for k in s.ids}
    judged: dict = {}
    state: dict = {}
    res: JointResult | None = None
    results = []
    for k in range(1, len(order) + 1):
        present = set(order[:k])
        subset = []
        for name in order[:k]:
            s = copy.deepcopy(sessions[name])
            if s.T_own is None:
                s.T_own = np.asarray(s.T_init, float).copy()
            if res is not None and name in res.component:
                s.prev_component = res.component[name]
                s.T_init = np.array([res.poses[int(i)] for i in s.ids])
            else:
                s.prev_component, s.T_init = None, s.T_own.copy()
            subset.append(s)
        now = []
        for lp in loops:
            if where.get(int(lp.query)) in present and where.get(int(lp.match)) in present:
                lp = copy.deepcopy(lp)
                if (lp.query, lp.match) in state:
                    lp.accepted, lp.reason = state[(lp.query, lp.match)]
                now.append(lp)
        res = solve(subset, now, conf, judged=judged)
        judged = {tuple(d.sessions): record(d, res.rule) for d in res.pairs}
        state = {(lp.query, lp.match): (lp.accepted and not lp.reason.startswith("gnc"), lp.reason) for lp in now}
        results.append(res)
    return results, state
