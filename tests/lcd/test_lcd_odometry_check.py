"""A tight-rule loop must agree with the odometry between its keyframes within a drift budget."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.geometry import inv
from slam_lcd.lcd import LcdConfig, LoopDetector
from slam_lcd.lcd.odometry_check import drift_budget, odometry_disagreement, odometry_drift_reason


def _pose(yaw_deg: float, x: float, y: float) -> np.ndarray:
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:2, :2] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    T[:2, 3] = x, y
    return T


def test_disagreement_is_zero_for_the_odometry_pose_and_the_same_both_ways():
    T_wm, T_wq = _pose(10, 1.0, 2.0), _pose(100, 6.0, -1.0)
    T_odom = inv(T_wm) @ T_wq
    assert np.allclose(odometry_disagreement(T_odom, T_wm, T_wq), (0.0, 0.0), atol=1e-9)
    T_loop = T_odom @ _pose(30, 0.4, -0.2)  # 30 deg, ~0.45 m off
    t, r = odometry_disagreement(T_loop, T_wm, T_wq)
    assert np.isclose(r, 30.0) and t >= np.hypot(0.4, 0.2) - 1e-9
    # query and match swapped: the other keyframe's view of the same disagreement
    assert np.allclose(odometry_disagreement(inv(T_loop), T_wq, T_wm), (t, r))


def test_budget_grows_with_the_distance_travelled():
    conf = LcdConfig()
    assert drift_budget(0.0, conf) == (conf.odometry_drift_floor_m, conf.odometry_drift_floor_deg)
    bt, br = drift_budget(40.0, conf)
    assert np.isclose(bt, conf.odometry_drift_floor_m + 40 * conf.odometry_max_drift)
    assert np.isclose(br, conf.odometry_drift_floor_deg + 40 * conf.odometry_max_drift_deg_per_m)
    assert drift_budget(-40.0, conf) == (bt, br)  # query before match (swapped roles)


@pytest.mark.parametrize("off_deg, off_m, path_m, reason", [
    (18.0, 2.2, 43.0, ""),  # a wide-baseline revisit after one lap of 2-4 % odometry drift (demo world)
    (86.0, 8.2, 11.8, "odometry_disagrees"),  # the look-alike loop of the 10-lap demo log (67 -> 44)
    (3.0, 3.0, 5.0, "odometry_disagrees"),  # 3 m off after 5 m of travel: translation alone
    (40.0, 0.1, 5.0, "odometry_disagrees"),  # rotation alone
])
def test_verdicts_on_measured_cases(off_deg, off_m, path_m, reason):
    T_wm, T_wq = _pose(0, 0, 0), _pose(45, 3.0, 4.0)
    T_loop = inv(T_wm) @ T_wq @ _pose(off_deg, off_m, 0.0)
    why, figures = odometry_drift_reason(T_loop, T_wm, T_wq, path_m, LcdConfig())
    assert why == reason
    assert np.isclose(figures["odometry_disagreement_deg"], off_deg, atol=1e-3)
    assert figures["odometry_path_m"] == round(path_m, 3)


def test_non_finite_odometry_is_not_taken_as_agreement():
    T = np.eye(4)
    bad = np.full((4, 4), np.nan)
    assert odometry_drift_reason(T, bad, T, 10.0, LcdConfig())[0] == "odometry_unknown"


def test_detector_keeps_the_odometry_path_of_each_keyframe():
    from slam_lcd.types import Features, Keyframe

    det = LoopDetector(LcdConfig(pose=False))
    rng = np.random.default_rng(0)
    xs = [0.0, 1.0, 3.0, 2.0]
    for k, x in enumerate(xs):
        d = rng.standard_normal((50, 256)).astype(np.float32)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        f = Features(keypoints=rng.uniform(0, 300, (50, 2)).astype(np.float32), scores=np.ones(50, np.float32),
                     descriptors=d, image_size=(320, 240), kind="superpoint")
        det.add(Keyframe(k, k * 10**9, _pose(0, x, 0.0), features=f))
    assert [det._entries[k].path_m for k in range(4)] == [0.0, 1.0, 3.0, 4.0]
