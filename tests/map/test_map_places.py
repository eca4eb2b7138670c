"""The place rules on views of unequal richness, and ``compact`` of a map that keeps places already.

Synthetic descriptors (unit float rows), no logs: a poor kept view (a blurred or dim moment) must not
absorb the rich views of its place; a richer view of the same appearance takes its place. A map built
by lifelong appends (days, a night, days again) compacted once and twice keeps its appearances,
last-use records and variants.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from slam_lcd.map.config import MapConfig
from slam_lcd.map.contents import MapGraph, SessionKeyframes
from slam_lcd.map.lifelong import compact, counts, reduce_append
from slam_lcd.map.places import REDUNDANT, RICHER, VARIANT, Kept, alike_ratio, judge, match_ratio


def _pose(x: float) -> np.ndarray:
    T = np.eye(4)
    T[0, 3] = x
    return T


def _unit(rows: np.ndarray) -> np.ndarray:
    return (rows / np.linalg.norm(rows, axis=1, keepdims=True)).astype(np.float32)


def _desc(seed: int, n: int) -> np.ndarray:
    return _unit(np.random.default_rng(seed).normal(size=(n, 64)))


def _again(d: np.ndarray, seed: int, noise: float = 0.1) -> np.ndarray:
    """Another view of the same descriptors (the same place in the same appearance): a little noise on each."""
    return _unit(d + noise * np.random.default_rng(seed).normal(size=d.shape) / np.sqrt(d.shape[1]))


def _const(d: np.ndarray):
    return lambda: d


def _mutual(a: np.ndarray, b: np.ndarray) -> int:
    return round(match_ratio(a, b) * len(a))


PLACE = _desc(1, 800)  # what a good view of the place shows
POOR = PLACE[:60]  # a blurred or dim moment of it: the 60 strongest of the same descriptors


def test_the_share_is_of_the_view_judged_not_of_the_smaller_one():
    rich = _again(PLACE, 2)
    assert match_ratio(POOR, rich) > 0.9  # all of the poor view lies in the rich one
    assert match_ratio(rich, POOR) < 0.1  # little of the rich view lies in the poor one
    assert alike_ratio(rich, POOR) == alike_ratio(POOR, rich) == match_ratio(POOR, rich)  # one appearance


def test_a_poor_kept_view_does_not_absorb_richer_views_of_its_place():
    """Rich views of the unchanged place meet a poor kept view: the first takes its place (its id, appearance
    and last use), the next is redundant against it; a later visit finds its matches in what is kept."""
    conf = MapConfig()
    kept = [Kept(1, _pose(0.0), 0, 7, 2, _const(POOR), 1)]
    v = judge([(10, _pose(0.2), _const(_again(PLACE, 3))), (11, _pose(0.3), _const(_again(PLACE, 4)))],
              0, kept, conf, now=5, next_place=8, appearance=1)
    assert v.status == {10: RICHER, 11: REDUNDANT} and v.replaced == {10: 1} and v.matched == {11: 10}
    assert [(k.kf_id, k.place, k.appearance, k.last_used) for k in kept] == [(10, 7, 1, 5)]
    later = _again(PLACE, 5)
    assert max(_mutual(later, k.descriptors()) for k in kept) > 0.8 * len(PLACE)


def test_a_poor_new_view_of_a_rich_kept_one_is_redundant():
    conf = MapConfig()
    kept = [Kept(1, _pose(0.0), 0, 0, 1, _const(_again(PLACE, 6)))]
    v = judge([(10, _pose(0.2), _const(_again(POOR, 7)))], 0, kept, conf, now=2, next_place=1)
    assert v.status == {10: REDUNDANT} and v.matched == {10: 1} and [k.kf_id for k in kept] == [1]


def test_a_richer_view_replaces_only_its_own_appearance_and_each_appearance_keeps_a_view():
    """A place with a day view and a poor night view: a rich night view replaces the night one, the day view
    stays; a rich view of the same place judged in the day appearance is redundant against the day view."""
    conf = MapConfig(max_variants=2)
    day = _desc(20, 500)
    kept = [Kept(1, _pose(0.0), 0, 0, 3, _const(day), 0), Kept(2, _pose(0.1), 0, 0, 1, _const(POOR), 1)]
    v = judge([(10, _pose(0.05), _const(_again(PLACE, 8)))], 0, kept, conf, now=4, next_place=1, appearance=1)
    assert v.status == {10: RICHER} and v.replaced == {10: 2} and not v.evicted
    assert sorted((k.kf_id, k.place, k.appearance) for k in kept) == [(1, 0, 0), (10, 0, 1)]
    v = judge([(11, _pose(0.05), _const(_again(day, 9)))], 0, kept, conf, now=5, next_place=1, appearance=0)
    assert v.status == {11: REDUNDANT} and v.matched == {11: 1}
    v = judge([(12, _pose(0.0), _const(_desc(21, 300)))], 0, kept, conf, now=6, next_place=1, appearance=0)
    assert v.status == {12: VARIANT} and v.evicted == [1]  # a day view gives way to a day view, not the night's
    assert sorted(k.appearance for k in kept) == [0, 1]


def test_an_append_whose_richer_view_replaces_an_old_one_rewrites_that_session():
    """The poor view of session 0 replaced by session 1's rich view: session 0 loses its descriptors (its file is
    rewritten), session 1 keeps the rich view with the place's records."""
    conf = MapConfig()
    s0, p0 = _session(0, [POOR])
    s1, p1 = _session(10, [_again(PLACE, 11)], x=0.2)
    poses = {**p0, **p1}
    g0 = _graph([0], poses, None)
    g0.kf_place, g0.kf_last_used, g0.kf_appearance = (np.array([v], np.int64) for v in (0, 1, 0))
    result = SimpleNamespace(poses=poses, component={"s0": 0, "s1": 0})
    after, changed, g = reduce_append([{"name": "s0", "component": 0}], [s0], g0, _graph([0, 10], poses, g0),
                                      result, {"name": "s1", "component": 0}, s1, [], conf)
    assert changed == {0} and not after[0].kept().any() and after[1].kept().all()  # (the new session is written)
    assert _records(g) == {10: (0, 2, 0)}


def test_a_richer_view_of_the_same_append_drops_the_poorer_one_it_added():
    conf = MapConfig()
    v = judge([(10, _pose(0.0), _const(POOR)), (11, _pose(0.1), _const(_again(PLACE, 10)))], 0, [], conf,
              now=1, next_place=0)
    assert v.status == {10: REDUNDANT, 11: RICHER} and v.place == {11: 0}


# -- compact of a map that keeps places


def _session(first_id: int, views: list[np.ndarray], x: float = 0.0):
    """A session file (float16 descriptors) of ``views`` 0.4 m apart from ``x`` on, and its poses."""
    n = len(views)
    desc = np.concatenate(views).astype(np.float16)
    T = np.stack([_pose(x + 0.4 * i) for i in range(n)])
    rows = len(desc)
    sess = SessionKeyframes(
        ids=np.arange(first_id, first_id + n, dtype=np.int64), stamps=np.arange(n, dtype=np.int64) * 10**9,
        T_odom=T, cov=np.zeros((n, 6, 6)), T_gt=np.full((n, 4, 4), np.nan),
        offsets=np.concatenate([[0], np.cumsum([len(v) for v in views])]).astype(np.int64),
        keypoints=np.zeros((rows, 2), np.float32), descriptors=desc, scales=np.zeros(0, np.float32),
        points3d=np.zeros((rows, 3), np.float32), points_source=np.array(["rgbd"] * n, "<U10"))
    return sess, {int(k): t for k, t in zip(sess.ids, T, strict=True)}


def _route(kind: str, first_id: int, shift_m: float = 0.0) -> tuple[SessionKeyframes, dict[int, np.ndarray]]:
    """Six views 0.4 m apart along a wall of 300 points, 100 a view (test_map_lifelong's route), as a session
    file (float16 descriptors); ``night`` describes 55 % of the points otherwise."""
    rng = np.random.default_rng(7)
    day = rng.normal(size=(300, 64))
    pts = {"day": day, "night": np.where(rng.random((300, 1)) < 0.45, day, rng.normal(size=(300, 64)))}[kind]
    pts = _unit(pts)
    return _session(first_id, [pts[30 * i: 30 * i + 100] for i in range(6)], shift_m)


def _graph(ids: list[int], poses: dict[int, np.ndarray], before: MapGraph | None) -> MapGraph:
    g = MapGraph.empty()
    g.kf_ids = np.array(ids, np.int64)
    g.T_map = np.stack([poses[k] for k in ids])
    for name in MapGraph.OPTIONAL:  # the records of the keyframes the map held, as a joint solve carries them
        old = getattr(before, name, None) if before is not None else None
        if old is not None:
            setattr(g, name, np.concatenate([old, np.full(len(ids) - len(old), -1, np.int64)]))
    return g


def _lifelong_map(conf: MapConfig):
    """Sessions day, night, day (slightly off), each appended with the rule: (table, sessions, graph, poses, the
    sessions each append changed)."""
    table, sessions, poses, graph, rewrites = [], [], {}, MapGraph.empty(), []
    for i, (kind, shift) in enumerate((("day", 0.0), ("night", 0.05), ("day", 0.1))):
        sess, p = _route(kind, 100 * i, shift)
        poses.update(p)
        meta = {"name": f"s{i}", "component": 0}
        new_graph = _graph([k for s in [*sessions, sess] for k in s.ids.tolist()], poses, graph)
        result = SimpleNamespace(poses=poses, component={m["name"]: 0 for m in [*table, meta]})
        sessions, changed, graph = reduce_append(table, sessions, graph, new_graph, result, meta, sess, [], conf)
        table.append(meta)
        rewrites.append(changed)
    return table, sessions, graph, poses, rewrites


def _records(graph: MapGraph) -> dict[int, tuple[int, int, int]]:
    return {int(k): (int(p), int(u), int(a)) for k, p, u, a in
            zip(graph.kf_ids, graph.kf_place, graph.kf_last_used, graph.kf_appearance, strict=True) if p >= 0}


def test_compacting_a_lifelong_map_keeps_its_appearances_last_uses_and_variants():
    conf = MapConfig()
    table, sessions, graph, poses, rewrites = _lifelong_map(conf)
    assert rewrites == [{0}, {1}, {2}]  # each append dropped views of its own session only: no earlier file rewritten
    before = _records(graph)
    assert {a for _, _, a in before.values()} == {0, 1} and len({u for _, u, _ in before.values()}) >= 2
    nights = {k for k, (_, _, a) in before.items() if a == 1}
    assert nights and nights <= set(range(100, 106))
    first = counts(graph, sessions)
    for _ in range(2):  # compacted, then compacted again
        sessions, changed, graph = compact(table, sessions, graph, poses, [], conf)
        assert not changed and _records(graph) == before
        assert counts(graph, sessions) == first


def test_compacting_a_lifelong_map_drops_what_the_rules_now_drop():
    """With fewer variants allowed, each full place gives up views down to one; what stays keeps its records."""
    table, sessions, graph, poses, _ = _lifelong_map(MapConfig())
    before = _records(graph)
    per_place = {p: [k for k, r in before.items() if r[0] == p] for p, _, _ in before.values()}
    assert max(len(v) for v in per_place.values()) >= 2
    sessions, changed, graph = compact(table, sessions, graph, poses, [], MapConfig(max_variants=1))
    after = _records(graph)
    assert changed and set(after) < set(before)
    assert all(before[k] == r for k, r in after.items())  # what stays keeps its records
    assert all(sum(r[0] == p for r in after.values()) == 1 for p in per_place)  # every place keeps one view

