"""The maximum clique of a consistency graph: exact branch and bound, a node budget.

Why exact: a greedy clique grown from well-connected seeds is fooled by loops of high degree
that are consistent with many others but not with each other; it can return two loops of a true
set of four, or let a smaller false set win. The search only has to prove or improve a greedy
clique, and two searches share that work by the graph's shape:

* **Near-complete graphs** (true loops: almost every pair consistent). A clique is what is left
  of the vertices after removing a vertex cover of the complement graph (the inconsistent
  pairs), and that graph is sparse: the minimum vertex cover is found by branch and reduce.
  Reductions keep optimality: an isolated vertex stays out, the neighbour of a degree-1 vertex
  goes in, so do the two neighbours of a degree-2 vertex in a triangle, and a vertex with more
  neighbours than the cover may still take goes in (its neighbours all would otherwise). A
  greedy matching bounds the cover from below, independent parts are solved apart, and the
  search branches on the vertex of most inconsistencies: it is in the cover, or all its
  neighbours are. Bron–Kerbosch on such a graph goes one vertex deep per clique member and
  prunes nothing (every branch still sees hundreds of candidates).
* **Sparse graphs** (few loops agree: false loops, look-alikes). Tomita's MCQ: the candidates
  are greedily coloured and a branch is cut when its clique plus its number of colours cannot
  beat the best; vertices are taken by degree, highest first.

Before either, a vertex with fewer neighbours than the greedy clique has members cannot be in a
larger clique and is dropped (repeatedly); the dense search runs when what is left has at least
half of its pairs consistent.

Bound: the search stops after ``budget`` nodes, a node of the cover search counting for
:data:`COVER_NODE`; a node costs O(n) operations on n-bit integers, so the default budget of
100,000 bounds a search that cannot prove its answer to a few seconds at 1000 loops (a random
graph of 1000 vertices with 2 % of its pairs missing: 3.7 s).
Measured (``tools/bench_pcm.py``, 2-core AMD EPYC): 1000 true loops of two sessions, 2 % of
their pairs inconsistent: the largest set (840) proven in 44 nodes, 0.02-0.035 s, the largest
among the rest (71) in 126 nodes, 0.01-0.02 s; with 10 % false loops 59 and 80 nodes.
Bron–Kerbosch with a pivot and the size bound alone runs out of the default budget of 100,000
nodes on each (4.7-5.4 s and 1.5 s), one loop short of the largest. Past the budget either
search stops and returns the best clique found with ``exact=False``, at least the greedy one (for
a near-complete graph the better of the greedy clique and what a greedy cover leaves: the vertex
of most inconsistencies out, repeatedly); the caller logs it and records it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DENSE = 0.5  # share of consistent pairs from which the complement's vertex cover is searched
MAX_DEPTH = 300  # nested branches and splits of the cover search (Python's stack); deeper ones finish greedily
SEEDS = 16  # seeds of the greedy clique (highest degrees first)
# budget units a node of the cover search counts for: it reduces, bounds and splits the whole graph
# (0.25 ms at 300 vertices, 0.6 ms at 1000 on the 2-core EPYC, about twenty times a colouring node)
COVER_NODE = 20


@dataclass
class CliqueSearch:
    members: list[int]  # sorted vertex indices of the largest clique found
    exact: bool  # True: proven maximum; False: the node budget ran out first
    nodes: int  # search nodes explored


def _bits(mask: int) -> list[int]:
    """The set bits of ``mask``, ascending (through numpy: a Python loop over bits costs ~1 us a bit)."""
    raw = np.frombuffer(mask.to_bytes((mask.bit_length() + 7) // 8, "little"), np.uint8)
    return np.flatnonzero(np.unpackbits(raw, bitorder="little")).tolist()


def _rows(adj: np.ndarray) -> list[int]:
    """Each row of a bool matrix as an integer bitset (bit j: column j)."""
    packed = np.packbits(adj, axis=1, bitorder="little")
    return [int.from_bytes(r.tobytes(), "little") for r in packed]


def _greedy(nbr: list[int], live: int) -> int:
    """From each of the first :data:`SEEDS` vertices, a clique grown through the candidates in index
    order (highest degree first); the largest."""
    best = 0
    for seed in list(_bits(live))[:SEEDS]:
        clique, cand = 1 << seed, live & nbr[seed]
        while cand:
            low = cand & -cand
            clique |= low
            cand &= nbr[low.bit_length() - 1]
        if clique.bit_count() > best.bit_count():
            best = clique
    return best


def _core(nbr: list[int], live: int, size: int) -> int:
    """The vertices that may be in a clique of more than ``size``: at least ``size`` neighbours among them."""
    changed = True
    while changed:
        changed = False
        for v in _bits(live):
            if (nbr[v] & live).bit_count() < size:
                live ^= 1 << v
                changed = True
    return live


class _Cover:
    """Minimum vertex cover of a sparse graph (bitset neighbours ``hn``), branch and reduce, node budget."""

    def __init__(self, hn: list[int], budget: int):
        self.hn, self.budget = hn, budget
        self.nodes, self.exact = 0, True

    def reduce(self, live: int, limit: int) -> tuple[int, int, int, int]:
        """The rules that keep an optimal cover (module docstring); ``limit``: the cover must stay below it.
        Returns the vertices left, those put in the cover, and the vertex of most neighbours left with
        their number."""
        hn, taken, k = self.hn, 0, 0
        changed = True
        top, most = -1, -1
        while changed and live:
            changed, top, most = False, -1, -1
            for v in _bits(live):
                if not live >> v & 1:
                    continue
                nb = hn[v] & live
                d = nb.bit_count()
                if d == 0:
                    live ^= 1 << v
                elif d == 1:
                    taken, k, live, changed = taken | nb, k + 1, live & ~(nb | 1 << v), True
                elif d >= limit - k:  # outside the cover its d neighbours would be in it: too many
                    taken, k, live, changed = taken | 1 << v, k + 1, live ^ 1 << v, True
                elif d == 2 and hn[(nb & -nb).bit_length() - 1] & nb:
                    taken, k, live, changed = taken | nb, k + 2, live & ~(nb | 1 << v), True
                elif d > most:
                    top, most = v, d
                if k >= limit:
                    return live, taken, -1, -1
        return live, taken, top, most

    def matching(self, live: int) -> int:
        """Edges of a greedy maximal matching: each needs its own cover vertex (a lower bound)."""
        free, size = live, 0
        for v in _bits(live):
            if free >> v & 1:
                cand = self.hn[v] & free
                if cand:
                    free &= ~(1 << v | (cand & -cand))
                    size += 1
        return size

    def components(self, live: int) -> list[int]:
        out = []
        while live:
            comp = front = live & -live
            while front:
                reach = 0
                for v in _bits(front):
                    reach |= self.hn[v]
                front = reach & live & ~comp
                comp |= front
            out.append(comp)
            live &= ~comp
        return out

    def search(self, live: int, limit: int, depth: int = 0, greedy: bool = False) -> int | None:
        """The smallest cover of the graph on ``live`` with fewer than ``limit`` vertices; None when there is
        none (or none found within the budget). Greedy: no second branches (the search's first bound)."""
        taken, best = 0, None
        while True:
            self.nodes += 1
            live, forced, v, d = self.reduce(live, limit - taken.bit_count())
            taken |= forced
            k = taken.bit_count()
            if k >= limit:
                return best
            if not live:
                return taken
            if k + self.matching(live) >= limit:
                return best
            parts = self.components(live)
            if len(parts) > 1 and depth < MAX_DEPTH:
                rest = self.split(parts, limit - k, depth, greedy)
                return best if rest is None else taken | rest
            nb = self.hn[v] & live
            if k + d < limit and not greedy:  # second branch: v outside the cover, all its neighbours in it
                if self.nodes > self.budget:
                    self.exact = False
                    return best
                if depth >= MAX_DEPTH:
                    self.exact = False
                else:
                    r = self.search(live & ~(nb | 1 << v), limit - k - d, depth + 1)
                    if r is not None:
                        best = taken | nb | r
                        limit = best.bit_count()
            taken |= 1 << v
            live ^= 1 << v

    def split(self, parts: list[int], limit: int, depth: int, greedy: bool) -> int | None:
        """Independent parts one by one, each bounded by what the others need at least."""
        need = [self.matching(p) for p in parts]
        out, k = 0, 0
        for i, p in enumerate(parts):
            r = self.search(p, limit - k - sum(need[i + 1:]), depth + 1, greedy)
            if r is None:
                return None
            out |= r
            k += r.bit_count()
        return out


def _dense(nbr: list[int], live: int, best: int, budget: int) -> tuple[int, bool, int]:
    """The largest clique as ``live`` less a minimum vertex cover of the complement graph."""
    hn = [~nbr[v] & live & ~(1 << v) if live >> v & 1 else 0 for v in range(len(nbr))]
    search = _Cover(hn, max(1, budget // COVER_NODE))
    n = live.bit_count()
    first = search.search(live, n - best.bit_count() + 1, greedy=True)  # the greedy cover bounds the search
    if first is not None and n - first.bit_count() > best.bit_count():
        best = live & ~first
    found = search.search(live, n - best.bit_count())
    if found is not None:
        best = live & ~found
    return best, search.exact, search.nodes


def _colour(nbr: list[int], P: int) -> tuple[list[int], list[int]]:
    """Greedy colouring of ``P`` in index order: vertices sorted by colour, and their colours."""
    verts, cols, c = [], [], 0
    while P:
        c += 1
        Q = P
        while Q:
            low = Q & -Q
            v = low.bit_length() - 1
            verts.append(v)
            cols.append(c)
            P ^= low
            Q &= ~nbr[v] & ~low
    return verts, cols


class _Branch:
    """One open node of the sparse search: its clique, its candidates, their colours (ascending)."""

    __slots__ = ("R", "r", "P", "verts", "cols")

    def __init__(self, nbr: list[int], R: int, r: int, P: int):
        self.R, self.r, self.P = R, r, P
        self.verts, self.cols = _colour(nbr, P)


def _sparse(nbr: list[int], live: int, best: int, budget: int) -> tuple[int, bool, int]:
    """Tomita's MCQ: branch on the candidates from the highest colour down; a colour bound cuts a branch."""
    size = best.bit_count()
    nodes, exact = 1, True
    stack = [_Branch(nbr, 0, 0, live)]
    while stack:
        b = stack[-1]
        if not b.verts or b.r + b.cols[-1] <= size:
            stack.pop()
            continue
        v = b.verts.pop()
        b.cols.pop()
        Pv = b.P & nbr[v]
        b.P &= ~(1 << v)
        if not Pv:
            if b.r + 1 > size:
                best, size = b.R | 1 << v, b.r + 1
            continue
        nodes += 1
        if nodes > budget:
            exact = False
            break
        stack.append(_Branch(nbr, b.R | 1 << v, b.r + 1, Pv))
    return best, exact, nodes


def maximum_clique(adj: np.ndarray, budget: int = 20000, allowed: np.ndarray | None = None) -> CliqueSearch:
    """Largest set of vertices pairwise adjacent in ``adj`` (symmetric bool, diagonal ignored).

    ``allowed`` (bool mask): search only these vertices. ``budget``: search nodes at most.
    """
    adj = np.asarray(adj, bool)
    mask = np.ones(len(adj), bool) if allowed is None else np.asarray(allowed, bool)
    idx = np.flatnonzero(mask)
    if len(idx) == 0:
        return CliqueSearch([], True, 0)
    sub = adj[np.ix_(idx, idx)].copy()
    np.fill_diagonal(sub, False)
    order = np.argsort(-sub.sum(1), kind="stable")  # highest degree first: bit 0
    sub = sub[np.ix_(order, order)]
    nbr = _rows(sub)
    live = (1 << len(idx)) - 1
    best = _greedy(nbr, live)
    live = _core(nbr, live, best.bit_count())
    exact, nodes = True, 0
    if live:
        n = live.bit_count()
        pairs = sum((nbr[v] & live).bit_count() for v in _bits(live))
        run = _dense if pairs >= DENSE * n * (n - 1) else _sparse
        best, exact, nodes = run(nbr, live, best, budget)
    return CliqueSearch(sorted(int(idx[order[v]]) for v in _bits(best)), exact, nodes)
