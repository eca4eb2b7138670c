"""One verdict for one set of logs: the joint graph's answer does not depend on the order of appends.

Three synthetic sessions of one route (odometry noised by the covariance it gives), each pair with
true loops, a consistent look-alike trio and scattered false loops, appended in all 6 orders as a
map appends them: the verdicts and loop states of earlier appends carried on, each session placed
where the previous solve put it. Then a session of another world with false loops to one of them.
"""
from __future__ import annotations

import copy
import itertools

import numpy as np
import pytest
from test_map_pcm import _noisy_session
from test_map_sessions import INFO, _route

from slam_lcd.geometry import inv, make_T, se3_exp, so3_exp
from slam_lcd.map.joint_graph import JointLoop, SessionPoses, solve
from slam_lcd.map.pair_verdicts import KEPT, record
from slam_lcd.map.replay import append_in_order

NAMES = ("s0", "s1", "s2")
FIRST = {"s0": 0, "s1": 1000, "s2": 2000, "other": 3000}


def _loops_between(gt, a: str, b: str, rng) -> list[JointLoop]:
    """Loops from session b's keyframes to session a's: true ones, a look-alike trio, scattered false ones."""
    ia, ib = FIRST[a], FIRST[b]
    L = np.linalg.cholesky(np.linalg.inv(INFO))
    out = [JointLoop(ib + j, ia + j, inv(gt[a][j]) @ gt[b][j] @ se3_exp(L @ rng.normal(size=6)), INFO, True)
           for j in range(2, len(gt[a]) - 1, 2)]
    W = make_T(so3_exp(np.array([0, 0, 0.4])), np.array([3.0, -2.0, 0]))  # one wrong place, three loops agree on it
    out += [JointLoop(ib + j, ia + i, inv(gt[a][i]) @ W @ gt[b][j], INFO, True) for i, j in ((30, 5), (31, 6), (32, 7))]
    for _ in range(4):
        i, j = rng.integers(0, len(gt[a]), 2)
        out.append(JointLoop(ib + int(j), ia + int(i), se3_exp(rng.normal(0, 1.0, 6)), INFO, True))
    return out


@pytest.fixture(scope="module")
def world():
    rng = np.random.default_rng(5)
    route = _route(60, 3)
    side = make_T(np.eye(3), np.array([0.0, 0.6, 0.0]))
    gt = {"s0": route, "s1": route @ side, "s2": route @ inv(side)}
    sessions = {n: _noisy_session(n, gt[n], FIRST[n], rng) for n in NAMES}
    loops = {(a, b): _loops_between(gt, a, b, rng) for a, b in itertools.combinations(NAMES, 2)}
    other_gt = _route(40, 9)
    sessions["other"] = _noisy_session("other", other_gt, FIRST["other"], rng)
    loops[("s2", "other")] = [JointLoop(FIRST["other"] + int(j), FIRST["s2"] + int(i), se3_exp(rng.normal(0, 1.0, 6)),
                                        INFO, True) for i, j in rng.integers(0, 40, (12, 2))]
    return sessions, loops


def _append(order, world):
    """Append the sessions in ``order`` as a map does (:func:`slam_lcd.map.replay.append_in_order`)."""
    sessions, loops = world
    chosen = {n: sessions[n] for n in order}
    return append_in_order(chosen, [lp for (a, b), group in loops.items() if a in chosen and b in chosen
                                    for lp in group], order)


def _components(res) -> set[frozenset[str]]:
    by: dict[int, set[str]] = {}
    for name, c in res.component.items():
        by.setdefault(c, set()).add(name)
    return {frozenset(v) for v in by.values()}


def _kept(state) -> set[tuple[int, int]]:
    return {k for k, (acc, _) in state.items() if acc and (k[0] // 1000) != (k[1] // 1000)}


def _relative(res, a: str, b: str) -> np.ndarray:
    """Session b's first keyframe seen from session a's (the map frame's gauge removed)."""
    return inv(res.poses[FIRST[a]]) @ res.poses[FIRST[b]]


def test_components_kept_loops_and_poses_are_the_same_in_all_six_orders(world):
    outcomes = [_append(order, world) for order in itertools.permutations(NAMES)]
    (ref_results, ref_state) = outcomes[0]
    ref = ref_results[-1]
    assert _components(ref) == {frozenset(NAMES)}
    kept = _kept(ref_state)
    true_kept = {k for k in kept if (k[0] % 1000) == (k[1] % 1000)}
    assert len(true_kept) == len(kept) and len(kept) >= 3 * 26, "false loops kept or true ones lost"
    for results, state in outcomes[1:]:
        res = results[-1]
        assert _components(res) == _components(ref)
        assert _kept(state) == kept
        for a, b in (("s0", "s1"), ("s0", "s2"), ("s1", "s2")):
            d = np.linalg.norm(_relative(res, a, b)[:3, 3] - _relative(ref, a, b)[:3, 3])
            assert d < 1e-3, f"{a}->{b} differs by {d:.4f} m between orders"


def test_an_append_keeps_earlier_verdicts_and_judges_only_its_own_pairs(world):
    results, _ = _append(("s0", "s1", "s2"), world)
    assert [d.status for d in results[1].pairs] == ["judged"]
    status = {d.sessions: d.status for d in results[2].pairs}
    assert status == {("s0", "s1"): KEPT, ("s0", "s2"): "judged", ("s1", "s2"): "judged"}


def test_a_session_of_another_world_changes_no_earlier_verdict(world):
    three, state3 = _append(("s2", "s0", "s1"), world)
    four, state4 = _append(("s2", "s0", "s1", "other"), world)
    before = {d.sessions: (d.decision, d.kept) for d in three[-1].pairs}
    after = {d.sessions: (d.decision, d.kept) for d in four[-1].pairs}
    new = [d for d in four[-1].pairs if "other" in d.sessions]
    assert len(new) == 1 and new[0].decision != "joined"
    assert {k: v for k, v in after.items() if "other" not in k} == before
    assert _kept(state4) == _kept(state3)
    assert _components(four[-1]) == _components(three[-1]) | {frozenset({"other"})}
    assert all(d.status == KEPT for d in four[-1].pairs if "other" not in d.sessions)


def test_a_verdict_recorded_under_other_rules_is_judged_again(world):
    results, _ = _append(("s0", "s1"), world)
    sessions, loops = world
    rec = record(results[-1].pairs[0], "another rule")
    a, b = copy.deepcopy(sessions["s0"]), copy.deepcopy(sessions["s1"])
    res = solve([a, b], copy.deepcopy(loops[("s0", "s1")]), judged={("s0", "s1"): rec})
    assert res.pairs[0].status == "judged"
    assert isinstance(sessions["s0"], SessionPoses)


def test_a_kept_verdict_that_a_later_session_contradicts_is_judged_again_and_undone():
    """s0 and s1 joined by a consistent set of loops to one wrong place (nothing to tell it apart then); s2's
    true loops to both place s1 elsewhere: the joint graph contradicts the kept pair, which is judged again."""
    rng = np.random.default_rng(8)
    route = _route(60, 3)
    side = make_T(np.eye(3), np.array([0.0, 0.6, 0.0]))
    gt = {"s0": route, "s1": route @ side, "s2": route @ inv(side)}
    sessions = {n: _noisy_session(n, gt[n], FIRST[n], rng) for n in NAMES}
    W = make_T(so3_exp(np.array([0, 0, 0.5])), np.array([4.0, -3.0, 0]))
    wrong = [JointLoop(FIRST["s1"] + j, FIRST["s0"] + j, inv(gt["s0"][j]) @ W @ gt["s1"][j], INFO, True)
             for j in range(4, 40, 3)]
    L = np.linalg.cholesky(np.linalg.inv(INFO))
    true = [JointLoop(FIRST["s2"] + j, FIRST[a] + j, inv(gt[a][j]) @ gt["s2"][j] @ se3_exp(L @ rng.normal(size=6)),
                      INFO, True) for a in ("s0", "s1") for j in range(2, 58, 2)]
    results, state = append_in_order(sessions, wrong + true, ("s0", "s1", "s2"))
    assert results[1].pairs[0].decision == "joined"  # alone, the wrong set cannot be told apart
    d = {p.sessions: p for p in results[2].pairs}
    assert d[("s0", "s1")].status == "re-judged" and d[("s0", "s1")].decision == "undone by gnc"
    assert "re-judged" in d[("s0", "s1")].reason
    assert d[("s0", "s2")].decision == d[("s1", "s2")].decision == "joined"
    assert _components(results[2]) == {frozenset(NAMES)}
    assert not any(state[(lp.query, lp.match)][0] for lp in wrong)
    rec = record(d[("s0", "s1")], results[2].rule)
    assert rec["status"] == "re-judged"


def test_a_map_written_without_own_estimates_gets_them_from_each_sessions_odometry_and_own_loops(world):
    """Sessions of a map that did not record ``T_own``: their own estimate is solved from the session alone
    (its odometry and its own accepted loops), so the verdicts read no pose of another session."""
    from slam_lcd.map.session_graph import own_estimate

    sessions, _ = world
    s = copy.deepcopy(sessions["s0"])
    gt = _route(60, 3)
    closing = [JointLoop(int(s.ids[j]), int(s.ids[i]), inv(gt[i]) @ gt[j], INFO, False, True, "ok")
               for i, j in ((0, 48), (1, 49), (12, 36))]
    alone = own_estimate(s, [])
    np.testing.assert_allclose(alone, s.T_odom, atol=1e-9)
    own = own_estimate(s, closing)
    err = [np.linalg.norm((inv(own[i]) @ own[j])[:3, 3] - (inv(gt[i]) @ gt[j])[:3, 3]) for i, j in ((0, 48), (1, 49))]
    drift = np.linalg.norm((inv(s.T_odom[0]) @ s.T_odom[48])[:3, 3] - (inv(gt[0]) @ gt[48])[:3, 3])
    assert max(err) < 0.1 * drift and max(err) < 0.05, (err, drift)
