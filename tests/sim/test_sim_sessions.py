"""Sessions of the demo world: presets, each session's own odometry frame, shared places
between sessions (from the trajectories, no rendering), cross-session pairs, small logs."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from slam_lcd.cli.main import main
from slam_lcd.io import open_log
from slam_lcd.io.decode import decode_pose
from slam_lcd.sim import (
    SESSIONS,
    T_body_camera,
    build_world,
    gt_cross_pairs,
    gt_loop_pairs,
    keyframe_indices,
    make_demo_log,
    make_path,
    render,
    session_start_ns,
    shared_place_fraction,
)
from slam_lcd.sim.demo_log import session_scenario
from slam_lcd.sim.trajectory import START_NS
from slam_lcd.types import Trajectory

TBC = T_body_camera()


@pytest.fixture(scope="module")
def scenarios():
    return {k: session_scenario(k) for k in SESSIONS}


def _pose(x, y, yaw_deg):
    T = np.eye(4)
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = x, y
    return T


def test_presets_set_routes_worlds_lighting_and_days(scenarios):
    world = build_world(0)
    for k, sc in scenarios.items():
        pre = SESSIONS[k]
        assert sc.world_seed == pre.world_seed and sc.exposure == pre.exposure
        assert sc.world_frame == ("world" if pre.world_seed == 0 else f"world_{pre.world_seed}")
        assert sc.gt_cam.frame_id == sc.gt_odo.frame_id == sc.world_frame
        assert sc.cam_stamps[0] == sc.odo_stamps[0] == START_NS + k * 86_400 * 10**9 == session_start_ns(k)
        # the route starts where the preset says, and the lighting epochs are offset by the preset's
        start = make_path(pre.kind, laps=0.1, seed=pre.seed, start_at=pre.start_at).pose_at(0.0)[0]
        assert np.allclose(sc.gt_cam.poses[0], start)
        assert sc.laps[0] == pytest.approx(pre.lighting)
        assert sc.laps[-1] == pytest.approx(pre.lighting + pre.laps, abs=0.02)
        assert world.is_free(sc.gt_odo.positions[:, :2], margin=0.6).all()
    starts = [scenarios[k].gt_cam.positions[0, :2] for k in (1, 2, 3, 5)]
    assert min(np.linalg.norm(a - b) for a, b in itertools.combinations(starts, 2)) > 3.0  # other start points
    assert scenarios[4].world_seed != 0 and scenarios[3].exposure < 1.0 and scenarios[3].laps[0] >= 1.0
    # session 1 closes a loop of its own; sessions differ in their noise
    assert len(gt_loop_pairs(scenarios[1].gt_cam, T_body_camera=TBC)) > 1000
    assert len({SESSIONS[k].seed for k in SESSIONS}) == len(SESSIONS)


def test_session_odometry_starts_at_the_identity(scenarios):
    for sc in scenarios.values():
        odo, gt = sc.odom, sc.gt_odo
        assert np.array_equal(odo.poses[0], np.eye(4)) and not np.allclose(gt.poses[0], np.eye(4))
        rel = np.linalg.inv(gt.poses[0]) @ gt.poses  # ground truth seen from the start
        err = np.linalg.norm(odo.positions - rel[:, :3, 3], axis=1)
        assert err[:50].max() < 0.05 and 0.1 < err[-1] < 0.1 * gt.path_length()  # drifts from the start on
    plain = session_scenario(None, frames=30)
    assert np.allclose(plain.odom.poses[0], plain.gt_odo.poses[0]) and plain.cam_stamps[0] == START_NS


def test_shared_place_fractions_meet_the_targets(scenarios):
    gt = {k: sc.gt_cam for k, sc in scenarios.items()}
    frac = {}
    for a, b in itertools.combinations([1, 2, 3], 2):
        frac[a, b] = min(shared_place_fraction(gt[a], gt[b], T_body_camera=TBC),
                         shared_place_fraction(gt[b], gt[a], T_body_camera=TBC))
    print({f"{a}-{b}": round(v, 3) for (a, b), v in frac.items()})
    assert min(frac.values()) >= 0.3
    assert shared_place_fraction(gt[5], [gt[1], gt[2], gt[3]], T_body_camera=TBC) == 1.0
    assert shared_place_fraction(gt[4], [gt[1], gt[2], gt[3]], T_body_camera=TBC) == 0.0
    for k in (1, 2, 3, 5):
        assert len(gt_cross_pairs(gt[4], gt[k], T_body_camera=TBC)) == 0  # another world: no place shared
    # ... although its route is session 1's: only the world frame keeps them apart
    same_frame = Trajectory(gt[4].stamps, gt[4].poses, frame_id=gt[1].frame_id)
    assert shared_place_fraction(same_frame, gt[1], T_body_camera=TBC) > 0.9


def test_cross_pairs_on_a_synthetic_case():
    a = Trajectory(np.arange(11) * 10**9, np.stack([_pose(x, 0.0, 0.0) for x in range(11)]))
    b = Trajectory(np.arange(5) * 10**9 + 7, np.stack([
        _pose(5.3, 0.5, 10.0),  # near a[5] (0.58 m, 10 deg): pair; a[6] is 0.86 m away: pair too
        _pose(2.0, 0.0, 90.0),  # right place, looking elsewhere: none
        _pose(8.0, 0.3, -19.0),  # a[8] within 20 deg: pair (a[7] and a[9] are 1.04 m away)
        _pose(20.0, 0.0, 0.0),  # nowhere near
        _pose(0.0, 1.2, 0.0),  # 1.2 m to the side of a[0]: none
    ]))
    pairs = gt_cross_pairs(a, b)
    assert pairs.tolist() == [[5, 0], [6, 0], [8, 2]]
    assert gt_cross_pairs(b, a).tolist() == [[0, 5], [0, 6], [2, 8]]
    assert gt_cross_pairs(a, b, max_dist=0.7).tolist() == [[5, 0], [8, 2]]
    assert gt_cross_pairs(a, b, max_angle_deg=15.0).tolist() == [[5, 0], [6, 0]]
    other_world = Trajectory(b.stamps, b.poses, frame_id="world_7")
    assert gt_cross_pairs(a, other_world).shape == (0, 2)
    # camera mounting: the pairs are of camera poses
    assert gt_cross_pairs(a, b, T_body_camera=TBC).tolist() == [[5, 0], [6, 0], [8, 2]]
    # keyframes every 0.5 m or 15 deg; a keeps every pose (1 m apart)
    assert keyframe_indices(a).tolist() == list(range(11))
    assert keyframe_indices(a, min_translation=2.5, min_rotation_deg=0).tolist() == [0, 3, 6, 9]
    assert shared_place_fraction(a, b, min_translation=0, min_rotation_deg=0) == pytest.approx(3 / 11)
    assert shared_place_fraction(b, a, min_translation=0, min_rotation_deg=0) == pytest.approx(2 / 5)


def test_changed_lighting_and_another_world_look_different():
    sc1, sc3 = session_scenario(1, frames=5), session_scenario(3, frames=5)
    cam = sc1.camera.__class__(**{**sc1.camera.__dict__, "width": 160, "height": 120, "fx": 114.25, "fy": 114.25,
                                  "cx": 79.5, "cy": 59.5})
    T_wc = sc1.gt_cam.poses[2] @ TBC
    nominal, _ = render(build_world(0), cam, T_wc, epoch=0.0, with_depth=False)
    dim, _ = render(build_world(0), cam, T_wc, epoch=float(sc3.laps[0]), gain=sc3.exposure, with_depth=False)
    ratio = dim.mean() / nominal.mean()
    assert ratio < 0.8  # session 3's lamps and exposure: clearly darker
    other, _ = render(build_world(1000), cam, T_wc, epoch=0.0, with_depth=False)

    def corr(x, y):
        return np.corrcoef(x.ravel().astype(float), y.ravel().astype(float))[0, 1]

    print(f"brightness ratio {ratio:.2f}, correlation relit {corr(nominal, dim):.2f}, "
          f"other world {corr(nominal, other):.2f}")
    # the same walls relit still correlate; another world's walls (same corridors) much less
    assert corr(nominal, dim) > 0.9 and corr(nominal, other) < corr(nominal, dim) - 0.2


def test_session_log_frames_and_overrides(tmp_path):
    info = make_demo_log(tmp_path / "s2.mcap", session=2, frames=12, width=96, height=72, depth=False)
    assert info.session == 2 and info.kind == "figure8" and info.seed == 2 and info.world_seed == 0
    assert info.start_at == 55.0 and "session 2" in info.summary()
    gt, odo, tf = {}, {}, None
    with open_log(info.path) as r:
        for m in r.messages():
            if m.topic == "/ground_truth/pose":
                gt[m.stamp] = decode_pose(m.msg)[0]
                assert m.msg.header.frame_id == "world"
            elif m.topic == "/odom":
                odo[m.stamp] = decode_pose(m.msg)[0]
            elif m.topic == "/tf_static":
                tf = {t.child_frame_id for t in m.msg.transforms}
    first = min(gt)
    assert first == session_start_ns(2)
    assert np.allclose(odo[first], np.eye(4), atol=1e-9) and not np.allclose(gt[first], np.eye(4))
    assert "odom" not in tf and "camera_optical_frame" in tf  # no world -> odom: the frames are unrelated
    # explicit arguments win over the preset
    o = make_demo_log(tmp_path / "o.mcap", session=4, frames=4, width=64, height=48, depth=False, seed=11,
                      kind="laps", start_at=10.0, lighting=2.0, exposure=0.9, world_seed=0)
    assert (o.seed, o.world_seed, o.world_frame, o.start_at, o.lighting, o.exposure) == (11, 0, "world", 10.0, 2.0, 0.9)


def test_cli_session(tmp_path, capsys):
    out = tmp_path / "s4.mcap"
    assert main(["make-demo-log", str(out), "--session", "4", "--frames", "6", "--size", "64x48", "--no-depth",
                 "--lighting", "1.5"]) == 0
    text = capsys.readouterr().out
    assert "session 4: world 1000 (ground truth in 'world_1000')" in text and "lighting +1.5" in text
    with open_log(out) as r:
        frames = {m.msg.header.frame_id for m in r.messages() if m.topic == "/ground_truth/pose"}
    assert frames == {"world_1000"}
    assert main(["make-demo-log", str(tmp_path / "x.mcap"), "--session", "9"]) == 2
    assert main(["make-demo-log", str(tmp_path / "y.mcap"), "--exposure", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 2


def _grid_corners(tile_m, phase_m, step=None):
    """Floor / ceiling grid crossings over the 25 x 14 m plan (texture row 0 at y = 14, column 0 at x = 0)."""
    xs = np.arange(0.0, 25.0 + tile_m, tile_m) - phase_m[0]
    ys = 14.0 - (np.arange(0.0, 14.0 + tile_m, tile_m) - phase_m[1])
    X, Y = np.meshgrid(xs, ys)
    return np.column_stack([X.ravel(), Y.ravel()])


def _segment_distance(p, a, b):
    """Distance of points p (N, 2) from the segment a-b."""
    d = b - a
    t = np.clip(((p - a) @ d) / (d @ d), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * d), axis=1)


def test_another_world_is_another_place(scenarios):
    from slam_lcd.sim.world import OTHER_PLACE_SEED, building

    demo, other = building(0), building(SESSIONS[4].world_seed)
    assert SESSIONS[4].world_seed >= OTHER_PLACE_SEED and not demo.other_place and other.other_place
    # the demo building is where it always was, for every seed below 1000 (textures change, places do not)
    assert len(demo.lamps) == 25 and np.allclose(demo.lamps[:, 2], 2.95)  # every 3 m on the corridors' centre lines
    assert all(x in (1.5, 12.5, 23.5) or y in (1.5, 12.5) for x, y, _ in demo.lamps)
    assert set(np.round(demo.lamps[:, :2].ravel() % 3.0, 6)) == {0.5, 1.5, 2.5}
    assert (demo.floor_tile_m, demo.floor_phase_m, demo.ceil_tile_m, demo.ceil_phase_m) == (0.5, (0, 0), 0.6, (0, 0))
    assert [p[1:3] for p in demo.pillars] == [(7.0, 0.0), (7.0, 14.0), (18.0, 0.0), (18.0, 14.0), (0.0, 7.0),
                                              (25.0, 7.0)]
    assert demo.panels == tuple((k, 1.3, 1.3, 2.2) for k in range(4)) and demo.materials["A0"] == "bricks"
    for seed in (1, 7, 999):
        b = building(seed)
        assert np.array_equal(b.lamps, demo.lamps) and (b.materials, b.slots, b.pillars, b.panels) == (
            demo.materials, demo.slots, demo.pillars, demo.panels)
    # another world: no lamp, grid crossing, material, decal group, pillar or panel where the demo has one
    assert np.linalg.norm(other.lamps[:, None, :2] - demo.lamps[None, :, :2], axis=2).min() >= 0.5
    assert len(other.lamps) >= 20 and other.lamp_half_px != demo.lamp_half_px
    for tile, phase, d_tile, d_phase in ((other.floor_tile_m, other.floor_phase_m, 0.5, (0, 0)),
                                         (other.ceil_tile_m, other.ceil_phase_m, 0.6, (0, 0))):
        assert tile != d_tile
        a, b = _grid_corners(tile, phase), _grid_corners(d_tile, d_phase)
        near = np.abs(a[:, None, :] - b[None, :, :]).max(2).min(1) < 0.03
        assert near.mean() < 0.05, (tile, phase, near.mean())
    assert all(other.materials[w] != m for w, m in demo.materials.items())
    sites0, sites1 = build_world(0).alias_sites, build_world(SESSIONS[4].world_seed).alias_sites
    assert len(sites1) >= 5 and len({s["group"] for s in sites1}) == 3
    assert min(np.linalg.norm(s["centre"] - t["centre"]) for s in sites1 for t in sites0) > 1.0
    p0 = np.array([p[1:3] for p in demo.pillars])
    assert all(np.linalg.norm(p0 - np.array(p[1:3]), axis=1).min() >= 1.0 for p in other.pillars)
    assert all(max(abs(rx - 1.3), abs(ry - 1.3)) >= 0.25 and abs(h - 2.2) >= 0.2 for _, rx, ry, h in other.panels)
    # session 4 still drives its route: at least 0.6 m from every wall, pillar and panel of its world
    world = build_world(SESSIONS[4].world_seed)
    xy = scenarios[4].gt_odo.positions[:, :2]
    walls = [p for p in world.planes if abs(p.normal[2]) < 0.5]
    dist = min(_segment_distance(xy, p.corners[0, :2], p.corners[1, :2]).min() for p in walls)
    assert dist >= 0.6, dist
