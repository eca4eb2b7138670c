"""A view drops (redundant) or takes a place (richer) only when the view that stays would localise the one that goes.

Synthetic views of one wall of 3-D points (a 320x240 pinhole camera, no logs): the new view shares its
descriptors with the kept one (the share rule alone calls it redundant). When its keypoints are where the
kept view's 3-D points project under their true relative pose, the kept view localises it and it still
drops; when the matched points project nowhere near its keypoints (the same descriptors on other
keypoints: look-alikes no pose explains), it is kept as a variant. A monocular map (no 3-D points) keeps
the share rule.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from test_map_lifelong import _pose  # tests/ is on sys.path (pytest rootdir import)

from slam_lcd.geometry import inv
from slam_lcd.map.config import MapConfig
from slam_lcd.map.contents import MapGraph, SessionKeyframes
from slam_lcd.map.keyframe_arrays import camera_json
from slam_lcd.map.lifelong import reduce_append
from slam_lcd.map.place_geometry import stored_view
from slam_lcd.map.places import REDUNDANT, RICHER, VARIANT, Kept, judge, prune
from slam_lcd.types import CameraModel

CAM = CameraModel(320, 240, 200.0, 200.0, 160.0, 120.0)


def _unit(rows: np.ndarray) -> np.ndarray:
    return (rows / np.linalg.norm(rows, axis=1, keepdims=True)).astype(np.float32)


def _project(P: np.ndarray) -> np.ndarray:
    return np.column_stack([CAM.fx * P[:, 0] / P[:, 2] + CAM.cx, CAM.fy * P[:, 1] / P[:, 2] + CAM.cy])


def _in(T: np.ndarray, X: np.ndarray) -> np.ndarray:
    """World points ``X`` in the camera at ``T`` (camera-to-world)."""
    Ti = inv(T)
    return X @ Ti[:3, :3].T + Ti[:3, 3]


RNG = np.random.default_rng(3)
WALL = np.column_stack([RNG.uniform(-1.5, 1.5, 400), RNG.uniform(-1.0, 1.0, 400), RNG.uniform(4.0, 6.0, 400)])
KEPT_T, NEW_T = _pose(0.0), _pose(0.3, 4.0)  # the new view 0.3 m and 4 deg off the kept one: one place
SEEN = np.flatnonzero(np.all([(lambda u: (u[:, 0] > 0) & (u[:, 0] < 320) & (u[:, 1] > 0) & (u[:, 1] < 240))(
    _project(_in(T, WALL))) for T in (KEPT_T, NEW_T)], axis=0))[:200]
DESC = _unit(RNG.normal(size=(len(SEEN), 64)))


def _view(T: np.ndarray, rows: np.ndarray, shuffle: float = 0.0, monocular: bool = False):
    """(descriptors, view) of the wall points ``SEEN[rows]`` from camera pose ``T``: keypoints where they
    project (a little noise), 3-D points in its camera frame; ``shuffle``: the share of descriptors moved
    onto one another's keypoints; ``monocular``: no 3-D points."""
    P = _in(T, WALL[SEEN[rows]])
    uv = _project(P) + RNG.normal(scale=0.3, size=(len(rows), 2))
    moved = int(round(shuffle * len(rows)))
    uv[:moved] = uv[:moved][np.random.default_rng(5).permutation(moved)]
    desc = _unit(DESC[rows] + 0.01 * RNG.normal(size=(len(rows), 64)))
    pts = np.full_like(P, np.nan) if monocular else P
    return desc, stored_view(uv.astype(np.float32), pts.astype(np.float32), "none" if monocular else "rgbd", CAM)


ALL = np.arange(len(SEEN))


def _kept(rows: np.ndarray = ALL, **kw) -> list[Kept]:
    desc, view = _view(KEPT_T, rows, **kw)
    return [Kept(1, KEPT_T, 0, 0, 1, lambda: desc, 0, view)]


def _judge(kept: list[Kept], rows: np.ndarray = ALL, **kw):
    desc, view = _view(NEW_T, rows, **kw)
    return judge([(10, NEW_T, lambda: desc)], 0, kept, MapConfig(), now=2, next_place=1, views={10: view})


def test_a_view_the_kept_one_localises_is_still_redundant():
    kept = _kept()
    v = _judge(kept)
    assert v.status == {10: REDUNDANT} and v.matched == {10: 1} and not v.reason
    assert [k.kf_id for k in kept] == [1]


@pytest.mark.parametrize("shuffle", [1.0, 0.85])
def test_a_view_whose_matches_no_pose_explains_is_kept_as_a_variant(shuffle):
    """The same descriptors on other keypoints: every share says redundant, but no pose puts the kept view's
    points on its keypoints (all moved), or one pose explains too few of them for the loop chain's pose stage
    (85 % moved: 30 of 200, under lcd.pnp_min_inliers, and its RANSAC finds no pose among so many outliers);
    the kept view would not localise it, so it stays as a variant of the place."""
    kept = _kept()
    v = _judge(kept, shuffle=shuffle)
    assert v.status == {10: VARIANT} and v.place == {10: 0} and not v.matched
    assert "would not localise" in v.reason[10] and "PnP inliers" in v.reason[10]
    assert sorted(k.kf_id for k in kept) == [1, 10]


def test_a_monocular_map_keeps_the_share_rule():
    v = _judge(_kept(monocular=True), shuffle=1.0, monocular=True)
    assert v.status == {10: REDUNDANT} and not v.reason


def test_a_richer_view_takes_the_place_only_when_it_localises_the_poor_one():
    """The poor kept view (a quarter of the place's points) goes only when the rich new view's points give it a pose."""
    poor = ALL[:50]
    kept = _kept(poor)
    v = _judge(kept)
    assert v.status == {10: RICHER} and v.replaced == {10: 1} and [k.kf_id for k in kept] == [10]
    kept = _kept(poor, shuffle=1.0)
    v = _judge(kept)
    assert v.status == {10: VARIANT} and "would not localise view 1" in v.reason[10]
    assert sorted(k.kf_id for k in kept) == [1, 10]


def test_prune_keeps_a_view_its_place_would_not_localise():
    """``map compact`` of a map that keeps places: the same check as at an append."""
    for shuffle, kept_ids in ((0.0, [1]), (1.0, [1, 10])):
        desc, view = _view(NEW_T, ALL, shuffle=shuffle)
        views = [*_kept(), Kept(10, NEW_T, 0, 0, 2, lambda d=desc: d, 0, view)]
        prune(views, MapConfig())
        assert [k.kf_id for k in views] == kept_ids


def _session(first_id: int, T: np.ndarray, desc: np.ndarray, view) -> tuple[SessionKeyframes, dict]:
    v = view()
    sess = SessionKeyframes(
        ids=np.array([first_id], np.int64), stamps=np.zeros(1, np.int64), T_odom=T[None], cov=np.zeros((1, 6, 6)),
        T_gt=np.full((1, 4, 4), np.nan), offsets=np.array([0, len(desc)], np.int64), keypoints=v.keypoints,
        descriptors=desc.astype(np.float16), scales=np.zeros(0, np.float32), points3d=v.points3d,
        points_source=np.array([v.source], "<U10"))
    return sess, {first_id: T}


def test_an_append_keeps_a_view_the_map_would_not_localise():
    """Through the map's arrays: the session table's camera, the session files' keypoints and 3-D points."""
    for shuffle, kept_after in ((0.0, [True, False]), (1.0, [True, True])):
        s0, p0 = _session(0, KEPT_T, *_view(KEPT_T, ALL))
        s1, p1 = _session(10, NEW_T, *_view(NEW_T, ALL, shuffle=shuffle))
        poses = {**p0, **p1}
        g0 = MapGraph.empty()
        g0.kf_ids, g0.T_map = np.array([0], np.int64), KEPT_T[None]
        g0.kf_place, g0.kf_last_used, g0.kf_appearance = (np.array([v], np.int64) for v in (0, 1, 0))
        g1 = MapGraph.empty()
        g1.kf_ids, g1.T_map = np.array([0, 10], np.int64), np.stack([KEPT_T, NEW_T])
        g1.kf_place, g1.kf_last_used, g1.kf_appearance = (np.array([v, -1], np.int64) for v in (0, 1, 0))
        table = [{"name": "s0", "component": 0, "camera": camera_json(CAM)}]
        meta = {"name": "s1", "component": 0, "camera": camera_json(CAM)}
        result = SimpleNamespace(poses=poses, component={"s0": 0, "s1": 0})
        after, _, g = reduce_append(table, [s0], g0, g1, result, meta, s1, [], MapConfig())
        assert [bool(s.kept().all()) for s in after] == kept_after
        assert int(g.kf_place[1]) == (0 if shuffle else -1)
