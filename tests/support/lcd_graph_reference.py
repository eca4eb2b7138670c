"""Reference: graph verification as it was before the grid broad phase (all edge pairs, dense adjacency).

Kept only to check that :mod:`slam_lcd.lcd.graph` gives the same verdicts and crossing counts
(tests/lcd/test_lcd_graph_fast.py) and to time the two (tools/bench_graph.py). Do not use it elsewhere.

The original module note follows.

Graph verification of a loop candidate (Yue et al. 2019, §III-E, completed here).

Why: a Bag-of-Words candidate in a corridor often shares many *descriptors* with the query
(doors, lamps, posters) without being the same place. Where two images really show the
same place, the matched points keep their spatial arrangement: a point's neighbours in one
image are its neighbours in the other, triangles keep their orientation, edges do not cross.
Where the matches come from look-alike objects scattered over a different place, that
arrangement is broken.

Algorithm (the paper's text stops after "build a graph on the matched points"; the rest
is our design, see docs/lcd_graph.md):

1. Start from one-to-one (mutual nearest-neighbour) matches; merge near-duplicate points.
2. On the matched points of each image build a planar triangular graph: a Delaunay
   triangulation whose triangles with an edge longer than ``max_edge_factor`` x the median
   edge are removed (so long hull edges across empty image regions disappear; the graph need
   not be convex).
3. Carry each graph to the other image through the correspondences and measure, per node:
   the fraction of its triangles whose orientation flips, the fraction of its edges that
   cross another edge there, and the Jaccard overlap of its neighbour sets in the two graphs.
4. Remove the worst-violating nodes (a fraction of them per round), rebuild, repeat until
   no node violates the structure.
5. Accept when enough nodes survive (absolute and relative to the matches) and the two
   final graphs agree: score = mean of triangle-orientation agreement, non-crossing edge
   fraction and edge-set Jaccard of the two triangulations.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay, QhullError

from slam_lcd.lcd.config import LcdConfig
from slam_lcd.lcd.graph import GraphVerdict

# ----------------------------------------------------------------------------- graph building


def planar_graph(points: np.ndarray, max_edge_factor: float) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (T, 3) and undirected edges (E, 2) of a pruned Delaunay graph on ``points``.

    Triangles with an edge longer than ``max_edge_factor`` x the median edge length, and
    degenerate (zero-area) triangles, are dropped; edges are those of the kept triangles,
    so the graph stays planar (no two edges cross) and triangular.
    """
    n = len(points)
    empty = (np.zeros((0, 3), np.int64), np.zeros((0, 2), np.int64))
    if n < 3:
        return empty
    try:
        tri = Delaunay(points).simplices.astype(np.int64)
    except (QhullError, ValueError):  # all points collinear, or too few distinct ones
        return empty
    a, b, c = points[tri[:, 0]], points[tri[:, 1]], points[tri[:, 2]]
    lengths = np.stack(
        [np.linalg.norm(a - b, axis=1), np.linalg.norm(b - c, axis=1), np.linalg.norm(c - a, axis=1)], axis=1
    )
    area2 = np.abs(_cross2(b - a, c - a))
    longest = lengths.max(1)
    keep = area2 > 1e-6 * np.maximum(longest, 1.0) ** 2
    if max_edge_factor > 0 and keep.any():
        median = np.median(lengths[keep])
        keep &= longest <= max_edge_factor * max(median, 1e-9)
    tri = tri[keep]
    return tri, _unique_edges(tri)


def _unique_edges(tri: np.ndarray) -> np.ndarray:
    if len(tri) == 0:
        return np.zeros((0, 2), np.int64)
    e = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0)


def _cross2(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _signed_area2(pts: np.ndarray, tri: np.ndarray) -> np.ndarray:
    a, b, c = pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]
    return _cross2(b - a, c - a)


def crossing_edges(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """For each edge (drawn as a segment between ``points``), how many other edges it properly crosses.

    Edges sharing an end point never count as crossing.
    """
    m = len(edges)
    if m < 2:
        return np.zeros(m, np.int64)
    p, q = points[edges[:, 0]], points[edges[:, 1]]
    d = q - p  # (m, 2)
    # orientation of the ends of edge j relative to edge i: o[i, j]
    o_p = _cross2(d[:, None, :], p[None, :, :] - p[:, None, :])
    o_q = _cross2(d[:, None, :], q[None, :, :] - p[:, None, :])
    straddle = (o_p * o_q) < 0
    cross = straddle & straddle.T
    share = (
        (edges[:, None, 0] == edges[None, :, 0])
        | (edges[:, None, 0] == edges[None, :, 1])
        | (edges[:, None, 1] == edges[None, :, 0])
        | (edges[:, None, 1] == edges[None, :, 1])
    )
    cross &= ~share
    return cross.sum(1)


def _adjacency(n: int, edges: np.ndarray) -> np.ndarray:
    A = np.zeros((n, n), bool)
    if len(edges):
        A[edges[:, 0], edges[:, 1]] = True
        A[edges[:, 1], edges[:, 0]] = True
    return A


# ----------------------------------------------------------------------------- comparison


@dataclass
class _Comparison:
    badness: np.ndarray  # (n,) per-node violation, 0 (consistent) .. 1
    isolated: np.ndarray  # (n,) bool: node in no triangle of either graph
    orientation: float
    crossing_free: float
    edge_jaccard: float


def _directional(src: np.ndarray, dst: np.ndarray, tri: np.ndarray, edges: np.ndarray, n: int):
    """Violations of the graph built on ``src`` when drawn on ``dst``: per-node flip and crossing fractions."""
    flips = np.zeros(n)
    tri_count = np.zeros(n)
    if len(tri):
        s_src = np.sign(_signed_area2(src, tri))
        s_dst = np.sign(_signed_area2(dst, tri))
        flipped = (s_src != s_dst).astype(np.float64)
        for k in range(3):
            np.add.at(flips, tri[:, k], flipped)
            np.add.at(tri_count, tri[:, k], 1.0)
        orient = 1.0 - float(flipped.mean())
    else:
        orient = 0.0
    crosses = np.zeros(n)
    edge_count = np.zeros(n)
    if len(edges):
        c = (crossing_edges(dst, edges) > 0).astype(np.float64)
        for k in range(2):
            np.add.at(crosses, edges[:, k], c)
            np.add.at(edge_count, edges[:, k], 1.0)
        free = 1.0 - float(c.mean())
    else:
        free = 0.0
    flip_frac = np.divide(flips, tri_count, out=np.zeros(n), where=tri_count > 0)
    cross_frac = np.divide(crosses, edge_count, out=np.zeros(n), where=edge_count > 0)
    return flip_frac, cross_frac, tri_count > 0, orient, free


def compare_graphs(pq: np.ndarray, pm: np.ndarray, max_edge_factor: float) -> _Comparison:
    """Build a graph on each side, carry it to the other side and score every node."""
    n = len(pq)
    tri_q, e_q = planar_graph(pq, max_edge_factor)
    tri_m, e_m = planar_graph(pm, max_edge_factor)
    fq, cq, in_q, oq, xq = _directional(pq, pm, tri_q, e_q, n)
    fm, cm, in_m, om, xm = _directional(pm, pq, tri_m, e_m, n)
    A_q, A_m = _adjacency(n, e_q), _adjacency(n, e_m)
    inter = (A_q & A_m).sum(1)
    union = (A_q | A_m).sum(1)
    jac = np.divide(inter, union, out=np.zeros(n), where=union > 0)
    edge_jac = float(inter.sum() / union.sum()) if union.sum() else 0.0
    badness = (0.5 * (fq + fm) + 0.5 * (cq + cm) + (1.0 - jac)) / 3.0
    return _Comparison(
        badness=badness,
        isolated=~(in_q | in_m),
        orientation=0.5 * (oq + om),
        crossing_free=0.5 * (xq + xm),
        edge_jaccard=edge_jac,
    )


# ----------------------------------------------------------------------------- verification


def _dedupe(pq: np.ndarray, pm: np.ndarray, min_sep: float) -> np.ndarray:
    """Indices of matches to keep so that no two kept points coincide (within ``min_sep``) in either image."""
    keep = np.ones(len(pq), bool)
    if min_sep <= 0 or len(pq) < 2:
        return np.flatnonzero(keep)
    for pts in (pq, pm):
        cells = np.floor(pts / min_sep).astype(np.int64)
        _, first = np.unique(cells, axis=0, return_index=True)
        mask = np.zeros(len(pts), bool)
        mask[first] = True
        keep &= mask
    return np.flatnonzero(keep)


def verify_graph(
    kpts_q: np.ndarray,
    kpts_m: np.ndarray,
    matches: np.ndarray,
    conf: LcdConfig | None = None,
) -> GraphVerdict:
    """Verify a candidate by the topology of its one-to-one matches.

    ``kpts_q`` (Nq, 2) and ``kpts_m`` (Nm, 2) are pixel coordinates; ``matches`` (M, 2) holds
    rows ``[index in q, index in m]`` and must be one-to-one (e.g. from
    :func:`slam_lcd.features.matching.mutual_nn_match`). Returns a :class:`GraphVerdict`.
    """
    conf = conf or LcdConfig()
    matches = np.asarray(matches, dtype=np.int64).reshape(-1, 2)
    n_matches = len(matches)
    if n_matches and (
        len(np.unique(matches[:, 0])) != n_matches or len(np.unique(matches[:, 1])) != n_matches
    ):
        raise ValueError("verify_graph needs one-to-one matches (a keypoint appears twice)")
    if n_matches < max(conf.graph_min_matches, 3):
        return GraphVerdict(False, 0.0, n_matches, "too_few_matches", n_matches=n_matches)
    pq_all = np.asarray(kpts_q, dtype=np.float64)[matches[:, 0]]
    pm_all = np.asarray(kpts_m, dtype=np.float64)[matches[:, 1]]
    alive = _dedupe(pq_all, pm_all, conf.graph_min_separation_px)

    it = 0
    comp = None
    while True:
        if len(alive) < max(conf.graph_min_nodes, 3):
            break
        comp = compare_graphs(pq_all[alive], pm_all[alive], conf.graph_max_edge_factor)
        drop = comp.isolated.copy()
        violating = np.flatnonzero((comp.badness > conf.graph_node_threshold) & ~comp.isolated)
        if len(violating) == 0 and not drop.any():
            break
        if it >= conf.graph_max_iterations:
            break
        if len(violating):
            n_remove = max(1, int(np.ceil(conf.graph_remove_fraction * len(violating))))
            worst = violating[np.argsort(-comp.badness[violating], kind="stable")[:n_remove]]
            drop[worst] = True
        alive = alive[~drop]
        it += 1
        comp = None

    n_nodes = len(alive)
    if comp is None or n_nodes < max(conf.graph_min_nodes, 3):
        return GraphVerdict(
            False, 0.0, n_nodes, "too_few_nodes", n_matches=n_matches, kept=alive, iterations=it
        )
    score = (comp.orientation + comp.crossing_free + comp.edge_jaccard) / 3.0
    verdict = GraphVerdict(
        accepted=False,
        score=float(score),
        n_nodes=n_nodes,
        reason="ok",
        n_matches=n_matches,
        kept=alive,
        orientation_agreement=comp.orientation,
        crossing_free=comp.crossing_free,
        edge_jaccard=comp.edge_jaccard,
        iterations=it,
    )
    if n_nodes / n_matches < conf.graph_min_node_ratio:
        verdict.reason = "low_node_ratio"
    elif score < conf.graph_min_score:
        verdict.reason = "low_score"
    else:
        verdict.accepted = True
    return verdict
