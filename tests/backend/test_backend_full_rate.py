"""Full-rate correction: every odometry stamp gets a corrected pose (KITTI-00 scenario)."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.backend import correct_full_rate
from slam_lcd.backend.config import BackendConfig
from slam_lcd.errors import InputError, UnsortedStampsError
from slam_lcd.types import Trajectory

from support.scenario import ScenarioConfig, ate_rmse, make_scenario, run_scenario

KF_EVERY = 6


@pytest.fixture(scope="module")
def full_and_keyframes(shared_data):
    """Odometry at every frame; keyframes every KF_EVERY-th frame, kept between frames 40 and 4400."""
    d = shared_data / "trajectories"
    sc = make_scenario(d / "KITTI_00_gt.txt", ScenarioConfig(stride=1, loop_every=100000), d / "KITTI_00_gt_times.txt")
    sub = make_scenario(d / "KITTI_00_gt.txt", ScenarioConfig(stride=KF_EVERY), d / "KITTI_00_gt_times.txt")
    # build the keyframe problem from the full-rate odometry so both share one odometry
    sub.odom = sc.odom[np.arange(0, len(sc.odom), KF_EVERY)]
    g, res = run_scenario(sub, BackendConfig())
    kf_idx = np.arange(0, len(sc.odom), KF_EVERY)
    keep = (kf_idx >= 40) & (kf_idx <= 4400)
    return sc, kf_idx[keep], sub.odom[keep], g.estimate_array()[keep], res


def test_full_rate_matches_keyframes_and_is_smooth(full_and_keyframes):
    sc, kf_idx, kf_odom, kf_corr, res = full_and_keyframes
    odo = Trajectory(sc.stamps, sc.odom)
    out = correct_full_rate(odo, sc.stamps[kf_idx], kf_odom, kf_corr)
    assert len(out) == len(odo) and np.array_equal(out.stamps, odo.stamps)
    # exact at keyframes
    assert np.abs(out.poses[kf_idx] - kf_corr).max() < 1e-9
    # no jumps: consecutive corrected steps stay close to the odometry steps
    step_odo = np.linalg.norm(np.diff(sc.odom[:, :3, 3], axis=0), axis=1)
    step_out = np.linalg.norm(np.diff(out.positions, axis=0), axis=1)
    assert np.abs(step_out - step_odo).max() < 0.2
    # the full-rate trajectory is as good as the keyframes, and far better than odometry
    ate_full = ate_rmse(sc.gt, out.poses)
    ate_odo = ate_rmse(sc.gt, sc.odom)
    print(f"\nfull rate ({len(out)} stamps from {len(kf_idx)} keyframes): ATE {ate_full:.2f} m, "
          f"keyframes {res.ate:.2f} m, odometry {ate_odo:.2f} m")
    assert ate_full < 0.3 * ate_odo
    assert ate_full < 1.2 * ate_rmse(sc.gt[kf_idx], kf_corr) + 0.5
    # before the first / after the last keyframe: the end correction carried rigidly
    C0 = kf_corr[0] @ np.linalg.inv(kf_odom[0])
    np.testing.assert_allclose(out.poses[:kf_idx[0]], C0 @ sc.odom[:kf_idx[0]], atol=1e-9)
    C1 = kf_corr[-1] @ np.linalg.inv(kf_odom[-1])
    np.testing.assert_allclose(out.poses[kf_idx[-1]:], C1 @ sc.odom[kf_idx[-1]:], atol=1e-9)


def test_full_rate_bad_inputs():
    odo = Trajectory(np.arange(5), np.tile(np.eye(4), (5, 1, 1)))
    with pytest.raises(InputError):
        correct_full_rate(odo, [0, 2], np.tile(np.eye(4), (2, 1, 1)), np.tile(np.eye(4), (3, 1, 1)))
    with pytest.raises(UnsortedStampsError):
        correct_full_rate(odo, [2, 0], np.tile(np.eye(4), (2, 1, 1)), np.tile(np.eye(4), (2, 1, 1)))
