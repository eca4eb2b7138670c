"""loops.csv against position-only ground truth (EuRoC's Leica PointStamped): distances exact, the loop's
translation error through the corrected rotations (aligned to the ground truth's frame), no rotation error."""
from __future__ import annotations

from types import SimpleNamespace

import cv2
import numpy as np

from slam_lcd.geometry import inv, make_T
from slam_lcd.outputs.loops import loop_rows
from slam_lcd.types import Trajectory


def _pose(yaw_deg, x, y):
    return make_T(cv2.Rodrigues(np.radians([0.0, 0.0, yaw_deg]))[0], np.array([x, y, 0.2]))


def _record(q, m, T_match_query):
    return SimpleNamespace(query_id=q, match_id=m, accepted=True, row=lambda: {},
                           pose=SimpleNamespace(ok=True, T_match_query=T_match_query))


def test_position_only_ground_truth_gives_exact_distance_and_translation_error():
    stamps = np.arange(6, dtype=np.int64) * 1_000_000_000
    est = [_pose(0, 0, 0), _pose(40, 3, 0.5), _pose(95, 4, 3), _pose(180, 1, 4), _pose(260, -0.5, 1.5),
           _pose(10, 0.3, 0.2)]
    T_station = _pose(30, 4.0, -2.5)  # the Leica frame: the estimate's world turned and shifted
    gt_positions = [T_station @ T for T in est]
    gt = Trajectory(stamps, np.array([make_T(np.eye(3), T[:3, 3]) for T in gt_positions]))  # rotations unknown
    keyframes = [SimpleNamespace(id=i, stamp=int(s)) for i, s in enumerate(stamps)]
    kf_poses = Trajectory(stamps, np.array(est))
    true = inv(est[0]) @ est[5]  # the loop 5 -> 0, in the match body's frame
    off = make_T(np.eye(3), [0.1, 0.0, 0.0]) @ true  # 10 cm off
    recs = [_record(5, 0, true), _record(5, 0, off)]
    rows = loop_rows(recs, [], keyframes, gt, position_only=True, keyframe_poses=kf_poses)
    d = np.linalg.norm(est[5][:3, 3] - est[0][:3, 3])
    for r in rows:
        assert abs(float(r["gt_distance_m"]) - d) < 1e-5 and r["err_rot_deg"] == ""
    assert float(rows[0]["err_trans_m"]) < 1e-5
    assert abs(float(rows[1]["err_trans_m"]) - 0.1) < 1e-5
    # the gap this closes: the identity rotations taken as poses give a wrong error for the exact loop
    naive = loop_rows(recs[:1], [], keyframes, gt)
    assert float(naive[0]["err_trans_m"]) > 0.05
