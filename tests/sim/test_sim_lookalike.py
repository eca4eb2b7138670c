"""The look-alike world (world seeds from 2000): the east corridor repeats the west one, and the
sessions recorded in it (6-8) pass one, the other, and places they truly share."""
from __future__ import annotations

import numpy as np
import pytest
from test_sim_render import _body, _orb_inliers

from slam_lcd.sim import SESSIONS, T_body_camera, build_world, demo_camera, gt_cross_pairs, keyframe_indices, render
from slam_lcd.sim.building import LOOKALIKE_P1, LOOKALIKE_SHIFT, building
from slam_lcd.sim.demo_log import session_scenario
from slam_lcd.sim.lookalike import to_p1
from slam_lcd.sim.world_seeds import LOOKALIKE_SEED
from slam_lcd.types import Trajectory

TBC = T_body_camera()
DX = LOOKALIKE_SHIFT[0]


@pytest.fixture(scope="module")
def world():
    return build_world(LOOKALIKE_SEED)


def _views(world, cam, x, y, yaw_deg):
    """The view from (x, y) in the west corridor and from the same spot in the east one."""
    return [render(world, cam, _body(x + dx, y, np.radians(yaw_deg)) @ TBC, with_depth=False)[0] for dx in (0.0, DX)]


def test_the_look_alike_building_is_the_demo_building_but_for_one_pillar():
    demo, alike = building(0), building(LOOKALIKE_SEED)
    assert alike.lookalike and not demo.lookalike and not building(1000).lookalike
    assert np.array_equal(alike.lamps, demo.lamps) and (alike.materials, alike.slots, alike.panels) == (
        demo.materials, demo.slots, demo.panels)
    moved = set(alike.pillars) ^ set(demo.pillars)
    assert sorted(p[1:3] for p in moved) == [(22.0, 7.0), (25.0, 7.0)]  # off the outer east wall, onto B's east face


def test_the_east_corridor_looks_like_the_west_one(world):
    small = demo_camera(160, 120)
    for x, y, yaw in ((1.5, 7.0, 0.0), (1.5, 7.0, 180.0), (1.0, 9.0, -135.0)):  # the walls beside
        a, b = _views(world, small, x, y, yaw)
        assert np.abs(a.astype(float) - b).mean() < 1.0, (x, y, yaw)
    cam = demo_camera(320, 240)
    for y in (10.5, 8.0):  # down the corridor, heading south (until its end fills the view)
        a, b = _views(world, cam, 1.5, y, -90.0)
        assert _orb_inliers(a, b) > 60, y
    # another place of the same world (the middle corridor) does not
    a, _ = _views(world, cam, 1.5, 8.0, -90.0)
    other = render(world, cam, _body(12.5, 8.0, np.pi / 2) @ TBC, with_depth=False)[0]
    assert _orb_inliers(a, other) < 40


def _in(xy, box) -> np.ndarray:
    x0, y0, x1, y1 = box
    return (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)


def _keyframes(k: int) -> Trajectory:
    gt = session_scenario(k).gt_cam
    kf = keyframe_indices(gt)
    return Trajectory(gt.stamps[kf], gt.poses[kf], frame_id=gt.frame_id)


def test_sessions_pass_one_corridor_or_the_other_and_share_the_middle_one():
    p1 = LOOKALIKE_P1
    p2 = (p1[0] + DX, p1[1], p1[2] + DX, p1[3])
    kf = {k: _keyframes(k) for k in (6, 7, 8)}
    assert all(SESSIONS[k].world_seed == LOOKALIKE_SEED and kf[k].frame_id == "world_2000" for k in kf)
    xy = {k: t.poses[:, :2, 3] for k, t in kf.items()}
    assert _in(xy[6], p1).sum() >= 10 and not _in(xy[6], p2).any()
    assert _in(xy[7], p2).sum() >= 10 and not _in(xy[7], p1).any()
    assert _in(xy[8], p2).sum() >= 10
    # session 7 truly shares the middle corridor with session 6 ...
    true = {int(b) for _, b in gt_cross_pairs(kf[6], kf[7], T_body_camera=TBC)}
    # ... and its keyframes in P2 stand where session 6's in P1 do, once moved by the shift: what they see alike
    moved = kf[7].poses.copy()
    moved[:, :2, 3] = to_p1(xy[7])
    alike = {int(b) for _, b in gt_cross_pairs(kf[6], Trajectory(kf[7].stamps, moved, frame_id=kf[6].frame_id),
                                                 T_body_camera=TBC)} - true
    assert all(_in(xy[7][sorted(alike)], p2))
    print(f"session 7: {len(kf[7])} keyframes, {len(true)} share a place with session 6, {len(alike)} look like one")
    assert len(alike) >= 10 and len(true) >= 2 * len(alike)
