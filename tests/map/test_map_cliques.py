"""The largest consistent set: the exact clique search against brute force, and at the size of a real map.

Small random graphs of every density go through both searches (the vertex cover of the
complement for near-complete graphs, the coloured branch and bound for sparse ones), with and
without a mask of allowed vertices; a 1000-vertex near-complete graph with a planted answer is
what 1000 true loops and 100 false ones look like. Timing lives in ``tools/bench_pcm.py``.
"""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.map.cliques import maximum_clique


def _random_graph(n: int, p: float, rng) -> np.ndarray:
    a = np.triu(rng.random((n, n)) < p, 1)
    return a | a.T


def _brute_force(adj: np.ndarray, allowed: np.ndarray) -> int:
    """Size of the largest clique among the allowed vertices, every clique extended vertex by vertex."""
    best = 0

    def grow(size: int, cand: list[int]) -> None:
        nonlocal best
        best = max(best, size)
        for k, v in enumerate(cand):
            grow(size + 1, [u for u in cand[k + 1:] if adj[v, u]])

    grow(0, [int(i) for i in np.flatnonzero(allowed)])
    return best


def _is_clique(adj: np.ndarray, members: list[int]) -> bool:
    return all(adj[i, j] for i in members for j in members if i != j)


@pytest.mark.parametrize("p, n_max", [(0.1, 40), (0.3, 30), (0.5, 24), (0.7, 18), (0.9, 16), (0.97, 16)])
def test_the_search_finds_the_brute_force_maximum_on_small_random_graphs(p, n_max):
    rng = np.random.default_rng(int(p * 100))
    for trial in range(150):
        n = int(rng.integers(1, n_max + 1))
        adj = _random_graph(n, p, rng)
        allowed = rng.random(n) < 0.75 if trial % 2 else np.ones(n, bool)
        found = maximum_clique(adj, 100000, allowed=allowed)
        assert found.exact
        assert all(allowed[i] for i in found.members)
        assert _is_clique(adj, found.members)
        assert len(found.members) == _brute_force(adj, allowed), (n, p, trial)


def _planted(rng) -> tuple[np.ndarray, int, np.ndarray]:
    """900 true loops, consistent except in small groups whose least removal is known, and 100 false loops
    consistent with a random half of all others. Returns the graph, the size of its largest clique and
    the true loops."""
    n_true, n = 900, 1000
    adj = np.ones((n, n), bool)
    true = rng.permutation(n)[:n_true]  # scattered among the false ones: the order must not matter
    removed, at = 0, 0
    for size, shape, cost in [(3, "cycle", 2)] * 40 + [(5, "cycle", 3)] * 20 + [(4, "path", 2)] * 30 \
            + [(6, "star", 1)] * 20:
        g = true[at:at + size]
        at += size
        if shape == "star":
            edges = [(g[0], v) for v in g[1:]]
        else:
            edges = list(zip(g[:-1], g[1:], strict=True)) + ([(g[-1], g[0])] if shape == "cycle" else [])
        for u, v in edges:
            adj[u, v] = adj[v, u] = False
        removed += cost
    false = np.setdiff1d(np.arange(n), true)
    for v in false:
        half = rng.random(n) < 0.5
        adj[v, :] &= half
        adj[:, v] &= half
    np.fill_diagonal(adj, False)
    return adj, n_true - removed, true


def test_a_thousand_loops_with_a_planted_answer_give_the_largest_clique_exactly():
    adj, size, true = _planted(np.random.default_rng(11))
    found = maximum_clique(adj, 100000)
    assert found.exact
    assert len(found.members) == size
    assert _is_clique(adj, found.members)
    assert set(found.members) <= set(true.tolist())
    rest = np.ones(len(adj), bool)
    rest[found.members] = False  # the rival search: the loops left over
    rival = maximum_clique(adj, 100000, allowed=rest)
    assert rival.exact and _is_clique(adj, rival.members) and not set(rival.members) & set(found.members)


def test_past_its_budget_the_search_returns_a_clique_and_says_it_is_not_proven():
    rng = np.random.default_rng(5)
    for p in (0.3, 0.95):
        adj = _random_graph(200, p, rng)
        found = maximum_clique(adj, budget=5)
        assert not found.exact
        assert _is_clique(adj, found.members) and len(found.members) >= 2
