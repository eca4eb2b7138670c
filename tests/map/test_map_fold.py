"""Folding dropped keyframes out of a lifelong map's joint graph (slam_lcd.map.fold).

Synthetic sessions (poses and loops, no images): a chain folds exactly; folding keeps the solution
and every session at full rate; parallel folded factors merge by adding information; a recent
pair's loops keep their ends raw; a folded pair keeps its verdict; and a hundred appends of one
route keep the graph's size flat once the places stop growing.
"""
from __future__ import annotations

import copy
import time

import numpy as np
import pytest
from test_map_pcm import _noisy_session
from test_map_sessions import INFO, _route

from slam_lcd.geometry import inv, make_T, se3_exp
from slam_lcd.map.config import MapConfig
from slam_lcd.map.fold import fold, foldable, merge_parallel
from slam_lcd.map.joint_graph import JointLoop, solve
from slam_lcd.map.joint_types import FOLD
from slam_lcd.map.pair_verdicts import KEPT, record

L_LOOP = np.linalg.cholesky(np.linalg.inv(INFO))


def _true(gt_q, gt_m, q: int, m: int, rng, inter: bool = True) -> JointLoop:
    return JointLoop(q, m, inv(gt_m) @ gt_q @ se3_exp(L_LOOP @ rng.normal(size=6)), INFO, inter, not inter,
                     "" if inter else "ok")


def _placed(sessions, res):
    out = copy.deepcopy(sessions)
    for s in out:
        s.prev_component = res.component[s.name]
        s.T_init = np.array([res.poses[int(k)] for k in s.ids])
    return out


def _drop_all_but(sessions, every: dict[int, int]) -> set[int]:
    drop = set()
    for si, s in enumerate(sessions):
        keep = np.arange(len(s.ids)) % every[si] == 0
        drop |= {int(k) for k in s.ids[~keep]}
    return drop


def _ate(poses, gt, first: int) -> float:
    A = poses[first] @ inv(gt[0])
    return float(np.sqrt(np.mean([np.sum((poses[first + i][:3, 3] - (A @ g)[:3, 3]) ** 2)
                                  for i, g in enumerate(gt)])))


@pytest.fixture(scope="module")
def pair():
    """Two sessions of one route 0.6 m apart: a loop every second keyframe, an own loop in the first."""
    rng = np.random.default_rng(3)
    route = _route(60, 3)
    gt = {"a": route, "b": route @ make_T(np.eye(3), np.array([0.0, 0.6, 0.0]))}
    a, b = _noisy_session("a", gt["a"], 0, rng), _noisy_session("b", gt["b"], 1000, rng)
    for s in (a, b):
        s.T_own = s.T_init.copy()
    loops = [_true(gt["b"][j], gt["a"][j], 1000 + j, j, rng) for j in range(2, 59, 2)]
    loops.append(_true(gt["a"][48], gt["a"][0], 48, 0, rng, inter=False))
    conf = MapConfig(fold_after_appends=1)
    res = solve([a, b], loops, conf)
    return gt, [a, b], res, conf


def test_a_chain_without_loops_folds_exactly():
    """Odometry alone between the kept keyframes: each stretch's marginal is one relative factor (KL 0), and the
    solution stays (the folded factors are measured at it; only the pull the folded chain had on the loop is
    gone: the loop bends the chain by decimetres, the fold moves it by millimetres)."""
    rng = np.random.default_rng(1)
    gt = _route(40, 2)
    s = _noisy_session("a", gt, 0, rng)
    s.T_own = s.T_init.copy()
    loops = [_true(gt[30], gt[0], 30, 0, rng, inter=False)]
    conf = MapConfig(fold_after_appends=1)
    res = solve([s], loops, conf)
    placed = _placed([s], res)
    drop = _drop_all_but(placed, {0: 10}) - {30}
    out, rep = fold(placed, res.loops, res.poses, drop, conf)
    assert rep.keyframes == len(drop) and rep.kl_nats < 1e-6
    assert [lp.reason for lp in out].count(FOLD) == 3  # 0-10, 10-20, 20-30 (30-39 has no variable at its end)
    res2 = solve(placed, out, conf)
    for k in range(40):
        assert np.linalg.norm(res2.poses[k][:3, 3] - res.poses[k][:3, 3]) < 0.01


def test_folding_keeps_the_solution_and_the_sessions_at_full_rate(pair):
    gt, sessions, res, conf = pair
    placed = _placed(sessions, res)
    drop = _drop_all_but(placed, {0: 10, 1: 15})
    out, rep = fold(placed, res.loops, res.poses, drop, conf)
    print(f"\nfolded {rep.keyframes} keyframes: {rep.removed} raw loops -> {rep.added} folded factors, "
          f"KL {rep.kl_nats:.1f} nats")
    assert rep.keyframes == 110 and rep.removed == 29 and rep.added <= 12
    assert rep.by_pair == {frozenset(("a", "b")): 28}
    judged = {tuple(d.sessions): dict(record(d, res.rule), folded=28) for d in res.pairs}
    res2 = solve(placed, out, conf, judged=judged)
    assert res2.component == {"a": 0, "b": 0}
    assert [(d.status, d.folded) for d in res2.pairs] == [(KEPT, 28)]
    live = [int(k) for s in placed for k in s.ids[s.in_graph()]]
    assert len(live) == 10
    assert max(np.linalg.norm(res2.poses[k][:3, 3] - res.poses[k][:3, 3]) for k in live) < 0.005
    assert max(np.linalg.norm(res2.poses[k][:3, 3] - res.poses[k][:3, 3]) for k in res.poses) < 0.01
    for name, first in (("a", 0), ("b", 1000)):
        assert _ate(res2.poses, gt[name], first) <= 1.02 * _ate(res.poses, gt[name], first)


def test_parallel_folded_factors_merge_by_adding_information():
    rng = np.random.default_rng(4)
    T = se3_exp(rng.normal(0, 0.5, 6))
    info1 = np.diag(rng.uniform(10, 100, 6))
    info2 = np.diag(rng.uniform(10, 100, 6))
    a = JointLoop(2, 1, T, info1, False, True, FOLD)
    b = JointLoop(2, 1, T @ se3_exp(np.full(6, 1e-3)), info2, False, True, FOLD)
    (m,) = merge_parallel([a, b])
    assert np.allclose(m.info, info1 + info2)
    # the same factor seen the other way round merges into the same thing
    from slam_lcd.map.fold import _adjoint
    A = _adjoint(b.T)
    flipped = JointLoop(1, 2, inv(b.T), A @ np.linalg.inv(info2) @ A.T, False, True, FOLD)
    flipped.info = np.linalg.inv(flipped.info)
    (m2,) = merge_parallel([a, flipped])
    assert np.allclose(m2.T, m.T, atol=1e-9) and np.allclose(m2.info, m.info, rtol=1e-6)


def test_a_recent_pairs_loops_keep_their_ends_raw(pair):
    """With three appends to wait, only the first of four sessions folds, and not where a loop of a pair
    judged within the last three appends touches it."""
    gt, sessions, res, _ = pair
    extra = [copy.deepcopy(sessions[1]) for _ in range(2)]
    for i, s in enumerate(extra):
        s.name, s.ids = f"c{i}", s.ids + 1000 * (i + 1)
    four = [*sessions, *extra]
    recent = JointLoop(3005, 7, np.eye(4), INFO, True, True, "")  # c1 (the newest) to a's keyframe 7
    dropped = {si: np.arange(60) % 10 != 0 for si in range(4)}
    got = foldable(four, [recent], dropped, MapConfig(fold_after_appends=3))
    assert got == {k for k in range(60) if k % 10} - {7}


def test_a_hundred_appends_of_one_route_keep_the_graph_flat():
    """One route driven a hundred times (a lap of 24 keyframes, noised odometry, a true loop from every
    keyframe to the first lap's at its place). The first lap keeps the places; every later keyframe is dropped
    and folds three appends on: a whole lap folds, its poses follow the first lap's variables. Printed:
    variables, factors and append time every ten appends."""
    rng = np.random.default_rng(8)
    lap = _route(24, 6)
    conf = MapConfig(fold_after_appends=3)
    sessions, loops, judged, res = [], [], {}, None
    sizes, times = {}, {}
    for n in range(1, 101):
        s = _noisy_session(f"s{n}", lap, 1000 * n, rng)
        s.T_own = s.T_init.copy()
        if n > 1:
            loops += [_true(lap[j], lap[j], 1000 * n + j, 1000 + j, rng) for j in range(0, 24, 2)]
        placed = _placed(sessions, res) if res is not None else []  # the map's sessions as read (not timed)
        t0 = time.perf_counter()
        res = solve([*placed, s], loops, conf, judged=judged)
        sessions = _placed([*placed, s], res)
        dropped = {si: np.ones(24, bool) if si else np.zeros(24, bool) for si in range(len(sessions))}
        drop = foldable(sessions, res.loops, dropped, conf)
        loops, rep = fold(sessions, res.loops, res.poses, drop, conf)
        judged = {tuple(d.sessions): record(d, res.rule) for d in res.pairs}
        for rec in judged.values():
            rec["folded"] = rec.get("folded", 0) + rep.by_pair.get(frozenset(rec["sessions"]), 0)
        times[n] = time.perf_counter() - t0
        variables = sum(int(x.in_graph().sum()) for x in sessions)
        factors = sum(int(x.in_graph()[1:].sum() - ((~x.in_graph()[:-1]) & x.in_graph()[1:]).sum())
                      for x in sessions) + sum(1 for lp in loops if lp.accepted)
        sizes[n] = (variables, factors)
        assert all(d.decision == "joined" for d in res.pairs), n
    for n in range(10, 101, 10):
        print(f"append {n:3d}: {sizes[n][0]} variables, {sizes[n][1]} factors, "
              f"{1e3 * np.median([times[k] for k in range(n - 9, n + 1)]):.0f} ms (median of the last ten)")
    assert sizes[100][0] <= sizes[20][0] + 5 and sizes[100][1] <= 1.1 * sizes[20][1]
    assert sizes[20][0] == 24 * 4  # the first lap (the places) and the last three laps (raw)
