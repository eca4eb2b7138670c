"""Essential-matrix verification and metric loop pose (PnP + refinement + information)."""
from __future__ import annotations

import numpy as np

from slam_lcd.geometry import adjoint, inv, se3_exp
from slam_lcd.lcd import LcdConfig, estimate_loop_pose, verify_epipolar
from slam_lcd.types import CameraModel, Features, Keyframe
from slam_lcd.vision.pnp import _residuals_and_jacobian

CAM = CameraModel(width=640, height=480, fx=500.0, fy=500.0, cx=320.0, cy=240.0)


def _project(T_world_cam, X):
    T = inv(T_world_cam)
    P = X @ T[:3, :3].T + T[:3, 3]
    uv = P[:, :2] / P[:, 2:3] * [CAM.fx, CAM.fy] + [CAM.cx, CAM.cy]
    return uv, P[:, 2]


def _rgbd_pair(seed=0, noise_px=0.3, T_body_camera=None):
    if T_body_camera is None:
        T_body_camera = np.eye(4)
    rng = np.random.default_rng(seed)
    T_wb_m = np.eye(4)
    T_wb_q = T_body_camera @ se3_exp(np.array([0.02, -0.1, 0.03, 0.4, -0.1, 0.3])) @ inv(T_body_camera)
    T_wc_m, T_wc_q = T_wb_m @ T_body_camera, T_wb_q @ T_body_camera
    Xc = rng.uniform([-3, -2, 3], [3, 2, 8], size=(300, 3))  # points in front of the match camera
    X = Xc @ T_wc_m[:3, :3].T + T_wc_m[:3, 3]
    uv_m, z_m = _project(T_wc_m, X)
    uv_q, _ = _project(T_wc_q, X)
    uv_q = uv_q + rng.normal(0, noise_px, uv_q.shape)
    ok = (uv_m[:, 0] > 1) & (uv_m[:, 0] < 638) & (uv_m[:, 1] > 1) & (uv_m[:, 1] < 478)
    ok &= (uv_q[:, 0] > 1) & (uv_q[:, 0] < 638) & (uv_q[:, 1] > 1) & (uv_q[:, 1] < 478)
    X, uv_m, uv_q, z_m = X[ok], uv_m[ok], uv_q[ok], z_m[ok]
    depth = np.zeros((480, 640), np.float32)
    # keypoints at pixel centres of the match image so that nearest-pixel depth lookup is exact
    uv_m = np.round(uv_m)
    xn = (uv_m - [CAM.cx, CAM.cy]) / [CAM.fx, CAM.fy]
    Pm = np.column_stack([xn * z_m[:, None], z_m])  # camera-m points for the rounded pixels
    Xw = Pm @ T_wc_m[:3, :3].T + T_wc_m[:3, 3]
    uv_q, _ = _project(T_wc_q, Xw)
    uv_q = uv_q + rng.normal(0, noise_px, uv_q.shape)
    depth[uv_m[:, 1].astype(int), uv_m[:, 0].astype(int)] = z_m
    n = len(X)
    fm = Features(uv_m.astype(np.float32), np.ones(n, np.float32), np.zeros((n, 4), np.float32), (640, 480))
    fq = Features(uv_q.astype(np.float32), np.ones(n, np.float32), np.zeros((n, 4), np.float32), (640, 480))
    kf_m = Keyframe(0, 0, T_wb_m, camera=CAM, depth=depth, features=fm, T_body_camera=T_body_camera)
    kf_q = Keyframe(1, 1, T_wb_q, camera=CAM, features=fq, T_body_camera=T_body_camera)
    matches = np.column_stack([np.arange(n), np.arange(n)])
    return kf_q, kf_m, matches, inv(T_wb_m) @ T_wb_q


def _pose_error(T, T_gt):
    D = inv(T_gt) @ T
    ang = np.degrees(np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1, 1)))
    return float(np.linalg.norm(D[:3, 3])), float(ang)


def test_rgbd_pose_recovered_with_information():
    kf_q, kf_m, matches, T_gt = _rgbd_pair()
    v = estimate_loop_pose(kf_q, kf_m, matches, LcdConfig())
    assert v.ok, v.reason
    t_err, r_err = _pose_error(v.T_match_query, T_gt)
    assert t_err < 0.01 and r_err < 0.1
    assert v.source == "rgbd" and v.inliers > 0.9 * len(matches) and v.rms < 1.0
    assert v.information.shape == (6, 6)
    assert np.all(np.linalg.eigvalsh(v.information) > 0)


def test_outliers_and_body_frame():
    T_bc = np.array([[0, 0, 1, 0.2], [-1, 0, 0, 0.0], [0, -1, 0, 0.5], [0, 0, 0, 1.0]])  # camera looks along body x
    kf_q, kf_m, matches, T_gt = _rgbd_pair(seed=1, T_body_camera=T_bc)
    rng = np.random.default_rng(5)
    bad = rng.choice(len(matches), len(matches) // 4, replace=False)
    matches = matches.copy()
    matches[bad, 1] = rng.permutation(matches[bad, 1])  # 25% wrong correspondences
    v = estimate_loop_pose(kf_q, kf_m, matches, LcdConfig())
    assert v.ok, v.reason
    t_err, r_err = _pose_error(v.T_match_query, T_gt)
    assert t_err < 0.01 and r_err < 0.1
    assert v.inliers < 0.8 * len(matches)


def test_no_depth_means_no_pose():
    kf_q, kf_m, matches, _ = _rgbd_pair()
    kf_m.depth = None
    v = estimate_loop_pose(kf_q, kf_m, matches, LcdConfig())
    assert not v.ok and v.reason == "no_3d_points"


def test_query_depth_used_when_match_has_none():
    kf_q, kf_m, matches, T_gt = _rgbd_pair(seed=2)
    # swap roles: the keyframe with depth becomes the query
    v = estimate_loop_pose(kf_m, kf_q, matches[:, ::-1], LcdConfig())
    assert v.ok, v.reason
    t_err, r_err = _pose_error(v.T_match_query, inv(T_gt))
    assert t_err < 0.01 and r_err < 0.1
    assert np.all(np.linalg.eigvalsh(v.information) > 0)


def test_refinement_jacobian_matches_finite_differences():
    rng = np.random.default_rng(0)
    T = se3_exp(rng.normal(size=6) * 0.2)
    X = rng.normal(size=(12, 3)) + [0, 0, 5]
    xn = rng.normal(size=(12, 2)) * 0.1
    _, J, r = _residuals_and_jacobian(T, X, xn, 500.0)
    Jn = np.zeros_like(J)
    for k in range(6):
        d = np.zeros(6)
        d[k] = 1e-6
        Jn[:, k] = (_residuals_and_jacobian(T @ se3_exp(d), X, xn, 500.0)[2] - r) / 1e-6
    assert np.abs(J - Jn).max() < 1e-3 * np.abs(J).max()


def test_adjoint_identity():
    T = se3_exp(np.array([0.3, -0.2, 0.1, 1.0, 2.0, -0.5]))
    xi = np.array([0.01, 0.02, -0.03, 0.1, -0.05, 0.02])
    assert np.allclose(T @ se3_exp(xi) @ inv(T), se3_exp(adjoint(T) @ xi), atol=1e-9)


def test_epipolar_accepts_rigid_motion_and_rejects_random():
    kf_q, kf_m, matches, _ = _rgbd_pair(seed=3)
    kq, km = kf_q.features.keypoints, kf_m.features.keypoints
    v = verify_epipolar(kq, km, matches, CAM, CAM, LcdConfig())
    assert v.accepted and v.inliers > 0.9 * len(matches)
    rng = np.random.default_rng(0)
    shuffled = matches.copy()
    shuffled[:, 1] = rng.permutation(shuffled[:, 1])
    v2 = verify_epipolar(kq, km, shuffled, CAM, CAM, LcdConfig())
    assert not v2.accepted and v2.reason in ("too_few_inliers", "low_inlier_ratio")


def test_few_inliers_accepted_only_when_the_pose_is_tight():
    """lcd.pnp_min_inliers_tight: 20 good points give a tight pose (accepted, where 40 are required
    otherwise); the same pose against a bound below its sigma, or 20 inliers among 40 matched points
    (half of them wrong), are rejected."""
    from slam_lcd.lcd.geometry import pose_sigmas

    kf_q, kf_m, matches, T_gt = _rgbd_pair(seed=3)
    few = matches[:20]
    # on by default, with the odometry check (test_lcd_odometry_check.py)
    assert LcdConfig().pnp_min_inliers_tight == 15
    conf = LcdConfig(pnp_min_inliers_tight=15)
    assert conf.pnp_min_inliers == 40
    v = estimate_loop_pose(kf_q, kf_m, few, conf)
    assert v.ok and v.tight, v.reason
    sigma_t, sigma_r = pose_sigmas(v.information)
    assert sigma_t <= conf.pnp_tight_max_sigma_m and sigma_r <= conf.pnp_tight_max_sigma_deg
    assert _pose_error(v.T_match_query, T_gt)[0] < 0.02
    # the plain rule alone rejects the same points
    off = estimate_loop_pose(kf_q, kf_m, few, LcdConfig(pnp_min_inliers_tight=0))
    assert not off.ok and off.reason == "too_few_3d_points"
    # a pose that the same points determine less well than the bound: rejected as loose
    strict = estimate_loop_pose(kf_q, kf_m, few,
                                LcdConfig(pnp_min_inliers_tight=15, pnp_tight_max_sigma_m=0.1 * sigma_t))
    assert not strict.ok and strict.reason == "few_inliers_loose_pose"
    # 20 inliers among 40 points with depth (the other 20 matched wrongly): share 0.5 < 0.8
    rng = np.random.default_rng(0)
    half = matches[:40].copy()
    half[20:, 1] = rng.permutation(matches[100:, 1])[:20]
    mixed = estimate_loop_pose(kf_q, kf_m, half, conf)
    assert not mixed.ok and mixed.reason in ("few_inliers_low_share", "too_few_pnp_inliers")


def test_pose_sigmas_of_a_singular_information_are_infinite():
    from slam_lcd.lcd.geometry import pose_sigmas, tight_pose_reason

    assert pose_sigmas(np.zeros((6, 6))) == (float("inf"), float("inf"))
    info = np.diag([1e4] * 3 + [1e6] * 3)  # 0.0173 rad, 1.7 mm
    st, sr = pose_sigmas(info)
    assert np.isclose(st, np.sqrt(3e-6)) and np.isclose(sr, np.degrees(np.sqrt(3e-4)))
    conf = LcdConfig(pnp_min_inliers_tight=15)
    assert tight_pose_reason(info, 20, 22, conf) == "few_inliers_loose_pose"  # 0.99 deg > 0.6 deg
    assert tight_pose_reason(np.diag([1e5] * 3 + [1e6] * 3), 20, 22, conf) == ""
    assert tight_pose_reason(np.diag([1e5] * 3 + [1e6] * 3), 14, 15, conf) == "too_few_pnp_inliers"
    assert tight_pose_reason(np.diag([1e5] * 3 + [1e6] * 3), 20, 30, conf) == "few_inliers_low_share"
