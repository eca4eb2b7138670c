"""Keyframe selection on the real nav2 TurtleBot MCAP odometry, and covariance accumulation."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.frontend import FrontendConfig, KeyframeSelector, select_keyframes
from slam_lcd.geometry import compose_covariance, inv, rotation_angle, se3_exp, se3_log
from slam_lcd.types import Trajectory


@pytest.fixture(scope="module")
def turtlebot_odom(shared_data) -> Trajectory:
    from slam_lcd.io import open_log
    from slam_lcd.io.decode import decode_pose

    with open_log(shared_data / "bags" / "nav2_turtlebot.mcap") as reader:
        rows = [(m.stamp, *decode_pose(m.msg)) for m in reader.messages(["/odom"])]
    stamps = np.array([r[0] for r in rows], np.int64)
    order = np.argsort(stamps, kind="stable")
    return Trajectory(stamps=stamps[order], poses=np.array([rows[i][1] for i in order]))


def _check_thresholds(traj: Trajectory, idx: list[int], conf: FrontendConfig):
    """Every keyframe meets a threshold w.r.t. the previous one; no frame in between does."""
    kf_set = set(idx)
    last = idx[0]
    assert last == 0
    for i in range(1, len(traj)):
        T = inv(traj.poses[last]) @ traj.poses[i]
        d = np.linalg.norm(T[:3, 3])
        a = np.degrees(rotation_angle(T[:3, :3]))
        dt = (traj.stamps[i] - traj.stamps[last]) * 1e-9
        hit = d >= conf.kf_min_translation or a >= conf.kf_min_rotation_deg or (
            conf.kf_max_interval_s > 0 and dt >= conf.kf_max_interval_s)
        assert hit == (i in kf_set), (i, d, a, dt)
        if hit:
            last = i


@pytest.mark.parametrize("trans,rot", [(0.5, 15.0), (1.5, 45.0)])
def test_keyframes_follow_odometry_thresholds(turtlebot_odom, trans, rot):
    conf = FrontendConfig(kf_min_translation=trans, kf_min_rotation_deg=rot, kf_max_interval_s=0.0)
    idx = select_keyframes(turtlebot_odom, conf)
    _check_thresholds(turtlebot_odom, idx, conf)
    path = turtlebot_odom.path_length()
    # translation alone bounds the count from above: path / trans (+ rotation-triggered ones)
    assert 1 + 0.5 * path / trans <= len(idx) <= 1 + path / trans + 40, (len(idx), path)


def test_keyframe_count_shrinks_with_looser_thresholds(turtlebot_odom):
    tight = select_keyframes(turtlebot_odom,
                             FrontendConfig(kf_min_translation=0.5, kf_min_rotation_deg=15, kf_max_interval_s=0))
    loose = select_keyframes(turtlebot_odom,
                             FrontendConfig(kf_min_translation=1.5, kf_min_rotation_deg=45, kf_max_interval_s=0))
    assert len(loose) < 0.5 * len(tight)


def test_time_threshold_alone(turtlebot_odom):
    conf = FrontendConfig(kf_min_translation=1e9, kf_min_rotation_deg=1e9, kf_max_interval_s=10.0, kf_min_overlap=0)
    idx = select_keyframes(turtlebot_odom, conf)
    dur = (turtlebot_odom.stamps[-1] - turtlebot_odom.stamps[0]) * 1e-9
    assert len(idx) == 1 + int(dur // 10.0) or len(idx) == int(dur // 10.0)
    _check_thresholds(turtlebot_odom, idx, conf)


def test_relative_covariances_compose_like_gtsam():
    """Accumulated covariance equals the closed-form composition, and matches Monte Carlo."""
    rng = np.random.default_rng(1)
    steps = [se3_exp(rng.normal(0, [0.05] * 3 + [0.3] * 3)) for _ in range(4)]
    sig = np.diag([0.01, 0.02, 0.015, 0.05, 0.03, 0.04]) ** 2
    conf = FrontendConfig(odom_covariance="relative", kf_min_translation=1e9, kf_min_rotation_deg=1e9,
                          kf_max_interval_s=0, odom_min_sigma_trans=0.0, odom_min_sigma_rot_deg=0.0)
    sel = KeyframeSelector(conf)
    T = np.eye(4)
    sel.push(0, T)
    expect = np.zeros((6, 6))
    for k, S in enumerate(steps):
        T = T @ S
        sel.push(k + 1, T, sig)
        expect = compose_covariance(expect, S, sig)
    # Monte Carlo of the 4-step chain
    samples = []
    L = np.linalg.cholesky(sig)
    for _ in range(1500):
        Tn = np.eye(4)
        for S in steps:
            Tn = Tn @ S @ se3_exp(L @ rng.normal(size=6))
        samples.append(se3_log(inv(np.linalg.multi_dot(steps)) @ Tn))
    mc = np.cov(np.array(samples).T)
    assert np.allclose(np.sqrt(np.diag(mc)), np.sqrt(np.diag(expect)), rtol=0.12)
    # the selector's running covariance for the 4-step chain is that composition
    conf2 = FrontendConfig(**{**conf.__dict__, "kf_min_translation": 0.01})
    sel2 = KeyframeSelector(conf2)
    sel2.push(0, np.eye(4))
    T = np.eye(4)
    for k, S in enumerate(steps[:1]):
        T = T @ S
        assert sel2.push(k + 1, T, sig)
    assert np.allclose(sel2.keyframes[-1].covariance_since_last, sig)


def test_absolute_covariances_are_differenced():
    conf = FrontendConfig(odom_covariance="absolute", kf_min_translation=1.0, kf_max_interval_s=0)
    sel = KeyframeSelector(conf)
    C = np.diag([1e-4] * 3 + [1e-2] * 3)
    for k in range(21):
        T = se3_exp([0, 0, 0, 0.1 * k, 0, 0])
        sel.push(k * 10**8, T, C * (1 + k))  # covariance growing by C per 0.1 m
    kfs = sel.keyframes
    assert len(kfs) == 3  # at 0, 1.0 m and 2.0 m
    c = kfs[1].covariance_since_last
    assert np.allclose(np.diag(c)[3:], 10 * 1e-2, rtol=0.05)


def test_segment_break_promotes_previous_frame_and_adds_large_noise():
    conf = FrontendConfig(kf_min_translation=5.0, kf_max_interval_s=0)
    sel = KeyframeSelector(conf)
    for k in range(5):
        sel.push(k, se3_exp([0, 0, 0, 0.2 * k, 0, 0]))
    assert len(sel.keyframes) == 1
    assert sel.push(5, se3_exp([0, 0, 0, 1.0, 0, 0]), segment_start=True)
    assert [kf.stamp for kf in sel.keyframes] == [0, 4, 5]
    assert sel.reasons[-2:] == ["before-break", "segment-break"]
    assert np.sqrt(sel.keyframes[-1].covariance_since_last[3, 3]) >= 1.0
    assert np.sqrt(sel.keyframes[1].covariance_since_last[3, 3]) < 0.1


@pytest.mark.parametrize("covariances", ["none", "zero", "model"])
def test_the_modelled_covariance_does_not_shrink_with_the_odometry_rate(covariances):
    """A keyframe step's modelled covariance is the same at 10, 50 and 200 Hz (a random walk per metre)."""
    conf = FrontendConfig(kf_min_translation=0.5, kf_max_interval_s=0, kf_min_overlap=0,
                          odom_covariance="model" if covariances == "model" else "absolute")
    got = {}
    for rate in (10, 50, 200):
        sel = KeyframeSelector(conf)
        for k in range(int(2.0 * rate) + 1):  # 2 m straight at 1 m/s, turning 0.1 rad/s
            T = se3_exp([0, 0, 0.1 * k / rate, 0, 0, 0]) @ se3_exp([0, 0, 0, k / rate, 0, 0])
            sel.push(int(k * 1e9 / rate), T, None if covariances == "none" else np.zeros((6, 6)))
        assert {kf.covariance_source for kf in sel.keyframes[1:]} == {"model"}
        got[rate] = sel.keyframes[1].covariance_since_last
    s_t = conf.odom_trans_sigma_per_sqrt_m * np.sqrt(0.5)
    for rate, c in got.items():
        np.testing.assert_allclose(np.sqrt(c[3, 3]), s_t, rtol=0.05, err_msg=f"{rate} Hz")
        np.testing.assert_allclose(c, got[10], rtol=0.05, err_msg=f"{rate} Hz against 10 Hz")


def test_given_covariances_are_marked_given_and_a_step_missing_one_is_modelled():
    conf = FrontendConfig(odom_covariance="relative", kf_min_translation=0.5, kf_max_interval_s=0, kf_min_overlap=0)
    sel = KeyframeSelector(conf)
    C = np.diag([1e-6] * 3 + [1e-4] * 3)
    for k in range(21):  # 0.1 m a sample; the sample at 1.3 m gives no covariance
        sel.push(k * 10**8, se3_exp([0, 0, 0, 0.1 * k, 0, 0]), None if k == 13 else C)
    assert [kf.covariance_source for kf in sel.keyframes] == ["given", "given", "given", "model", "given"]
