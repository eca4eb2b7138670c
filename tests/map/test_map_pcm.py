"""The joint graph's consistency rules: the pairwise test's calibration, the exact largest set, the
span and ambiguity guards, the re-check after GNC and the visual links' gate.

Synthetic sessions only (helpers of tests/map/test_map_sessions.py); every figure in the asserts is
what the rule promises, not what one run happened to give.
"""
from __future__ import annotations

import re

import numpy as np
import pytest
from test_map_sessions import INFO, _route, _session, _true_loop  # tests/ is on sys.path (pytest rootdir import)

from slam_lcd.geometry import adjoint, compose_covariance, inv, make_T, rotation_angle, se3_exp, so3_exp
from slam_lcd.map.cliques import maximum_clique
from slam_lcd.map.config import MapConfig
from slam_lcd.map.joint_graph import JointLoop, SessionPoses, solve
from slam_lcd.map.pcm import FLOOR, SessionChains, allowance, pairwise_consistent, pcm_threshold, step_covariances

STEP = 0.5  # m between keyframes
SIG_T, SIG_R = 0.05, 0.02  # odometry noise per sqrt(m): the sessions' own covariances
ISO = np.diag([1e-4] * 6)  # a loop good to 1 cm / 0.6 deg
DEPTH = np.diag([1e-4] * 3 + [0.3 ** 2, 1e-4, 1e-4])  # 0.3 m along the camera's depth (body x)


def _line(n: int, turn_at: int | None = None) -> np.ndarray:
    """n + 1 poses 0.5 m apart along x, turning 90 degrees left at ``turn_at``."""
    T = [np.eye(4)]
    for i in range(1, n + 1):
        yaw = np.pi / 2 if i == turn_at else 0.0
        T.append(T[-1] @ make_T(so3_exp(np.array([0, 0, yaw])), np.array([STEP, 0, 0])))
    return np.array(T)


def _step_cov() -> np.ndarray:
    return np.diag([SIG_R ** 2 * STEP] * 3 + [SIG_T ** 2 * STEP] * 3)


def _noisy_session(name: str, gt: np.ndarray, first: int, rng) -> SessionPoses:
    """Odometry noised by exactly the covariance the session gives for each step."""
    L = np.linalg.cholesky(_step_cov())
    odo = [np.eye(4)]
    for i in range(1, len(gt)):
        odo.append(odo[-1] @ inv(gt[i - 1]) @ gt[i] @ se3_exp(L @ rng.normal(size=6)))
    odo_a = np.array(odo)
    return SessionPoses(name, np.arange(first, first + len(gt)), odo_a, np.repeat(_step_cov()[None], len(gt), 0),
                        odo_a.copy())


def _flipped(lp: JointLoop) -> JointLoop:
    """The same loop seen from its other end: T^-1, information carried by the adjoint."""
    A = adjoint(lp.T)
    return JointLoop(lp.match, lp.query, inv(lp.T), np.linalg.inv(A @ np.linalg.inv(lp.info) @ A.T), lp.inter)


def _trial(distance: float, loop_cov: np.ndarray, turn: bool, rng):
    n = int(round(distance / STEP))
    gt_a = _line(n, n // 2 if turn else None)
    gt_b = gt_a @ make_T(so3_exp(np.array([0, 0, 0.3])), np.array([0.5, 1.0, 0]))  # driven beside it
    a, b = _noisy_session("a", gt_a, 0, rng), _noisy_session("b", gt_b, 1000, rng)
    L = np.linalg.cholesky(loop_cov)
    loops = [JointLoop(1000 + i, i, inv(gt_a[i]) @ gt_b[i] @ se3_exp(L @ rng.normal(size=6)),
                       np.linalg.inv(loop_cov), True) for i in (0, n)]
    return SessionChains([a, b], MapConfig()), loops


@pytest.mark.parametrize("distance, loop_cov, turn", [(2, ISO, False), (10, ISO, False), (25, ISO, False),
                                                      (50, ISO, False), (2, DEPTH, True), (25, DEPTH, True)],
                         ids=["2m", "10m", "25m", "50m", "depth-90deg-2m", "depth-90deg-25m"])
def test_true_loop_pairs_are_rejected_at_the_nominal_rate_whatever_their_distance_and_order(distance, loop_cov, turn):
    rng = np.random.default_rng(int(distance) + 7 * turn)
    thr = pcm_threshold(MapConfig())
    assert MapConfig().pcm_probability == 0.99
    trials, rejected, order_dependent = 300, 0, 0
    for _ in range(trials):
        chains, (l1, l2) = _trial(distance, loop_cov, turn, rng)
        verdict = pairwise_consistent(l1, l2, chains, thr)
        rejected += not verdict
        others = (pairwise_consistent(l2, l1, chains, thr), pairwise_consistent(_flipped(l1), l2, chains, thr),
                  pairwise_consistent(l2, _flipped(l1), chains, thr),
                  pairwise_consistent(_flipped(l2), _flipped(l1), chains, thr))
        order_dependent += any(v != verdict for v in others)
    assert order_dependent == 0
    assert rejected <= 0.02 * trials, f"{rejected} of {trials} true pairs rejected at {distance} m"


def test_chain_covariance_is_the_composition_of_the_steps_through_adjoints_and_the_allowance_only_fills_gaps():
    rng = np.random.default_rng(3)
    s = _noisy_session("a", _line(8, 4), 0, rng)
    s.cov[3] = np.nan  # this step came without a covariance
    conf = MapConfig()
    steps = step_covariances(s, conf)
    d = np.linalg.norm(s.T_odom[3, :3, 3] - s.T_odom[2, :3, 3])
    a = rotation_angle(inv(s.T_odom[2]) @ s.T_odom[3])  # the step's noise turned it a little
    v_r = conf.pcm_sigma_rot_per_m ** 2 * d + conf.pcm_sigma_rot_per_rad ** 2 * a
    np.testing.assert_allclose(steps[3], np.diag([v_r] * 3 + [conf.pcm_sigma_trans_per_m ** 2 * d] * 3 + FLOOR))
    np.testing.assert_allclose(steps[5], s.cov[5])  # given: used as it is, nothing added
    cov = np.zeros((6, 6))
    for i in range(2, 8):  # composed one step at a time, frame of the last keyframe
        cov = compose_covariance(cov, inv(s.T_odom[i - 1]) @ s.T_odom[i], steps[i])
    T, S = SessionChains([s], conf).odometry(1, 7)
    np.testing.assert_allclose(T, inv(s.T_odom[1]) @ s.T_odom[7], atol=1e-12)
    np.testing.assert_allclose(S, cov, rtol=1e-9, atol=1e-12)


def _blocked_clique() -> np.ndarray:
    """A true 4-clique (0-3) whose every loop also agrees with one of the 'blockers' 4-7; the blockers
    agree with 8-11 (complete bipartite, no triangle), so they have the highest degrees."""
    adj = np.zeros((12, 12), bool)
    adj[:4, :4] = True
    for t in range(4):
        adj[t, 4 + t] = adj[4 + t, t] = True
    adj[4:8, 8:12] = adj[8:12, 4:8] = True
    np.fill_diagonal(adj, False)
    return adj


def test_the_exact_largest_set_finds_a_blocked_four_clique_and_prefers_it_to_a_false_three_clique():
    adj = _blocked_clique()
    assert maximum_clique(adj).members == [0, 1, 2, 3]
    with_false = np.zeros((15, 15), bool)
    with_false[:12, :12] = adj
    with_false[12:, 12:] = True  # three look-alike loops consistent with each other only
    np.fill_diagonal(with_false, False)
    found = maximum_clique(with_false)
    assert found.members == [0, 1, 2, 3] and found.exact
    # past its budget the search keeps the best found so far and says so
    tight = maximum_clique(with_false, budget=1)
    assert not tight.exact and len(tight.members) >= 2


@pytest.fixture(scope="module")
def route():
    return _route(48, 1)


def _offset_loops(gt_a, gt_b, pairs, W, id_b: int = 100) -> list[JointLoop]:
    """Loops that all put session b at the same wrong place ``W`` (a look-alike with one consistent offset)."""
    return [JointLoop(id_b + j, i, inv(gt_a[i]) @ W @ gt_b[j], INFO, True) for i, j in pairs]


def test_three_consecutive_look_alike_loops_do_not_join_sessions_far_apart(route):
    gt_a = route
    gt_b = make_T(np.eye(3), np.array([0.0, 25.0, 0.0])) @ route  # 25 m away: they never meet
    a, b = _session("a", gt_a, 0, 1), _session("b", gt_b, 100, 2)
    W = make_T(so3_exp(np.array([0, 0, 0.2])), np.array([0.4, -25.0, 0.0]))
    loops = _offset_loops(gt_a, gt_b, [(20, 30), (21, 31), (22, 32)], W)  # 3 keyframes, 1 m of travel
    res = solve([a, b], loops)
    assert res.component == {"a": 0, "b": 1}
    assert not any(lp.accepted for lp in loops)
    (d,) = res.pairs
    assert d.decision == "too short a span" and d.largest == 3
    assert max(d.span_m) < 1.1 and all("span" in lp.reason for lp in loops)


def test_a_second_consistent_set_of_similar_size_makes_the_pair_ambiguous(route):
    gt_a = gt_b = route
    a, b = _session("a", gt_a, 0, 1), _session("b", gt_b, 100, 2)
    true = [_true_loop(gt_a, gt_b, i, i, 0, 100) for i in (4, 16, 28, 40)]
    W = make_T(so3_exp(np.array([0, 0, 0.5])), np.array([6.0, 3.0, 0.0]))  # another place that looks the same
    false = _offset_loops(gt_a, gt_b, [(8, 10), (22, 33), (36, 20)], W)
    res = solve([a, b], true + false)
    assert res.component == {"a": 0, "b": 1}
    assert not any(lp.accepted for lp in true + false)
    (d,) = res.pairs
    assert (d.decision, d.largest, d.second) == ("ambiguous", 4, 3)
    assert all("ambiguous" in lp.reason and "4 and 3" in lp.reason for lp in true + false)


def test_a_pair_whose_loops_gnc_drops_is_not_reported_joined(route):
    """Session b's own estimate bends away from its odometry; three loops agree with the bent estimate
    (so they pass the pairwise test) but not with the odometry the joint graph holds."""
    gt_a = gt_b = route
    a = SessionPoses("a", np.arange(48), gt_a.copy(), np.repeat(np.diag([1e-6] * 3 + [1e-5] * 3)[None], 48, 0),
                     gt_a.copy())
    bent = np.array([T @ make_T(so3_exp(np.array([0, 0, 0.012 * i])), np.zeros(3)) for i, T in enumerate(gt_b)])
    b = SessionPoses("b", np.arange(100, 148), gt_b.copy(), a.cov.copy(), bent)
    loops = [JointLoop(100 + i, i, inv(gt_a[i]) @ bent[i], INFO, True) for i in (5, 22, 40)]
    res = solve([a, b], loops)
    (d,) = res.pairs
    assert d.decision == "undone by gnc", d
    assert res.component == {"a": 0, "b": 1}
    assert not any(lp.accepted for lp in loops)
    assert all(lp.reason.startswith("gnc") for lp in loops)
    # b lost its join: it keeps its own frame (its first keyframe where its own estimate has it)
    np.testing.assert_allclose(res.poses[100], bent[0], atol=1e-6)


def _noisy(T: np.ndarray, rng, sigma_t: float = 0.005, sigma_r: float = 0.0012) -> np.ndarray:
    return T @ make_T(so3_exp(rng.normal(0, sigma_r, 3)), rng.normal(0, sigma_t, 3))


def test_a_wrong_visual_link_is_dropped_and_the_true_loops_between_sessions_kept(route):
    rng = np.random.default_rng(5)
    gt_a = gt_b = route
    a, b = _session("a", gt_a, 0, 1), _session("b", gt_b, 100, 2)
    info_link = np.linalg.inv(np.diag([0.0012 ** 2] * 3 + [0.005 ** 2] * 3))
    links = [JointLoop(s0 + i, s0 + i - 1, _noisy(inv(gt[i - 1]) @ gt[i], rng), info_link, False, True, "link")
             for s0, gt in ((0, gt_a), (100, gt_b)) for i in range(1, len(gt))]
    wrong = next(lp for lp in links if lp.query == 100 + 24)
    wrong.T = wrong.T @ make_T(np.eye(3), np.array([0.0, 0.5, 0.0]))  # 0.5 m off
    inter = [_true_loop(gt_a, gt_b, i, i, 0, 100) for i in (2, 8, 14, 20, 28, 34, 40, 46)]
    without = solve([a, b], [lp for lp in links if lp is not wrong] + inter)  # the same map, that link never made
    res = solve([a, b], links + inter)
    assert not wrong.accepted and "inconsistent with the odometry" in wrong.reason
    assert sum(lp.accepted for lp in links) == len(links) - 1
    assert sum(lp.accepted for lp in inter) == 8, [lp.reason for lp in inter if not lp.accepted]
    assert res.component == {"a": 0, "b": 0}
    # the session's end: where the map without that link has it (which the links' own noise leaves ~5 cm
    # from the truth after 47 steps)
    assert np.linalg.norm(res.poses[147][:3, 3] - without.poses[147][:3, 3]) < 0.01
    assert np.linalg.norm(res.poses[147][:3, 3] - gt_b[47][:3, 3]) < 0.08


def test_a_link_and_a_visual_odometry_step_count_half_each_an_independent_odometry_in_full(route):
    from slam_lcd.map.links import gate_links
    from slam_lcd.map.pair_verdicts import SessionGraphs

    info_link = np.linalg.inv(np.diag([0.0012 ** 2] * 3 + [0.005 ** 2] * 3))
    seen = {}
    for independent in (False, True, None):
        s = _session("a", route, 0, 1)
        s.odometry_independent = independent
        link = JointLoop(1, 0, inv(s.T_odom[0]) @ s.T_odom[1], info_link, False, True, "link")
        chains = SessionChains([s], MapConfig())
        gate_links([link], chains, 0.999)
        init = {int(k): T for k, T in zip(s.ids, s.T_init, strict=True)}
        graph = SessionGraphs([s], [link], chains).known([0], [0], init)
        step = graph.at(0)  # the odometry step 0 -> 1, which the link spans
        seen[independent] = step.noiseModel().R().T @ step.noiseModel().R()
    np.testing.assert_allclose(seen[False], 0.5 * np.linalg.inv(s.cov[1]), rtol=1e-9)
    np.testing.assert_allclose(seen[True], np.linalg.inv(s.cov[1]), rtol=1e-9)
    np.testing.assert_allclose(seen[None], seen[True])  # not known: counted as independent (stated in links.py)


def test_the_batched_cycle_test_is_the_loop_gates_pair_test_one_pair_at_a_time():
    """The map's PCM and the single-session gate share one propagation: figures equal pair by pair."""
    from slam_lcd.backend.gate import ChainRelatives, pair_chi2
    from slam_lcd.map.pcm import oriented, pair_statistics

    rng = np.random.default_rng(11)
    chains, _ = _trial(20, DEPTH, True, rng)
    a, b = chains.sessions
    loops = [JointLoop(1000 + j, i, inv(a.T_odom[i]) @ b.T_odom[j] @ se3_exp(rng.normal(0, 0.05, 6)),
                       np.linalg.inv(DEPTH), True) for i, j in rng.integers(0, 41, size=(6, 2))]
    loops[2] = _flipped(loops[2])  # one seen from its other end

    class Own:  # each session's own estimate with its chain covariance, as the gate's Relatives
        def odometry(self, p, q):
            (si, i), (_, j) = chains.where[p], chains.where[q]
            c = ChainRelatives.from_steps(chains.sessions[si].T_odom, step_covariances(chains.sessions[si],
                                                                                     MapConfig()))
            X = chains.sessions[si].T_init
            return inv(X[i]) @ X[j], c.chain_cov(i, j)

    stats = pair_statistics(loops, chains)
    for i in range(len(loops)):
        for j in range(i + 1, len(loops)):
            g = sorted((oriented(loops[i], 0, chains), oriented(loops[j], 0, chains)), key=lambda x: (x.a, x.b))
            assert stats[i, j] == pytest.approx(pair_chi2(g[0], g[1], Own()), rel=1e-9)
            assert stats[i, j] == stats[j, i]


def _turning_session(name: str, T0: np.ndarray, first: int, rng) -> tuple[SessionPoses, np.ndarray]:
    """Walk 2 m in, turn a full circle in place (24 keyframes, 15 degrees each), walk 2 m on; the odometry noised
    by exactly the covariance each step gives. Returns the session and its true poses."""
    walk, turn = make_T(np.eye(3), np.array([STEP, 0, 0])), make_T(so3_exp(np.radians([0, 0, 15.0])), np.zeros(3))
    steps = [walk] * 4 + [turn] * 24 + [walk] * 4
    gt, odo, cov = [T0], [np.eye(4)], [np.full((6, 6), np.nan)]
    for S in steps:
        c = allowance(S, MapConfig())  # the front end's motion model: 0.05 rad per sqrt(rad) turned
        gt.append(gt[-1] @ S)
        odo.append(odo[-1] @ S @ se3_exp(np.linalg.cholesky(c) @ rng.normal(size=6)))
        cov.append(c)
    odo_a = np.array(odo)
    return SessionPoses(name, np.arange(first, first + len(odo)), odo_a, np.array(cov), odo_a.copy()), np.array(gt)


def test_two_sessions_that_meet_only_turning_in_place_join():
    """Each session turns a full circle where they meet (0.3 m apart): 24 true loops between keyframes that look
    the same way, over no distance but every direction. The span guard counts directions as well as metres."""
    rng = np.random.default_rng(21)
    a, gt_a = _turning_session("a", make_T(np.eye(3), np.array([-2.0, 0, 0])), 0, rng)
    # b comes from elsewhere, facing 45 degrees off a, and turns 0.3 m from where a turned
    b, gt_b = _turning_session("b", make_T(so3_exp(np.radians([0, 0, 45.0])), np.array([0.3, 0.0, 0])) @
                               make_T(np.eye(3), np.array([-2.0, 0, 0])), 100, rng)
    loop_cov = np.diag([np.radians(0.5) ** 2] * 3 + [0.03 ** 2] * 3)
    L = np.linalg.cholesky(loop_cov)
    loops = []
    for i in range(4, 28):  # a's turning keyframes; b's keyframe 3 steps behind looks the same way
        j = (i - 4 - 3) % 24 + 4
        loops.append(JointLoop(100 + j, i, inv(gt_a[i]) @ gt_b[j] @ se3_exp(L @ rng.normal(size=6)),
                               np.linalg.inv(loop_cov), True))
    res = solve([a, b], loops)
    (d,) = res.pairs
    print(f"turning in place: {d.decision}, {d.largest} of {d.offered} loops consistent, spans "
          f"{d.span_m[0]:.2f} m / {d.span_m[1]:.2f} m and {d.span_deg[0]:.0f} / {d.span_deg[1]:.0f} deg")
    assert d.decision == "joined" and d.largest >= 22 and max(d.span_m) < 0.1
    assert res.component == {"a": 0, "b": 0}
    assert np.linalg.norm(res.poses[100 + 16][:3, 3] - res.poses[16][:3, 3]) == pytest.approx(0.3, abs=0.1)
    # three of those loops, from consecutive keyframes (30 degrees of the turn), are what a look-alike gives: too short
    few = solve([a, b], [JointLoop(lp.query, lp.match, lp.T, lp.info, True) for lp in loops[:3]])
    assert few.pairs[0].decision == "too short a span" and few.component == {"a": 0, "b": 1}
    # by distance alone the same loops span too short a stretch, and the reason gives both figures
    off = solve([a, b], [JointLoop(lp.query, lp.match, lp.T, lp.info, True) for lp in loops],
                MapConfig(min_join_view_angle_deg=360.0))
    assert off.pairs[0].decision == "too short a span" and off.component == {"a": 0, "b": 1}
    assert re.search(r"\(0\.0 m and 0\.0 m, viewing directions 1[78]\d deg and 1[78]\d deg apart; 2 m or 360 deg "
                     r"needed in each\)", off.pairs[0].reason), off.pairs[0].reason
