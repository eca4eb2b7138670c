"""The map cloud's pieces on small synthetic data: voxel grid, sensor points, bad input, sharpness, truth, files."""
from __future__ import annotations

import logging

import numpy as np
import pytest

from slam_lcd.cloud import (
    Cloud,
    MapCloudBuilder,
    MapCloudConfig,
    VoxelGrid,
    depth_points,
    read_cloud,
    sharpness,
    surface_distances,
    write_cloud,
)
from slam_lcd.errors import InputError, UnsupportedFormatError
from slam_lcd.types import CameraModel, Keyframe, Rectangles

CAM = CameraModel(width=64, height=48, fx=50.0, fy=50.0, cx=31.5, cy=23.5)


def test_voxel_grid_keeps_one_centroid_per_voxel_with_its_mean_colour():
    g = VoxelGrid(1.0)
    g.add(np.array([[0.2, 0.2, 0.2], [0.4, 0.6, 0.8], [1.5, 0.5, 0.5]]),
          np.array([[0, 0, 0], [100, 200, 50], [9, 9, 9]], np.uint8))
    c = g.cloud()
    order = np.argsort(c.points[:, 0])
    np.testing.assert_allclose(c.points[order], [[0.3, 0.4, 0.5], [1.5, 0.5, 0.5]], atol=1e-6)
    np.testing.assert_array_equal(c.colours[order], [[50, 100, 25], [9, 9, 9]])


def test_voxel_grid_batches_equal_one_batch_and_memory_follows_extent_not_input():
    rng = np.random.default_rng(1)
    pts = rng.uniform(-5, 5, (30000, 3))
    one = VoxelGrid(0.5)
    one.add(pts)
    many = VoxelGrid(0.5)
    for chunk in np.array_split(pts, 37):
        many.add(chunk)
    a, b = one.cloud(), many.cloud()
    ia, ib = np.lexsort(a.points.T), np.lexsort(b.points.T)
    np.testing.assert_allclose(a.points[ia], b.points[ib], atol=1e-5)
    size = many.nbytes
    for _ in range(20):  # the same space seen again and again: the grid does not grow
        many.add(rng.uniform(-5, 5, (30000, 3)))
    assert len(many) == 20 ** 3 and many.nbytes < 2.1 * size  # every voxel of the 10 m cube, no more


def test_points_beyond_the_key_range_are_dropped_not_wrapped():
    g = VoxelGrid(0.05)
    g.add(np.array([[1e6, 0, 0], [0.01, 0.01, 0.01]]))
    assert len(g) == 1


def _wall_depth(z=2.0):
    return np.full((CAM.height, CAM.width), z, np.float32)


def test_depth_points_lie_on_the_plane_they_were_seen_on_and_respect_the_range():
    sp = depth_points(CAM, _wall_depth(2.0), None, step=2, min_depth=0.3, max_depth=5.0)
    assert len(sp) == (CAM.height // 2) * (CAM.width // 2)
    np.testing.assert_allclose(sp.points[:, 2], 2.0, atol=1e-6)
    assert len(depth_points(CAM, _wall_depth(6.0), None, max_depth=5.0)) == 0


def _kf(i, depth, image=None):
    return Keyframe(id=i, stamp=i, T_world_body=np.eye(4), image=image, camera=CAM, depth=depth)


@pytest.mark.parametrize("queue", [0, 2])  # in the caller's thread / in the builder's own
def test_bad_depth_is_a_warning_per_reason_and_a_count_not_a_crash(caplog, queue):
    b = MapCloudBuilder(MapCloudConfig(queue_keyframes=queue), source="log.mcap: /camera/depth")
    with caplog.at_level(logging.WARNING):
        for i in range(3):
            assert b.add_keyframe(_kf(i, np.zeros((10, 10), np.float32))) == bool(queue)  # wrong size
        for i in range(3, 6):
            assert b.add_keyframe(_kf(i, np.full((CAM.height, CAM.width), np.nan, np.float32))) == bool(queue)
        assert b.add_keyframe(_kf(6, _wall_depth()))
        b.drain()
    lines = [r.getMessage() for r in caplog.records if "map cloud" in r.getMessage()]
    assert len(lines) == 2 and all("/camera/depth" in x for x in lines), lines
    assert sorted(b.skipped.values()) == [3, 3] and b.n_keyframes == 1
    assert "10x10" in next(k for k in b.skipped if "size" in k or "pixels" in k)
    b.close()


def test_builder_merges_with_any_poses_later():
    b = MapCloudBuilder(MapCloudConfig(voxel_m=0.05, min_keyframes_per_voxel=1))
    b.add_keyframe(_kf(0, _wall_depth(2.0)))
    T = np.eye(4)
    T[0, 3] = 10.0
    near, far = b.cloud({0: np.eye(4)}), b.cloud({0: T})
    np.testing.assert_allclose(far.points.mean(axis=0) - near.points.mean(axis=0), [10, 0, 0], atol=0.01)
    assert len(b.cloud({})) == 0  # a keyframe without a pose is left out
    b.close()


def test_the_builders_thread_gives_the_same_map_and_survives_a_failure(caplog):
    """Keyframes taken in the builder's thread: the same store as in the caller's (first in, first out);
    an unexpected error there is said once and stops taking keyframes, it never reaches the caller."""
    rng = np.random.default_rng(3)
    depths = [rng.uniform(1.0, 4.0, (CAM.height, CAM.width)).astype(np.float32) for _ in range(12)]
    poses = {i: np.eye(4) for i in range(12)}
    for i in range(12):
        poses[i][:3, 3] = rng.normal(size=3)
    maps = []
    for queue in (0, 3):
        b = MapCloudBuilder(MapCloudConfig(queue_keyframes=queue))
        for i, d in enumerate(depths):
            b.add_keyframe(_kf(i, d))
        maps.append(b.cloud(poses))
        assert b.n_keyframes == 12
        b.close()
    np.testing.assert_array_equal(maps[0].points, maps[1].points)
    np.testing.assert_array_equal(maps[0].colours, maps[1].colours)
    b = MapCloudBuilder(MapCloudConfig(queue_keyframes=2))
    bad = _kf(1, depths[1])
    bad.camera = "not a camera"
    with caplog.at_level(logging.WARNING):
        for kf in (_kf(0, depths[0]), bad, _kf(2, depths[2])):
            b.add_keyframe(kf)
        b.drain()
    assert b.failed and b.n_keyframes == 1 and not b.add_keyframe(_kf(3, depths[3]))
    assert b.skipped == {b.failed: 3} and "keyframe 1" in b.failed  # the failing one and the two after it
    # said once, when the map is built (a run that fails first, on a full disk say, says only its own line)
    assert not any("failed from keyframe 1" in r.getMessage() for r in caplog.records)
    with caplog.at_level(logging.WARNING):
        b.cloud(poses)
        b.cloud(poses)
    assert sum("failed from keyframe 1" in r.getMessage() for r in caplog.records) == 1
    b.close()


def _plane(rng, n, offset=0.0, noise=0.002):
    p = np.column_stack([rng.uniform(0, 4, n), rng.uniform(0, 3, n), offset + rng.normal(0, noise, n)])
    return p


def test_sharpness_sees_a_doubled_wall_and_is_lower_for_one_wall():
    rng = np.random.default_rng(0)
    one = _plane(rng, 20000)
    two = np.vstack([_plane(rng, 10000), _plane(rng, 10000, offset=0.06)])
    a = sharpness(one, 0.3, 3000, min_std=0.01)
    b = sharpness(two, 0.3, 3000, min_std=0.01)
    assert a["mme"] < b["mme"] - 0.5 and a["plane_variance_m2"] < 0.1 * b["plane_variance_m2"]
    assert b["plane_std_mm"] == pytest.approx(30, rel=0.15)  # two sheets 6 cm apart: +-3 cm about the mid-plane
    assert sharpness(one[:3], 0.3)["mme"] is None


def test_surface_distances_to_rectangles():
    r = Rectangles(origins=np.zeros((1, 3)), u=np.array([[1.0, 0, 0]]), v=np.array([[0, 1.0, 0]]),
                   widths=np.array([2.0]), heights=np.array([1.0]))
    d = surface_distances(np.array([[1, 0.5, 0.3], [3, 0.5, 0], [-1, -1, 0], [0.5, 0.5, 0]]), r)
    np.testing.assert_allclose(d, [0.3, 1.0, np.sqrt(2), 0.0])


@pytest.mark.parametrize("suffix", [".ply", ".pcd"])
def test_cloud_files_round_trip(tmp_path, suffix):
    rng = np.random.default_rng(2)
    c = Cloud(rng.normal(size=(500, 3)).astype(np.float32), rng.integers(0, 256, (500, 3)).astype(np.uint8))
    path = write_cloud(tmp_path / f"m{suffix}", c)
    back = read_cloud(path)
    np.testing.assert_array_equal(back.points, c.points)
    np.testing.assert_array_equal(back.colours, c.colours)
    assert [p.name for p in tmp_path.iterdir()] == [f"m{suffix}"]  # no temporary left beside it


def test_cloud_file_errors_name_the_file(tmp_path):
    with pytest.raises(UnsupportedFormatError, match="m.xyz"):
        write_cloud(tmp_path / "m.xyz", Cloud.empty())
    bad = tmp_path / "bad.pcd"
    bad.write_bytes(b"hello")
    with pytest.raises(InputError, match="bad.pcd"):
        read_cloud(bad)


def test_voxels_seen_by_fewer_batches_than_asked_are_left_out():
    g = VoxelGrid(1.0)
    g.add(np.array([[0.2, 0.2, 0.2], [0.3, 0.3, 0.3], [5.5, 0.5, 0.5]]))  # one batch: two points in one voxel
    g.add(np.array([[0.4, 0.4, 0.4]]))
    assert len(g.cloud()) == 2
    np.testing.assert_allclose(g.cloud(min_views=2).points, [[0.3, 0.3, 0.3]], atol=1e-6)
    assert len(g.cloud(min_views=3)) == 0


def _stereo_square_before_a_wall():
    """A rectified pair (blurred, as a lens blurs): a textured square 0.5 m away before a wall 2.5 m away."""
    import cv2

    rng = np.random.default_rng(0)
    far, near = (cv2.GaussianBlur((rng.random((240, 400)) * 255).astype(np.uint8), (3, 3), 0)[:, 40:360]
                 for _ in range(2))
    d_far, d_near = 8, 40  # disparities (px) at fx 200, baseline 0.1 m: 2.5 m and 0.5 m
    left = far.copy()
    right = np.roll(far, -d_far, axis=1)
    sq = np.zeros(left.shape, bool)
    sq[80:160, 120:200] = True
    left[sq] = near[sq]
    ys, xs = np.nonzero(sq)
    right[ys, xs - d_near] = near[ys, xs]
    return cv2.GaussianBlur(left, (7, 7), 2), cv2.GaussianBlur(right, (7, 7), 2)


def test_stereo_points_at_an_edge_floating_between_the_surfaces_are_dropped():
    from slam_lcd.cloud import stereo_points

    cam = CameraModel(width=320, height=240, fx=200.0, fy=200.0, cx=159.5, cy=119.5, baseline=0.1)
    left, right = _stereo_square_before_a_wall()
    kept, all_ = (stereo_points(cam, left, right, step=1, max_jump=j).points[:, 2] for j in (1.0, 0.0))
    between = [int(((z > 0.6) & (z < 2.2)).sum()) for z in (kept, all_)]
    assert between[0] == 0 < between[1], between  # the matching window's blend of square and wall
    for z in (kept, all_):  # both surfaces are still there
        assert (np.abs(z - 0.5) < 0.05).sum() > 4000 and (np.abs(z - 2.5) < 0.2).sum() > 30000
