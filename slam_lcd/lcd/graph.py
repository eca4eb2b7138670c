"""Graph verification of a loop candidate (Yue et al. 2019, §III-E, completed here).

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

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import Delaunay, QhullError

from .config import LcdConfig
from .segments import crosses_any, crossing_counts


@dataclass
class GraphVerdict:
    """Outcome of graph verification; ``reason`` is 'ok' when accepted, else why not."""

    accepted: bool
    score: float  # structural agreement of the final graphs, 0..1
    n_nodes: int  # nodes surviving the pruning
    reason: str
    n_matches: int = 0  # one-to-one matches given
    kept: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # rows of `matches` that survived
    orientation_agreement: float = 0.0
    crossing_free: float = 0.0
    edge_jaccard: float = 0.0
    iterations: int = 0
    stopped_early: bool = False  # pruning stopped once the rejection was certain (``lcd.graph_early_exit``)

    def evidence(self) -> dict:
        return {
            "graph_accepted": self.accepted,
            "graph_score": round(float(self.score), 4),
            "graph_nodes": int(self.n_nodes),
            "graph_matches": int(self.n_matches),
            "graph_orientation": round(float(self.orientation_agreement), 4),
            "graph_crossing_free": round(float(self.crossing_free), 4),
            "graph_edge_jaccard": round(float(self.edge_jaccard), 4),
            "graph_iterations": int(self.iterations),
            "graph_reason": self.reason,
        }


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
    """Distinct undirected edges (a < b) of the triangles, sorted by (a, b)."""
    if len(tri) == 0:
        return np.zeros((0, 2), np.int64)
    nxt = tri[:, [1, 2, 0]]  # the three sides (0, 1), (1, 2), (2, 0) of every triangle
    lo, hi = np.minimum(tri, nxt).ravel(), np.maximum(tri, nxt).ravel()
    n = int(hi.max()) + 1
    code = np.sort(lo * n + hi)  # integer codes sort like the rows (a, b)
    # drop repeats by hand: np.unique hashes first, 4x slower on these few hundred codes
    code = code[np.concatenate(([True], code[1:] != code[:-1]))]
    return np.stack([code // n, code % n], axis=1)


def _cross2(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _signed_area2(pts: np.ndarray, tri: np.ndarray) -> np.ndarray:
    a, b, c = pts[tri[:, 0]], pts[tri[:, 1]], pts[tri[:, 2]]
    return _cross2(b - a, c - a)


def crossing_edges(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """For each edge (drawn as a segment between ``points``), how many other edges it properly crosses.

    Edges sharing an end point never count as crossing. Grid broad phase
    (:mod:`slam_lcd.lcd.segments`), the same counts as testing all pairs.
    """
    return crossing_counts(points, edges)


def _edge_codes(edges: np.ndarray, n: int) -> np.ndarray:
    """Sorted integer code ``a * n + b`` of each undirected edge (a < b): a sparse adjacency."""
    return np.sort(edges[:, 0] * n + edges[:, 1]) if len(edges) else np.zeros(0, np.int64)


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
    flips: np.ndarray = np.zeros(n)  # float: bincount with weights (numpy's stub says int)
    tri_count = np.zeros(n)
    if len(tri):
        s_src = np.sign(_signed_area2(src, tri))
        s_dst = np.sign(_signed_area2(dst, tri))
        flipped = (s_src != s_dst).astype(np.float64)
        corners = tri.T.ravel()  # counts of 0/1 values: exact whatever the summation order
        flips = np.bincount(corners, np.tile(flipped, 3), minlength=n)
        tri_count = np.bincount(corners, minlength=n).astype(np.float64)
        orient = 1.0 - float(flipped.mean())
    else:
        orient = 0.0
    crosses: np.ndarray = np.zeros(n)  # float: bincount with weights
    edge_count = np.zeros(n)
    if len(edges):
        c = crosses_any(dst, edges).astype(np.float64)
        ends = edges.T.ravel()
        crosses = np.bincount(ends, np.tile(c, 2), minlength=n)
        edge_count = np.bincount(ends, minlength=n).astype(np.float64)
        free = 1.0 - float(c.mean())
    else:
        free = 0.0
    flip_frac = np.divide(flips, tri_count, out=np.zeros(n), where=tri_count > 0)
    cross_frac = np.divide(crosses, edge_count, out=np.zeros(n), where=edge_count > 0)
    return flip_frac, cross_frac, tri_count > 0, orient, free


def knn_overlap(pq: np.ndarray, pm: np.ndarray, k: int) -> np.ndarray:
    """Per node: share of its ``k`` nearest matched neighbours in one image that are also among its ``k`` nearest
    in the other.

    Symmetric in the two images. Unlike the neighbours of a Delaunay graph, which change
    wherever four points are nearly cocircular (any perspective change flips such edges),
    a node's nearest neighbours survive a moderate viewpoint change; matches scattered by
    aliasing share almost none.
    """
    n = len(pq)
    k = min(int(k), n - 1)
    if k < 1:
        return np.zeros(n)
    from scipy.spatial import cKDTree

    a = cKDTree(pq).query(pq, k + 1)[1][:, 1:]
    b = cKDTree(pm).query(pm, k + 1)[1][:, 1:]
    rows = np.repeat(np.arange(n), k)
    code_a = np.sort(rows * n + a.ravel())
    code_b = rows * n + b.ravel()
    shared = np.isin(code_b, code_a, assume_unique=False)
    return np.bincount(rows, shared.astype(np.float64), minlength=n) / k


def compare_graphs(pq: np.ndarray, pm: np.ndarray, max_edge_factor: float, knn: int = 0) -> _Comparison:
    """Build a graph on each side, carry it to the other side and score every node.

    ``knn`` > 0: the neighbourhood term of a node's violation is its k-nearest-neighbour
    overlap (:func:`knn_overlap`) instead of the Jaccard overlap of its Delaunay neighbours.
    """
    n = len(pq)
    tri_q, e_q = planar_graph(pq, max_edge_factor)
    tri_m, e_m = planar_graph(pm, max_edge_factor)
    fq, cq, in_q, oq, xq = _directional(pq, pm, tri_q, e_q, n)
    fm, cm, in_m, om, xm = _directional(pm, pq, tri_m, e_m, n)
    # per-node neighbour-set Jaccard from sorted edge codes (no n x n adjacency)
    common = np.intersect1d(_edge_codes(e_q, n), _edge_codes(e_m, n), assume_unique=True)
    inter = np.bincount(np.concatenate([common // n, common % n]), minlength=n)
    deg_q = np.bincount(e_q.ravel(), minlength=n)
    deg_m = np.bincount(e_m.ravel(), minlength=n)
    union = deg_q + deg_m - inter
    jac = np.divide(inter, union, out=np.zeros(n), where=union > 0)
    edge_jac = float(inter.sum() / union.sum()) if union.sum() else 0.0
    neighbours = knn_overlap(pq, pm, knn) if knn > 0 else jac
    badness = (0.5 * (fq + fm) + 0.5 * (cq + cm) + (1.0 - neighbours)) / 3.0
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
    min_nodes = max(conf.graph_min_nodes, 3)

    it = 0
    comp = None
    while True:
        if len(alive) < min_nodes:
            break
        # pruning only removes nodes: below the node ratio the candidate is rejected whatever follows
        if conf.graph_early_exit and len(alive) / n_matches < conf.graph_min_node_ratio:
            return GraphVerdict(False, 0.0, len(alive), "low_node_ratio", n_matches=n_matches, kept=alive,
                                iterations=it, stopped_early=True)
        comp = compare_graphs(pq_all[alive], pm_all[alive], conf.graph_max_edge_factor, conf.graph_knn)
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
    if comp is None or n_nodes < min_nodes:
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
