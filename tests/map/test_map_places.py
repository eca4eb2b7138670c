"""The place rules on views of unequal richness, and ``compact`` of a map that keeps places already.

Synthetic descriptors (unit float rows), no logs: a poor kept view (a blurred or dim moment) must not
absorb the rich views of its place; a richer view of the same appearance takes its place. A map built
by lifelong appends (days, a night, days again) compacted once and twice keeps its appearances,
last-use records and variants.
"""
from __future__ import annotations

import numpy as np

from slam_lcd.map.config import MapConfig
from slam_lcd.map.places import REDUNDANT, RICHER, VARIANT, Kept, judge, match_ratio


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


def test_a_richer_view_of_the_same_append_drops_the_poorer_one_it_added():
    conf = MapConfig()
    v = judge([(10, _pose(0.0), _const(POOR)), (11, _pose(0.1), _const(_again(PLACE, 10)))], 0, [], conf,
              now=1, next_place=0)
    assert v.status == {10: REDUNDANT, 11: RICHER} and v.place == {11: 0}
