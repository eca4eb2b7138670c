"""Wide-baseline revisits with exact ground truth: the demo world's 'laps-wide' trajectory.

Every second lap is driven 0.45 m to the side with the camera turned 30 deg off the direction of
travel, so its keyframes revisit the other laps' places with a lateral offset and a heading
difference of up to ~45 deg (GT pairs: cameras within 1 m and 45 deg, 20 s apart).
"""
from __future__ import annotations

import numpy as np
import pytest

from support.demo_world_loops import detect_on_rendered_keyframes, relative_error

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def wide_run(superpoint_weights):
    pytest.importorskip("slam_lcd.sim")
    return detect_on_rendered_keyframes(superpoint_weights, "laps-wide", 2.3, max_dist=1.0, max_angle_deg=45.0)


def test_trajectory_revisits_with_offset_and_heading_difference(wide_run):
    _, traj, pairs, T_bc = wide_run
    cams = traj.poses @ T_bc
    angles = np.array([relative_error(cams[i], cams[j])[1] for i, j in pairs])
    assert len(pairs) > 50 and np.sum(angles >= 20.0) > 20 and angles.max() <= 45.0


def test_wide_baseline_loops(wide_run, capsys):
    det, traj, pairs, T_bc = wide_run
    cams = traj.poses @ T_bc
    queries = set(np.unique(pairs[:, 0]).tolist())
    wide = {int(i) for i, j in pairs if relative_error(cams[i], cams[j])[1] >= 20.0}
    found, errs = set(), []
    for c in det.closures:
        t_cam, a_cam = relative_error(cams[c.match_id], cams[c.query_id])
        assert t_cam < 2.0 and a_cam < 60.0, (c.query_id, c.match_id, t_cam, a_cam)  # no false loop
        errs.append(relative_error(c.T_match_query, np.linalg.inv(traj.poses[c.match_id]) @ traj.poses[c.query_id]))
        if c.query_id in queries:
            found.add(c.query_id)
    errs = np.array(errs)
    recall = len(found) / len(queries)
    with capsys.disabled():
        print(f"\n[lcd demo wide] keyframes {len(traj)}, GT revisit keyframes {len(queries)} ({len(wide)} with a "
              f">= 20 deg heading difference), accepted loops {len(det.closures)}, revisit keyframes with a loop "
              f"{len(found)} ({recall:.0%}; wide: {len(found & wide)}), "
              f"pose error max {errs[:, 0].max() * 100:.2f} cm / {errs[:, 1].max():.3f} deg")
    # measured 80% (40 / 50): 30 at the full 40 PnP inliers, 10 more on the tight-pose rule, each within
    # the odometry's drift budget (1-2.3 m, 9-19 deg off after ~40 m; docs/lcd_pose.md); the bar: 80 %
    tight = sum(1 for c in det.closures if c.evidence.get("pose_tight"))
    with capsys.disabled():
        print(f"[lcd demo wide] tight-rule loops {tight}")
    assert recall >= 0.8
    assert errs[:, 0].max() < 0.05 and errs[:, 1].max() < 1.0
