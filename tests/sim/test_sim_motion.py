"""Demo trajectories, drifting odometry and ground-truth loop pairs."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.sim import (
    T_body_camera,
    build_world,
    end_drift,
    gt_loop_pairs,
    make_path,
    make_trajectory,
    read_loop_pairs,
    simulate_odometry,
    write_loop_pairs,
)


@pytest.mark.parametrize("kind", ["laps", "figure8"])
def test_trajectory_is_smooth_collision_free_and_loops(kind):
    gt = make_trajectory(kind, rate_hz=50.0, laps=2.0 if kind == "laps" else 1.0)
    world = build_world(0)
    xy = gt.positions[:, :2]
    assert world.is_free(xy, margin=0.6).all()  # stays in the corridors, 0.6 m from any wall
    assert np.allclose(gt.positions[:, 2], 0.0)
    dt = np.diff(gt.times_s)
    speed = np.linalg.norm(np.diff(xy, axis=0), axis=1) / dt
    assert 0.8 < np.median(speed) < 1.3 and speed.max() < 1.5
    yaw = np.unwrap(np.arctan2(gt.poses[:, 1, 0], gt.poses[:, 0, 0]))
    rate = np.abs(np.diff(yaw)) / dt
    assert np.degrees(rate.max()) < 90.0  # turning, but no jumps
    total_turn = np.degrees(yaw[-1] - yaw[0])
    if kind == "laps":
        assert abs(total_turn - 720.0) < 30.0  # two full counter-clockwise laps
        assert 80.0 < gt.path_length() < 90.0
    else:
        assert abs(total_turn) < 30.0  # a figure eight turns left and right equally
    # the path comes back: the end is near the start
    assert np.linalg.norm(xy[-1] - xy[0]) < 1.5


def test_frames_argument_gives_exact_count_and_rate():
    tr = make_trajectory("laps", frames=1200, rate_hz=10.0)
    assert len(tr) == 1200
    assert np.all(np.diff(tr.stamps) == 100_000_000)
    with pytest.raises(ValueError):
        make_path("spiral")


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_odometry_drift_is_visible_but_bounded(seed):
    gt = make_trajectory("laps", rate_hz=50.0, seed=seed)
    odom = simulate_odometry(gt, seed=seed)
    d = end_drift(gt, odom)
    print(f"seed {seed}: drift {d['drift_percent']:.2f} % ({d['end_error_m']:.2f} m of {d['path_length_m']:.1f} m), "
          f"yaw {d['end_yaw_error_deg']:+.1f} deg, error/sigma {d['error_over_sigma']:.2f}")
    assert 1.0 < d["drift_percent"] < 10.0
    # covariance is honest: the actual end error is within 3 sigma and not absurdly below it
    assert 0.05 < d["error_over_sigma"] < 3.0
    # the first pose is exact, errors grow with distance
    assert np.allclose(odom.poses[0], gt.poses[0])
    err = np.linalg.norm(odom.positions - gt.positions, axis=1)
    n = len(err)
    assert err[: n // 10].max() < err[n // 2:].max()


def test_odometry_covariance_is_valid_and_growing():
    gt = make_trajectory("laps", rate_hz=50.0, laps=1.0)
    odom = simulate_odometry(gt, seed=0)
    C = odom.covariances
    assert C.shape == (len(gt), 6, 6)
    assert np.allclose(C, np.transpose(C, (0, 2, 1)))
    assert (np.linalg.eigvalsh(C) > 0).all()
    pos_var = C[:, 3, 3] + C[:, 4, 4]
    # (position variance may shrink a little when the robot comes back towards the start: heading
    # error rotates the path about its start point)
    assert pos_var[len(C) // 2] > 10 * pos_var[len(C) // 20]
    assert np.all(np.diff(C[:, 2, 2]) >= 0)  # yaw variance never shrinks
    # rates: increments are noisy, but per step small
    steps = np.linalg.norm(np.diff(odom.positions, axis=0), axis=1)
    gsteps = np.linalg.norm(np.diff(gt.positions, axis=0), axis=1)
    assert np.abs(steps - gsteps).max() < 0.02


def test_odometry_is_deterministic_per_seed():
    gt = make_trajectory("laps", rate_hz=50.0, laps=0.5)
    a, b, c = simulate_odometry(gt, seed=5), simulate_odometry(gt, seed=5), simulate_odometry(gt, seed=6)
    assert np.array_equal(a.poses, b.poses) and np.array_equal(a.covariances, b.covariances)
    assert not np.allclose(a.poses, c.poses)


def test_gt_loop_pairs_follow_thresholds(tmp_path):
    Tbc = T_body_camera()
    gt = make_trajectory("laps")
    pairs = gt_loop_pairs(gt, max_dist=1.0, max_angle_deg=20.0, min_gap_s=20.0, T_body_camera=Tbc)
    assert len(pairs) > 100
    Tc = gt.poses @ Tbc
    i, j = pairs[:, 0], pairs[:, 1]
    assert (i > j).all()
    assert (np.linalg.norm(Tc[i, :3, 3] - Tc[j, :3, 3], axis=1) <= 1.0).all()
    assert ((gt.stamps[i] - gt.stamps[j]) >= 20e9).all()
    cosang = (np.einsum("nij,nij->n", Tc[i, :3, :3], Tc[j, :3, :3]) - 1) / 2
    assert (np.degrees(np.arccos(np.clip(cosang, -1, 1))) <= 20.0 + 1e-9).all()
    # the second lap revisits the first: almost every second-lap frame has a partner
    lap_frames = len(gt) // 2
    second = np.arange(lap_frames + 20, len(gt))
    has = np.isin(second, i)
    assert has.mean() > 0.85, has.mean()
    # nothing in the first lap (no revisits yet)
    assert i.min() > 200
    # tighter thresholds -> subset
    tight = gt_loop_pairs(gt, max_dist=0.5, max_angle_deg=10.0, min_gap_s=20.0, T_body_camera=Tbc)
    assert 0 < len(tight) < len(pairs)
    assert set(map(tuple, tight.tolist())) <= set(map(tuple, pairs.tolist()))
    # CSV round trip
    p = write_loop_pairs(tmp_path / "loops.csv", gt, pairs, T_body_camera=Tbc)
    assert np.array_equal(read_loop_pairs(p), pairs)
    lines = p.read_text().splitlines()
    assert lines[0].startswith("query_index,match_index,query_stamp_ns")
    q, m, qs, ms, d, a = lines[1].split(",")
    assert int(qs) == gt.stamps[int(q)] and float(d) <= 1.0
