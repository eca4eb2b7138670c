"""The shared SE(3)/SO(3)/quaternion helpers of slam_lcd.geometry against scipy and GTSAM."""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from slam_lcd import geometry as g


def _poses(n, seed=0):
    rng = np.random.default_rng(seed)
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    T[:, :3, 3] = rng.normal(size=(n, 3))
    return T


def test_inv_single_and_stacked():
    T = _poses(50)
    Ti = g.inv(T)
    assert np.allclose(Ti @ T, np.eye(4), atol=1e-12)
    assert np.allclose(g.inv(T[3]), np.linalg.inv(T[3]), atol=1e-12)


def test_quaternions_match_scipy_and_round_trip():
    R = Rotation.random(200, random_state=1)
    q = R.as_quat()  # (x, y, z, w)
    assert np.allclose(g.quat_to_rot(q), R.as_matrix(), atol=1e-12)
    assert np.allclose(g.quat_to_rot(3.0 * q[0]), R.as_matrix()[0], atol=1e-12)  # normalised first
    back = g.rot_to_quat(R.as_matrix())
    assert np.allclose(np.abs(np.sum(back * q, axis=1)), 1.0, atol=1e-12)
    pos = g.rot_to_quat(R.as_matrix(), w_nonnegative=True)
    assert np.all(pos[:, 3] >= 0) and np.allclose(np.abs(pos), np.abs(back))
    R180 = Rotation.from_rotvec([np.pi, 0, 0]).as_matrix()  # exact at 180 degrees
    assert np.allclose(np.abs(g.rot_to_quat(R180)), [1, 0, 0, 0], atol=1e-15)


def test_rotation_angle_accurate_for_tiny_and_stacked():
    rv = np.array([3e-9, -1e-9, 2e-9])
    assert abs(g.rotation_angle(Rotation.from_rotvec(rv).as_matrix()) - np.linalg.norm(rv)) < 1e-15
    R = Rotation.random(20, random_state=2)
    assert np.allclose(g.rotation_angle_deg(R.as_matrix()), np.degrees(R.magnitude()), atol=1e-9)
    assert isinstance(g.rotation_angle_deg(np.eye(4)), float)


def test_exp_log_adjoint_gtsam_conventions():
    gtsam = __import__("pytest").importorskip("gtsam")
    rng = np.random.default_rng(3)
    for _ in range(20):
        xi = rng.normal(size=6)
        T = g.se3_exp(xi)
        assert np.allclose(T, gtsam.Pose3.Expmap(xi).matrix(), atol=1e-12)
        assert np.allclose(g.se3_log(T), gtsam.Pose3.Logmap(gtsam.Pose3(T)), atol=1e-9)
        assert np.allclose(g.adjoint(T), gtsam.Pose3(T).AdjointMap(), atol=1e-12)
    Ts = _poses(5)
    assert np.allclose(g.adjoint(Ts)[2], g.adjoint(Ts[2]))


def test_nearest_rotation_and_project():
    T = _poses(1)[0]
    noisy = T.copy()
    noisy[:3, :3] += 1e-4 * np.random.default_rng(4).normal(size=(3, 3))
    P = g.project_to_se3(noisy)
    assert np.allclose(P[:3, :3] @ P[:3, :3].T, np.eye(3), atol=1e-12) and np.linalg.det(P[:3, :3]) > 0
    assert np.allclose(P[:3, 3], T[:3, 3]) and np.allclose(P[:3, :3], T[:3, :3], atol=1e-3)


def test_log_matches_gtsam_near_zero_and_pi():
    gtsam = __import__("pytest").importorskip("gtsam")
    rng = np.random.default_rng(5)
    for k in range(300):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = 10 ** rng.uniform(-12, -2) if k % 2 else np.pi - 10 ** rng.uniform(-9, -2)
        T = np.eye(4)
        T[:3, :3] = Rotation.from_rotvec(angle * axis).as_matrix()
        T[:3, 3] = rng.normal(size=3)
        xi = g.se3_log(T)
        assert np.all(np.isfinite(xi))
        assert np.allclose(xi, gtsam.Pose3.Logmap(gtsam.Pose3(T)), atol=1e-6)


def test_ros_covariance_to_gtsam_reorders_and_rotates_into_the_body_frame():
    """A ROS [t, r] covariance about the parent axes becomes GTSAM's [r, t] about the body axes:
    checked against samples drawn in ROS convention and mapped through the pose by hand."""
    from slam_lcd.geometry import ros_covariance_to_gtsam, so3_exp

    rng = np.random.default_rng(3)
    R = so3_exp(np.array([0.3, -0.5, 1.1]))
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, [1.0, 2.0, 3.0]
    A = rng.normal(size=(6, 6))
    ros = A @ A.T * 1e-3  # [x y z rx ry rz] about the parent axes
    samples = rng.multivariate_normal(np.zeros(6), ros, size=200_000)
    # the same perturbations in GTSAM's order about the body axes
    xi = np.hstack([samples[:, 3:] @ R, samples[:, :3] @ R])
    got = ros_covariance_to_gtsam(ros.reshape(-1), T)
    np.testing.assert_allclose(got, np.cov(xi.T), atol=5e-5)
    # the rotation part of the pose is all that matters; 3x3 works too
    np.testing.assert_allclose(ros_covariance_to_gtsam(ros, R), got, atol=1e-15)
    # 'body': only the order changes (translation block moves to the lower right)
    body = ros_covariance_to_gtsam(ros, T, frame="body")
    np.testing.assert_array_equal(body[3:, 3:], ros[:3, :3])
    np.testing.assert_array_equal(body[:3, :3], ros[3:, 3:])
    # ROS's "unknown" conventions
    assert ros_covariance_to_gtsam(np.zeros(36), T) is None
    unknown = np.zeros(36)
    unknown[0] = -1
    assert ros_covariance_to_gtsam(unknown, T) is None


def test_two_pose_interpolation_matches_scipy_slerp():
    """The per-frame fast path (two samples, one query) equals scipy's Slerp + linear translation."""
    from scipy.spatial.transform import Rotation, Slerp

    from slam_lcd.geometry import interpolate_poses, se3_exp

    rng = np.random.default_rng(0)
    for scale in (0.01, 0.5, 2.0):
        for _ in range(200):
            P = np.array([se3_exp(rng.normal(size=6) * scale) for _ in range(2)])
            st = np.array([100, 100 + int(rng.integers(1, 10**9))], np.int64)
            q = np.array([int(rng.integers(50, st[1] + 50))], np.int64)
            got = interpolate_poses(st, P, q)[0]
            x = (st - st[0]).astype(float)
            qq = np.clip(float(q[0] - st[0]), 0, x[1])
            R = Slerp(x, Rotation.from_matrix(P[:, :3, :3]))([qq]).as_matrix()[0]
            t = [np.interp(qq, x, P[:, k, 3]) for k in range(3)]
            assert np.allclose(got[:3, :3], R, atol=1e-8) and np.allclose(got[:3, 3], t, atol=1e-9)
            assert np.array_equal(got[3], [0, 0, 0, 1])


def test_rot_to_quat_of_one_matrix_is_the_batch_answer_bit_for_bit():
    """The single-matrix path (plain floats, what log writers call per message) gives the array
    path's bits, at 180 degrees, near identity and on matrices a little off orthonormal too."""
    from scipy.spatial.transform import Rotation

    rs = Rotation.random(5000, random_state=3).as_matrix()
    edge = [np.eye(3), np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1]),
            *Rotation.from_rotvec(np.random.default_rng(0).normal(size=(50, 3)) * 1e-9).as_matrix(),
            *np.round(rs[:200], 3)]
    rs = np.concatenate([rs, np.array(edge)])
    for w_nonnegative in (False, True):
        batch = g.rot_to_quat(rs, w_nonnegative=w_nonnegative)
        one = np.array([g.rot_to_quat(r, w_nonnegative=w_nonnegative) for r in rs])
        assert np.array_equal(batch, one)
