"""The fast graph verification (sweep and grid crossing tests) against the all-pairs reference it replaced.

Crossing counts and booleans must equal the brute force on random, integer-grid (collinear,
duplicate) and real point sets; ``verify_graph`` must return the same verdicts (every field)
as the reference implementation kept in ``lcd_graph_reference.py``.
"""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.features.matching import mutual_nn_match_bf
from slam_lcd.lcd import LcdConfig, planar_graph, verify_graph
from slam_lcd.lcd.budget import select_matches
from slam_lcd.lcd.segments import crosses_any, crossing_counts

from support import lcd_graph_reference as ref


def DELAUNAY(**kw) -> LcdConfig:
    """The reference scores a node's neighbourhood by its Delaunay neighbours (``graph_knn=0``)."""
    return LcdConfig(graph_knn=0, **kw)


def _assert_same_verdict(v, w):
    assert (w.accepted, w.reason, w.n_nodes, w.n_matches, w.iterations) == \
        (v.accepted, v.reason, v.n_nodes, v.n_matches, v.iterations)
    assert np.array_equal(w.kept, v.kept)
    # bit-identical floats: the same values are summed and divided
    assert (w.score, w.orientation_agreement, w.crossing_free, w.edge_jaccard) == \
        (v.score, v.orientation_agreement, v.crossing_free, v.edge_jaccard)


def _point_sets(rng, n):
    """Random, integer grid (many collinear triples, shared lines, duplicates), quarter-pixel, on two lines."""
    yield rng.uniform(0, 640, (n, 2))
    yield rng.integers(0, 10, (n, 2)).astype(np.float64)
    yield np.round(rng.uniform(0, 100, (n, 2)) * 4) / 4
    t = rng.uniform(0, 1, n)
    yield np.stack([t * 300, t * 150 + rng.integers(0, 2, n)], axis=1)
    yield np.repeat(rng.uniform(0, 50, (max(n // 4, 1), 2)), 4, axis=0)[:n]  # every point four times


def test_crossings_equal_brute_force_on_random_and_degenerate_sets():
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(40):
        n = int(rng.integers(3, 160))
        for pts in _point_sets(rng, n):
            edges = rng.integers(0, len(pts), (int(rng.integers(1, 3 * n)), 2))
            edges = edges[edges[:, 0] != edges[:, 1]]
            if not len(edges):
                continue
            expect = ref.crossing_edges(pts, edges)
            assert np.array_equal(crossing_counts(pts, edges), expect)
            assert np.array_equal(crosses_any(pts, edges), expect > 0)
            checked += 1
    assert checked > 150


def test_crossings_of_a_planar_graph_drawn_elsewhere():
    """The case verification meets: a triangulation of one image drawn through (partly wrong) matches."""
    rng = np.random.default_rng(8)
    for n, wrong in [(50, 0.0), (300, 0.02), (300, 0.3), (500, 0.9), (500, 0.1)]:
        src = rng.uniform([0, 0], [640, 480], (n, 2))
        _, edges = planar_graph(src, 3.0)
        dst = src * 1.05 + rng.normal(0, 1.0, (n, 2))
        bad = rng.choice(n, int(wrong * n), replace=False)
        dst[bad] = rng.uniform([0, 0], [640, 480], (len(bad), 2))
        expect = ref.crossing_edges(dst, edges)
        assert np.array_equal(crossing_counts(dst, edges), expect)
        assert np.array_equal(crosses_any(dst, edges), expect > 0)
        assert crossing_counts(src, edges).sum() == 0  # planar where it was built


def test_every_path_of_crosses_any_gives_the_same_answer(monkeypatch):
    """The sweep (step 0), all pairs (step 1) and the neighbour/direct/grid passes (steps 2-4) agree
    with the reference on clean, partly and fully scrambled drawings and a sheaf, whole or in blocks.

    Long segments across the whole image (a drawing scrambled by wrong matches, a sheaf of
    near-parallel lines) are the sweep's worst case, where its pairs approach all pairs: there
    the dispatch leaves the sweep for the passes (``_SWEEP_MAX_PAIRS``).
    """
    from slam_lcd.lcd import segments

    rng = np.random.default_rng(9)
    drawings = []
    for n, wrong in [(20, 0.0), (40, 0.1), (60, 0.5), (85, 0.05), (120, 1.0), (300, 0.02), (300, 0.6)]:
        src = rng.uniform([0, 0], [640, 480], (n, 2))
        _, edges = planar_graph(src, 3.0)
        dst = src + rng.normal(0, 1.0, (n, 2))
        bad = rng.choice(n, int(wrong * n), replace=False)
        dst[bad] = rng.uniform([0, 0], [640, 480], (len(bad), 2))
        drawings.append((dst, edges))
    edges = rng.integers(0, 30, (200, 2))
    drawings.append((rng.integers(0, 10, (30, 2)).astype(np.float64), edges[edges[:, 0] != edges[:, 1]]))
    t = np.linspace(0, 1, 60)  # a sheaf: every segment's box overlaps every other's
    sheaf = np.concatenate([np.stack([t * 5, np.zeros(60)], 1), np.stack([600 - t * 5, 480 + 3 * t], 1)])
    drawings.append((sheaf, np.column_stack([np.arange(60), 60 + rng.permutation(60)])))
    cases = [(pts, edges, ref.crossing_edges(pts, edges)) for pts, edges in drawings]
    assert cases[-1][2].sum() > 0 and any(len(e) > segments._ALL_PAIRS_MAX for _, e, _ in cases)
    paths = {"dispatch": {}, "sweep": {"_SWEEP_MAX_PAIRS": 10**9}, "all pairs, then passes": {"_SWEEP_MAX_PAIRS": -1},
             "passes": {"_SWEEP_MAX_PAIRS": -1, "_ALL_PAIRS_MAX": 0}}
    for settings in paths.values():
        for chunk in (segments._PAIR_CHUNK, 7):
            monkeypatch.setattr(segments, "_PAIR_CHUNK", chunk)
            for name, value in settings.items():
                monkeypatch.setattr(segments, name, value)
            for pts, edges, expect in cases:
                assert np.array_equal(crosses_any(pts, edges), expect > 0)
                assert np.array_equal(crossing_counts(pts, edges), expect)
            monkeypatch.undo()


def test_the_sweep_is_left_for_scrambled_drawings(monkeypatch):
    """A drawing through wrong matches has long segments whose boxes overlap nearly all others:
    the sweep would form nearly all pairs, so crosses_any takes the passes there (and the sweep
    for a drawing through right matches)."""
    from slam_lcd.lcd import segments

    rng = np.random.default_rng(21)
    src = rng.uniform([0, 0], [640, 480], (300, 2))
    _, edges = planar_graph(src, 3.0)
    right = src + rng.normal(0, 1.0, src.shape)
    scrambled = rng.uniform([0, 0], [640, 480], src.shape)
    swept = []
    real_sweep = segments._Sweep.overlapping_pairs

    def spy(self):
        swept.append(True)
        return real_sweep(self)

    monkeypatch.setattr(segments._Sweep, "overlapping_pairs", spy)
    crosses_any(right, edges)
    assert swept == [True]
    crosses_any(scrambled, edges)
    assert swept == [True]


def test_planar_graph_and_empty_inputs_unchanged():
    rng = np.random.default_rng(9)
    for pts in _point_sets(rng, 80):
        tri, edges = planar_graph(pts, 3.0)
        tri_r, edges_r = ref.planar_graph(pts, 3.0)
        assert np.array_equal(tri, tri_r) and np.array_equal(edges, edges_r)
    pts = np.zeros((3, 2))
    assert crosses_any(pts, np.zeros((0, 2), np.int64)).shape == (0,)
    assert crossing_counts(pts, np.array([[0, 1]])).tolist() == [0]


def _scenes(rng, count):
    for trial in range(count):
        n = int(rng.integers(15, 260))
        pq = rng.uniform([0, 0], [640, 480], (n, 2))
        pm = pq * rng.uniform(0.8, 1.2) + rng.normal(0, rng.choice([0.5, 3.0, 10.0]), (n, 2))
        k = int(rng.integers(0, n + 1))
        pm[rng.choice(n, k, replace=False)] = rng.uniform([0, 0], [640, 480], (k, 2))
        if trial % 3 == 0:
            pq, pm = np.round(pq), np.round(pm)  # integer pixels: duplicates and collinear points
        yield pq, pm, np.column_stack([np.arange(n), np.arange(n)])


@pytest.fixture(scope="module")
def random_cases():
    """Random scenes (0-100% wrong matches) with the reference's verdict, computed once."""
    exact = DELAUNAY(graph_early_exit=False)
    return [(pq, pm, m, ref.verify_graph(pq, pm, m, exact)) for pq, pm, m in _scenes(np.random.default_rng(10), 50)]


def test_verify_graph_identical_to_reference_on_random_match_sets(random_cases):
    exact = DELAUNAY(graph_early_exit=False)
    for pq, pm, m, v in random_cases:
        _assert_same_verdict(v, verify_graph(pq, pm, m, exact))
    accepted = sum(v.accepted for *_, v in random_cases)
    assert accepted >= 10 and len(random_cases) - accepted >= 10  # both kinds of verdict are compared


def test_early_exit_keeps_every_decision(random_cases):
    exits = 0
    for pq, pm, m, v in random_cases:
        w = verify_graph(pq, pm, m, DELAUNAY(graph_early_exit=True))
        assert w.accepted == v.accepted
        if v.accepted or not w.stopped_early:
            _assert_same_verdict(v, w)
        else:
            exits += 1
            assert w.reason == "low_node_ratio" and w.iterations <= v.iterations
            assert w.n_nodes / w.n_matches < LcdConfig().graph_min_node_ratio
    assert exits >= 3


@pytest.fixture(scope="module")
def corridor_sp(shared_data, superpoint_weights):
    from support.lcd_corridor_cache import corridor_features

    return corridor_features(str(shared_data / "rtabmap_corridor"), "superpoint", str(superpoint_weights))


def _corridor_pairs():
    rng = np.random.default_rng(12)
    pairs = [(q, q - d) for q in range(41, 84, 3) for d in (40, 41)]  # revisits (mostly GT loops)
    pairs += [tuple(rng.choice(84, 2, replace=False)) for _ in range(30)]  # mostly different places
    return pairs


def test_verify_graph_identical_to_reference_on_corridor_matches(corridor_sp):
    conf = DELAUNAY()
    exact = DELAUNAY(graph_early_exit=False)
    loose = DELAUNAY(graph_early_exit=False, match_max_distance_sp=1.0, match_ratio=None)  # many wrong matches
    seen = {True: 0, False: 0}
    for q, m in _corridor_pairs():
        fq, fm = corridor_sp[q], corridor_sp[m]
        for c in (exact, loose):
            matches = mutual_nn_match_bf(fq.descriptors, fm.descriptors, c.match_ratio, c.match_max_distance_sp)
            v = ref.verify_graph(fq.keypoints, fm.keypoints, matches, c)
            _assert_same_verdict(v, verify_graph(fq.keypoints, fm.keypoints, matches, c))
            assert verify_graph(fq.keypoints, fm.keypoints, matches, conf).accepted == v.accepted
            if v.n_matches >= conf.graph_min_matches:
                seen[v.accepted] += 1
            # the crossing test on the real drawn graphs
            pq = np.asarray(fq.keypoints, np.float64)[matches[:, 0]]
            pm = np.asarray(fm.keypoints, np.float64)[matches[:, 1]]
            _, e = planar_graph(pq, 0)
            assert np.array_equal(crosses_any(pm, e), ref.crossing_edges(pm, e) > 0)
    assert seen[True] >= 5 and seen[False] >= 5


# --------------------------------------------------------------------- match budget


def test_budget_keeps_best_and_spreads():
    rng = np.random.default_rng(13)
    kp = np.vstack([rng.uniform([0, 0], [100, 100], (300, 2)),  # a distinctive patch, best distances
                    rng.uniform([100, 100], [640, 480], (300, 2))])
    dist = np.concatenate([rng.uniform(0.1, 0.3, 300), rng.uniform(0.3, 0.7, 300)])
    matches = np.column_stack([np.arange(600), rng.permutation(600)])
    assert np.array_equal(select_matches(matches, dist, kp, 0), np.arange(600))
    assert np.array_equal(select_matches(matches, dist, kp, 600), np.arange(600))
    best = select_matches(matches, dist, kp, 200, (640, 480), spread_cells=0)
    assert len(best) == 200 and set(best) == set(np.argsort(dist)[:200].tolist())
    spread = select_matches(matches, dist, kp, 200, (640, 480), spread_cells=4)
    assert len(spread) == 200 and len(np.unique(spread)) == 200
    assert (spread >= 300).sum() > 100  # most cells lie outside the patch: they get their share
    cell = np.minimum((kp / [160, 120]).astype(int), 3) @ [1, 4]
    assert set(cell[spread]) == set(cell)  # every occupied cell is represented
    for c in np.unique(cell):  # and within a cell the best distances are taken first
        mine = np.flatnonzero(cell == c)
        kept = np.intersect1d(mine, spread)
        assert set(kept) == set(mine[np.argsort(dist[mine], kind="stable")[:len(kept)]].tolist())
