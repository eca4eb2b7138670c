"""The standalone loop gate and loop factors, on numpy arrays and small GTSAM graphs."""
from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import X

from slam_lcd.backend import PoseGraph
from slam_lcd.backend.config import BackendConfig
from slam_lcd.backend.gate import ArrayRelatives, Chi2Gate, GateLoop, PcmGate, default_gate, relative_from_marginals
from slam_lcd.backend.relatives import MarginalRelatives
from slam_lcd.errors import InputError
from slam_lcd.geometry import adjoint, inv, se3_exp, se3_log
from slam_lcd.types import LoopClosure


def _random_pose(rng, scale=1.0):
    return se3_exp(np.r_[rng.normal(0, 0.5, 3), rng.normal(0, scale, 3)])


def _random_info(rng):
    A = rng.normal(size=(6, 6))
    return A @ A.T + 6 * np.diag([400, 400, 400, 100, 100, 100.0])


@pytest.mark.parametrize("kernel", [None, "cauchy", "huber"])
def test_between_factor_agrees_with_a_hand_built_factor(kernel):
    """Error and Jacobians of LoopClosure.between_factor = BetweenFactorPose3 built by hand (1e-9)."""
    rng = np.random.default_rng(7)
    Z, info = _random_pose(rng), _random_info(rng)
    c = LoopClosure(query_id=5, match_id=2, T_match_query=Z, information=info)
    km, kq = X(2), X(5)
    ours = c.between_factor(km, kq, kernel=kernel)
    noise = gtsam.noiseModel.Gaussian.Information(info)
    if kernel is not None:
        m = {"cauchy": gtsam.noiseModel.mEstimator.Cauchy, "huber": gtsam.noiseModel.mEstimator.Huber}[kernel]
        noise = gtsam.noiseModel.Robust.Create(m.Create(3.0), noise)
    hand = gtsam.BetweenFactorPose3(km, kq, gtsam.Pose3(Z), noise)
    for _ in range(3):  # random linearisation points
        v = gtsam.Values()
        Xa = _random_pose(rng, 3.0)
        v.insert(km, gtsam.Pose3(Xa))
        v.insert(kq, gtsam.Pose3(Xa @ Z @ se3_exp(rng.normal(0, 0.05, 6))))
        assert ours.keys() == hand.keys()
        assert abs(ours.error(v) - hand.error(v)) <= 1e-9 * max(1.0, hand.error(v))
        A1, b1 = ours.linearize(v).jacobian()
        A2, b2 = hand.linearize(v).jacobian()
        assert np.allclose(A1, A2, rtol=0, atol=1e-9 * max(1.0, np.abs(A2).max()))
        assert np.allclose(b1, b2, rtol=0, atol=1e-9)
        if kernel is None:  # the convention: error = 1/2 Log(Z^-1 Xa^-1 Xb)^T Info Log(...)
            e = se3_log(inv(Z) @ inv(v.atPose3(km).matrix()) @ v.atPose3(kq).matrix())
            assert ours.error(v) == pytest.approx(0.5 * e @ info @ e, rel=1e-9)


def test_between_factor_refuses_a_loop_without_pose_or_information():
    bad_pose = LoopClosure(1, 0, np.full((4, 4), np.nan), np.eye(6))
    with pytest.raises(InputError):
        bad_pose.between_factor(0, 1)
    with pytest.raises(InputError):
        LoopClosure(1, 0, np.eye(4), np.zeros((6, 6))).between_factor(0, 1)
    from slam_lcd.backend import between_factors

    g = between_factors([LoopClosure(3, 1, np.eye(4), np.eye(6)), LoopClosure(4, 2, np.eye(4), np.eye(6))], X)
    assert g.size() == 2 and list(g.at(1).keys()) == [X(2), X(4)]


def _line(n=60, step=1.0):
    return np.array([se3_exp(np.r_[0, 0, 0.05 * k, step * k, 0, 0]) for k in range(n)])


def test_chi2_and_pcm_gates_on_arrays():
    """Gate decisions from plain arrays: poses + marginal covariances, no graph."""
    poses = _line()
    covs = np.array([np.diag([1e-4] * 3 + [1e-2] * 3)] * len(poses))
    rel = ArrayRelatives(poses, covs)
    cov_loop = np.diag([1e-4] * 3 + [1e-3] * 3)
    true = GateLoop(2, 50, inv(poses[2]) @ poses[50], cov_loop)
    false = GateLoop(3, 51, inv(poses[3]) @ poses[51] @ se3_exp(np.r_[0, 0, 0.3, 2.0, 0, 0]), cov_loop)
    for gate in (Chi2Gate(), PcmGate()):
        d = gate.check(true, rel, [])
        assert d.accept and d.chi2 < 1e-6
        d = gate.check(false, rel, [])
        assert not d.accept and d.chi2 > d.threshold and "chi2" in d.reason
    # PCM: a loop agreeing with the estimate but contradicting two accepted neighbours is vetoed
    class VagueEstimate:  # a vague estimate (passes the chi2 test), precise odometry (for the PCM cycles)
        estimate = ArrayRelatives(poses, np.array([np.diag([1e-2] * 3 + [10.0] * 3)] * len(poses))).estimate
        odometry = ArrayRelatives(poses, np.array([np.diag([1e-6] * 3 + [1e-4] * 3)] * len(poses))).estimate

    rel2 = VagueEstimate()
    near = [GateLoop(4 + i, 52 + i, inv(poses[4 + i]) @ poses[52 + i], cov_loop, accepted=True) for i in range(3)]
    shifted = GateLoop(5, 53, inv(poses[5]) @ poses[53] @ se3_exp(np.r_[0, 0, 0.02, 1.0, 0, 0]), cov_loop)
    assert Chi2Gate().check(shifted, rel2).accept
    d = PcmGate().check(shifted, rel2, near)
    assert not d.accept and d.stage == "pairwise" and d.pairwise_inconsistent == 3
    assert PcmGate().check(GateLoop(5, 53, inv(poses[5]) @ poses[53], cov_loop), rel2, near).accept
    assert isinstance(default_gate(BackendConfig()), PcmGate)


def test_relative_covariance_from_marginals_matches_sampling():
    rng = np.random.default_rng(3)
    Xa, Xb = _random_pose(rng), _random_pose(rng)
    L = rng.normal(size=(12, 12)) * 0.02
    S = L @ L.T
    T, C = relative_from_marginals(Xa, Xb, S[:6, :6], S[6:, 6:], S[:6, 6:])
    d = rng.multivariate_normal(np.zeros(12), S, size=4000)
    errs = np.array([se3_log(inv(T) @ inv(Xa @ se3_exp(x[:6])) @ Xb @ se3_exp(x[6:])) for x in d])
    assert np.allclose(np.cov(errs.T), C, atol=3e-4 + 0.1 * np.abs(C).max())
    assert np.allclose(adjoint(np.eye(4)), np.eye(6))


def _user_graph(n=80, seed=0):
    """A user's iSAM2: Symbol keys, drifting odometry, a GPS-like prior every 20 poses."""
    rng = np.random.default_rng(seed)
    gt = np.array([se3_exp(np.r_[0, 0, 2 * np.pi * k / 40, 0, 0, 0]) @ se3_exp(np.r_[0, 0, 0, 6.0, 0, 0])
                   for k in range(n)])  # two laps of a circle, radius 6 m
    isam = gtsam.ISAM2()
    odo_sig = np.array([1e-3, 1e-3, 0.01, 0.03, 0.03, 1e-3])
    user = []
    est = gt[0]
    for i in range(n):
        f, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
        if i == 0:
            f.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(gt[0]), gtsam.noiseModel.Isotropic.Sigma(6, 1e-4)))
        else:
            step = inv(gt[i - 1]) @ gt[i] @ se3_exp(np.r_[0, 0, 0.01, 0.02, 0, 0] + rng.normal(0, 1, 6) * odo_sig)
            f.add(gtsam.BetweenFactorPose3(X(i - 1), X(i), gtsam.Pose3(step),
                                           gtsam.noiseModel.Diagonal.Sigmas(odo_sig)))
            est = est @ step
        if i and i % 20 == 0:
            f.add(gtsam.PriorFactorPose3(X(i), gtsam.Pose3(gt[i]),
                                         gtsam.noiseModel.Diagonal.Sigmas([0.1] * 3 + [0.5] * 3)))
        v.insert(X(i), gtsam.Pose3(est))
        slots = isam.update(f, v).getNewFactorsIndices()
        user += [(int(s), f.at(j)) for j, s in enumerate(slots)]
    return gt, isam, user


def _user_factors_untouched(isam, user, graph):
    fs = isam.getFactorsUnsafe()
    ours = set(graph.loop_factor_indices())
    assert ours.isdisjoint(s for s, _ in user)
    for slot, f in user:  # every factor the user added is still in its slot, the same object
        assert fs.at(slot) is f
    present = [i for i in range(fs.size()) if fs.at(i) is not None]
    assert len(present) == len(user) + len(ours)


def test_gnc_on_a_users_graph_removes_only_its_own_loops():
    """'gnc' mode: every loop goes in, GNC takes the false ones out; the user's factors stay as they were."""
    gt, isam, user = _user_graph()
    g = PoseGraph(BackendConfig(outlier_rejection="gnc"), isam=isam, key=lambda i: X(i), add_odometry=False)
    for i in range(len(gt)):
        g.add_keyframe(i, i * 10**9)
    info = np.diag([1e4] * 3 + [400.0] * 3)
    truth = []
    for q in range(45, 80, 3):  # true revisits of lap one
        g.add_loop(LoopClosure(q, q - 40, inv(gt[q - 40]) @ gt[q], info))
        truth.append(True)
    for q in range(46, 80, 7):  # false loops: a plausible-looking pose between far-apart places
        g.add_loop(LoopClosure(q, q - 20, se3_exp(np.r_[0, 0, 0.1, 1.0, 0.5, 0]), info))
        truth.append(False)
    before = {s: f.error(isam.calculateEstimate()) for s, f in user}
    assert g.n_loops == len(truth) and len(g.loop_factor_indices()) == len(truth)
    g.finalize()
    verdicts = [r.verdict == "accepted" for r in g.loop_records]
    assert verdicts == truth
    assert all(r.stage == "gnc" for r, t in zip(g.loop_records, truth, strict=True) if not t)
    _user_factors_untouched(isam, user, g)
    # the user's factors are the same factors: same error as before at the same values
    v0 = isam.calculateEstimate()
    for s, f in user:
        assert isam.getFactorsUnsafe().at(s).error(v0) == f.error(v0)
    assert len(before) == len(user)
    est = np.array([isam.calculateEstimatePose3(X(i)).matrix() for i in range(len(gt))])
    assert np.sqrt(np.mean(np.sum((est[:, :3, 3] - gt[:, :3, 3]) ** 2, 1))) < 0.5


def test_gate_on_a_users_graph_asks_isam2_marginals():
    gt, isam, user = _user_graph()
    rel = MarginalRelatives(lambda i: X(i), isam=isam)
    T, C = rel.estimate(5, 60)
    assert T.shape == (4, 4) and np.all(np.linalg.eigvalsh(C) > 0)
    # the gate alone on the user's graph: no PoseGraph involved
    info = np.diag([1e4] * 3 + [400.0] * 3)
    good = LoopClosure(60, 20, inv(gt[20]) @ gt[60], info)
    bad = LoopClosure(60, 5, se3_exp(np.r_[0, 0, 0.5, 3.0, 0, 0]), info)
    assert PcmGate().check(GateLoop.from_closure(good, 20, 60), rel).accept
    d = Chi2Gate().check(GateLoop.from_closure(bad, 5, 60), rel)
    assert not d.accept and d.chi2 > d.threshold
    values = isam.calculateEstimate()
    joint = MarginalRelatives(lambda i: X(i), marginals=gtsam.Marginals(isam.getFactorsUnsafe(), values), values=values)
    Tj, Cj = joint.estimate(20, 60)
    assert np.allclose(Tj, rel.estimate(20, 60)[0], atol=1e-9)
    # the exact joint marginal knows the two poses are correlated: smaller than the uncorrelated bound
    assert np.trace(Cj) < np.trace(rel.estimate(20, 60)[1])
    assert PcmGate().check(GateLoop.from_closure(good, 20, 60), joint).accept
    g = PoseGraph(BackendConfig(), isam=isam, key=lambda i: X(i), add_odometry=False)
    with pytest.raises(InputError):
        g.add_loop(LoopClosure(1, 0, np.eye(4), np.eye(6)))  # keyframes never registered
    for i in range(len(gt)):
        g.add_keyframe(i, i * 10**9)
    far = g.add_loop(LoopClosure(60, 5, se3_exp(np.r_[0, 0, 0.5, 3.0, 0, 0]), np.diag([1e4] * 3 + [400.0] * 3)))
    assert far.verdict == "rejected" and "chi2" in far.reason
    ok = g.add_loop(LoopClosure(60, 20, inv(gt[20]) @ gt[60], np.diag([1e4] * 3 + [400.0] * 3)))
    assert ok.verdict == "accepted"
    _user_factors_untouched(isam, user, g)


@pytest.mark.parametrize("covariances", ["zero", "model"])
def test_where_the_front_end_modelled_the_covariance_the_gate_chains_what_the_maps_pcm_chains(covariances):
    """The single-session gate's chain covariance over modelled steps is PCM's per-metre allowance chain."""
    from slam_lcd.map.config import MapConfig
    from slam_lcd.map.pcm import SessionChains

    from support.odometry_routes import drive, open_route, session_of

    kfs = drive(open_route(10.0, length_m=30.0), 3, covariances)[:50]
    assert {k.covariance_source for k in kfs[1:]} == {"model"}
    pg = PoseGraph()
    for k in kfs:
        pg.add_keyframe(k.id, k.stamp, k.T_world_body, k.covariance_since_last)
    chains = SessionChains([session_of("s", kfs, 0)], MapConfig())
    for i, j in ((0, 1), (3, 20), (10, 49)):
        gate_T, gate_S = pg._relatives.odometry(i, j)
        pcm_T, pcm_S = chains.odometry(i, j)
        np.testing.assert_allclose(gate_T, pcm_T, atol=1e-12)
        np.testing.assert_allclose(gate_S, pcm_S, rtol=0.02, atol=1e-9)
