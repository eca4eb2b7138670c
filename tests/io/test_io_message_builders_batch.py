"""Batched pose conversions give exactly the per-pose messages (corrected.mcap writes them in bulk)."""
import numpy as np
import pytest

from slam_lcd.errors import InvalidPoseError
from slam_lcd.geometry import se3_exp
from slam_lcd.io import message_builders as M
from slam_lcd.io.transforms import tq_from_pose, tq_from_poses
from slam_lcd.types import Trajectory


def _poses(n, seed=0):
    rng = np.random.default_rng(seed)
    Ts = np.stack([se3_exp(rng.normal(size=6) * [1, 1, 1, 2, 2, 2]) for _ in range(n)])
    Ts[3, :3, :3] = np.diag([1.0, -1.0, -1.0])  # a 180-degree turn (Shepperd's other branches)
    return Ts


def test_batched_tq_equals_per_pose():
    Ts = _poses(40)
    t, q = tq_from_poses(Ts)
    for i, T in enumerate(Ts):
        ti, qi = tq_from_pose(T)
        assert np.array_equal(t[i], ti) and np.array_equal(q[i], qi)


def test_batched_tq_refuses_what_the_single_one_refuses():
    Ts = _poses(5)
    bad = Ts.copy()
    bad[2, 0, 0] = np.nan
    with pytest.raises(InvalidPoseError, match="pose 2"):
        tq_from_poses(bad)
    bad = Ts.copy()
    bad[4, :3, :3] *= 2.0
    with pytest.raises(InvalidPoseError, match="pose 4"):
        tq_from_poses(bad)
    assert tq_from_poses(np.zeros((0, 4, 4)))[0].shape == (0, 3)


def test_batched_messages_equal_single_ones():
    Ts = _poses(12)
    stamps = np.arange(12, dtype=np.int64) * 10**8 + 5
    for a, (T, s) in zip(M.pose_stamped_msgs(Ts, stamps, "map"), zip(Ts, stamps.tolist(), strict=True), strict=True):
        assert a == M.pose_stamped_msg(T, s, "map")
    for a, (T, s) in zip(M.tf_messages(Ts, stamps, "map", "odom"), zip(Ts, stamps.tolist(), strict=True), strict=True):
        assert a == M.tf_message([(T, s, "map", "odom")])
    traj = Trajectory(stamps, Ts)
    paths = M.growing_path_msgs(traj, [1, 5, 12], "map")
    for e, p in zip([1, 5, 12], paths, strict=True):
        assert p == M.path_msg(Trajectory(stamps[:e], Ts[:e]), "map")
