"""Which segments of a drawn graph cross another one, without testing all pairs.

Why: graph verification draws each image's triangulation in the other image and asks, per
edge, whether it properly crosses any other edge. Testing all E^2 pairs made this 3/4 of
loop-detection time once candidates had a few hundred matches (~900 edges, ~20 pruning
rounds, two directions, five candidates per keyframe).

How (:func:`crosses_any`, the question verification asks):

0. Sweep and prune, when the boxes overlap little: only segments whose bounding boxes
   overlap can cross. The segments are sorted by the low end of their padded boxes along the
   axis where the boxes overlap least, and each is paired with the later ones whose box starts
   before its own ends there (one ``searchsorted``: the number of such pairs is known before
   any is formed). When there are at most ``_SWEEP_MAX_PAIRS`` per segment (a drawing through
   mostly right matches: short edges; ~32 per segment on the 2-lap demo), those pairs are
   formed, kept when their boxes also overlap on the other axis, and tested. About half the
   time of the passes below on such drawings. Otherwise (long segments across the image: a
   drawing scrambled by wrong matches, where the pairs approach all pairs) the passes below
   settle it in a fraction of the pairs:
1. Few segments (<= 256): every pair, from one index table
   kept for all calls. Below that size the grid's bookkeeping (a few dozen small array
   operations) costs more than the pair tests it avoids; at most 32,640 of them, a constant,
   so the cost per call stated below holds for every size.
2. Each segment is tested against the next 3 segments in the grid order of their mid points
   (E x 3 tests). In a scrambled drawing (a false loop, or the outliers of a true one) long
   segments with nearby mid points nearly always cross, so this settles almost every one.
3. Few segments left unsettled (<= 48): each is tested against all segments (48 x E tests).
4. Many left (a nearly planar drawing, a true loop): a uniform grid (cell side
   ``sqrt(area / E)``, about one segment per cell). Every segment is cut into pieces no longer
   than a cell and registered in the cells its padded piece boxes touch (at most 3 x 3), and
   each unsettled segment is tested against the segments sharing one of its cells. Two
   segments that cross share the cell of their crossing point, so nothing is missed.

Every test is the all-pairs reference's own arithmetic (same float64 products, same strict
sign tests), after a padded bounding-box check, so the answer is the reference's, crossing
for crossing. Cost per call: O(E log E) for the sorts plus the pairs tested: at most
``_SWEEP_MAX_PAIRS`` x E for the sweep, O(E) for a nearly planar drawing through the passes,
O(E) + 48 E for a scrambled one; only a drawing with many unsettled long segments sharing
cells (parallel sheaves, which real matches do not make) costs more, bounded by the
all-pairs count. :func:`crossing_counts` (how many, not whether) tests every pair of
segments sharing a grid cell; it serves the planarity checks in the tests.

One difference from the all-pairs reference, by construction: two segments whose padded
bounding boxes are disjoint are never counted. They cannot cross; the reference could report
them as crossing only through rounding, when four end points lie (almost exactly) on one
line, which needs coordinates that are not small integers (those give exact products).
"""
from __future__ import annotations

import numpy as np

_FIRST_PASS_NEIGHBOURS = 3  # step 2: each segment against this many next ones in mid-point grid order
_DIRECT_MAX_OPEN = 48  # at most this many unsettled segments: test them against all (cheaper than the grid)
_PAIR_CHUNK = 1 << 20  # candidate pairs tested per block (bounds the temporaries)
_ALL_PAIRS_MAX = 256  # up to this many segments crosses_any tests every pair (step 1 of the module note)
# step 0 (the sweep) runs when it forms at most this many pairs per segment: the break-even with
# steps 1-4, measured on the 2-lap demo's 2,038 drawings and scrambled ones
_SWEEP_MAX_PAIRS = 64
_PAIRS: tuple[np.ndarray, np.ndarray] | None = None  # every pair (i < j < _ALL_PAIRS_MAX), ordered by j


def _pairs_below(m: int) -> tuple[np.ndarray, np.ndarray]:
    """Every pair (i < j < m) for m <= _ALL_PAIRS_MAX: a prefix of one table ordered by j (0.5 MB, built once)."""
    global _PAIRS
    if _PAIRS is None:
        j, i = np.tril_indices(_ALL_PAIRS_MAX, -1)  # rows j > columns i, row-major: ordered by j
        _PAIRS = (i, j)
    n = m * (m - 1) // 2
    return _PAIRS[0][:n], _PAIRS[1][:n]


class _Segments:
    """End points, directions, end ids and padded boxes of the segments, as flat arrays (fast gathers)."""

    def __init__(self, points: np.ndarray, edges: np.ndarray):
        p, q = points[edges[:, 0]], points[edges[:, 1]]
        self.p, self.q = p, q
        self.px, self.py, self.qx, self.qy = p[:, 0].copy(), p[:, 1].copy(), q[:, 0].copy(), q[:, 1].copy()
        self.dx, self.dy = self.qx - self.px, self.qy - self.py  # the reference's d = q - p
        self.a, self.b = edges[:, 0].copy(), edges[:, 1].copy()
        self.scale = (float(np.abs(points).max()) + 1.0) if len(points) else 1.0
        tol = 1e-9 * self.scale  # box padding, far above the rounding of end points and pieces
        self.tol = tol
        self.x0, self.x1 = np.minimum(self.px, self.qx) - tol, np.maximum(self.px, self.qx) + tol
        self.y0, self.y1 = np.minimum(self.py, self.qy) - tol, np.maximum(self.py, self.qy) + tol

    def cross(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Do segments ``i`` and ``j`` properly cross? Shared end points never cross.

        Pairs whose padded boxes are disjoint are rejected first; the rest get the same float64
        expressions as the all-pairs reference (sign of the cross products, strict tests).
        """
        box = ((self.x0[i] <= self.x1[j]) & (self.x0[j] <= self.x1[i])
               & (self.y0[i] <= self.y1[j]) & (self.y0[j] <= self.y1[i]))
        ai, bi, aj, bj = self.a[i], self.b[i], self.a[j], self.b[j]
        box &= (ai != aj) & (ai != bj) & (bi != aj) & (bi != bj)
        out = np.zeros(len(i), bool)
        if not box.any():
            return out
        i, j = i[box], j[box]
        pxi, pyi, dxi, dyi = self.px[i], self.py[i], self.dx[i], self.dy[i]
        pxj, pyj, dxj, dyj = self.px[j], self.py[j], self.dx[j], self.dy[j]
        qxj, qyj, qxi, qyi = self.qx[j], self.qy[j], self.qx[i], self.qy[i]
        s_ij = ((dxi * (pyj - pyi) - dyi * (pxj - pxi)) * (dxi * (qyj - pyi) - dyi * (qxj - pxi))) < 0
        s_ji = ((dxj * (pyi - pyj) - dyj * (pxi - pxj)) * (dxj * (qyi - pyj) - dyj * (qxi - pxj))) < 0
        out[box] = s_ij & s_ji
        return out


class _Sweep:
    """Sweep and prune over the segments' padded boxes (step 0 of the module note).

    ``pairs`` is how many pairs overlap on the sweep axis, known before they are formed.
    """

    def __init__(self, segs: _Segments):
        x0, x1, y0, y1 = segs.x0, segs.x1, segs.y0, segs.y1
        # sweep along the axis where the boxes overlap least: fewer pairs
        if (x1 - x0).sum() * (y1.max() - y0.min()) <= (y1 - y0).sum() * (x1.max() - x0.min()):
            lo, hi, lo2, hi2 = x0, x1, y0, y1
        else:
            lo, hi, lo2, hi2 = y0, y1, x0, x1
        self.order = np.argsort(lo, kind="stable")
        m = len(lo)
        self.lo2, self.hi2 = lo2[self.order], hi2[self.order]
        self.first = np.arange(1, m + 1)  # sorted position of each segment's first partner
        # partners: the later segments whose box starts before this one's ends
        self.counts = np.maximum(np.searchsorted(lo[self.order], hi[self.order], side="right") - self.first, 0)
        self.total = np.cumsum(self.counts)
        self.pairs = int(self.total[-1]) if m else 0

    def overlapping_pairs(self):
        """Blocks of segment pairs (i, j), each pair once, whose padded boxes overlap."""
        m, counts, total = len(self.order), self.counts, self.total
        row = 0
        while row < m:
            base = int(total[row - 1]) if row else 0
            stop = max(int(np.searchsorted(total, base + _PAIR_CHUNK, side="right")), row + 1)
            c = counts[row:stop]
            a = np.repeat(np.arange(row, stop), c)
            b = np.arange(len(a)) + np.repeat(self.first[row:stop] - (np.cumsum(c) - c), c)
            keep = (self.lo2[a] <= self.hi2[b]) & (self.lo2[b] <= self.hi2[a])
            yield self.order[a[keep]], self.order[b[keep]]
            row = stop


def _registrations(seg_: _Segments) -> tuple[np.ndarray, np.ndarray]:
    """(cell id, segment) of every grid cell a piece of each segment touches, sorted by cell."""
    p, q = seg_.p, seg_.q
    m = len(p)
    lo = np.minimum(p, q).min(0)
    hi = np.maximum(p, q).max(0)
    extent = hi - lo
    tol, scale = seg_.tol, seg_.scale
    area = float(extent[0] * extent[1])
    cell = np.sqrt(area / m) if area > 0 else float(extent.max()) / m
    cell = max(cell, 1e-6 * scale)
    n_cells = np.floor(extent / cell).astype(np.int64) + 1
    length = np.linalg.norm(q - p, axis=1)
    pieces = np.maximum(1, np.ceil(length / cell)).astype(np.int64)
    seg = np.repeat(np.arange(m), pieces)
    first = np.cumsum(pieces) - pieces
    k = np.arange(len(seg)) - first[seg]
    t0 = (k / pieces[seg])[:, None]
    t1 = ((k + 1) / pieces[seg])[:, None]
    d = q - p
    a = p[seg] + t0 * d[seg]
    b = p[seg] + t1 * d[seg]
    c_lo = np.floor((np.minimum(a, b) - tol - lo) / cell).astype(np.int64)
    c_hi = np.floor((np.maximum(a, b) + tol - lo) / cell).astype(np.int64)
    c_lo = np.clip(c_lo, 0, n_cells - 1)
    c_hi = np.clip(c_hi, 0, n_cells - 1)
    nx = c_hi[:, 0] - c_lo[:, 0] + 1
    ny = c_hi[:, 1] - c_lo[:, 1] + 1
    count = nx * ny
    owner = np.repeat(np.arange(len(seg)), count)
    r = np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)
    cx = c_lo[owner, 0] + r % nx[owner]
    cy = c_lo[owner, 1] + r // nx[owner]
    cell_id = cx * n_cells[1] + cy
    segment = seg[owner]
    # one registration per (cell, segment): pieces of one segment often share a cell
    code = _sorted_unique(cell_id * m + segment)
    return code // m, code % m


def _group_bounds(cell_id: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end (exclusive) of each registration's cell group in the sorted registrations."""
    n = len(cell_id)
    new = np.ones(n, bool)
    new[1:] = cell_id[1:] != cell_id[:-1]
    starts = np.flatnonzero(new)
    sizes = np.diff(np.append(starts, n))
    group = np.cumsum(new) - 1
    return starts[group], (starts + sizes)[group]


def _expand(rows: np.ndarray, begin: np.ndarray, end: np.ndarray):
    """Blocks of (row, column) pairs with column in [begin, end) per row, at most ~_PAIR_CHUNK each."""
    counts = np.maximum(end - begin, 0)
    total = np.cumsum(counts)
    start_row = 0
    while start_row < len(rows):
        base = total[start_row - 1] if start_row else 0
        stop = int(np.searchsorted(total, base + _PAIR_CHUNK, side="right"))
        stop = max(stop, start_row + 1)
        c = counts[start_row:stop]
        a = np.repeat(rows[start_row:stop], c)
        offs = np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c)
        b = np.repeat(begin[start_row:stop], c) + offs
        yield a, b
        start_row = stop


def _candidate_pairs(cell_id: np.ndarray, segment: np.ndarray, rows: np.ndarray, begin: np.ndarray,
                     end: np.ndarray, m: int):
    """Distinct segment pairs (i < j) from registration pairs, in blocks."""
    for a, b in _expand(rows, begin, end):
        i, j = segment[a], segment[b]
        keep = i != j
        lo, hi = np.minimum(i[keep], j[keep]), np.maximum(i[keep], j[keep])
        code = _sorted_unique(lo * m + hi)
        yield code // m, code % m


def crossing_counts(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """For each edge (a segment between ``points``), how many other edges it properly crosses.

    Same counts as testing all pairs (see the module note on disjoint boxes); every pair of
    segments sharing a grid cell is tested once.
    """
    points = np.asarray(points, dtype=np.float64)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    m = len(edges)
    counts = np.zeros(m, np.int64)
    if m < 2:
        return counts
    segs = _Segments(points, edges)
    cell_id, segment = _registrations(segs)
    _, g_end = _group_bounds(cell_id)
    rows = np.arange(len(cell_id))
    # a pair may share several cells: collect the pairs of every cell, then count each once
    codes = [i * m + j for i, j in _candidate_pairs(cell_id, segment, rows, rows + 1, g_end, m)]
    if not codes:
        return counts
    code = _sorted_unique(np.concatenate(codes))
    i, j = code // m, code % m
    hit = segs.cross(i, j)
    counts += np.bincount(i[hit], minlength=m)
    counts += np.bincount(j[hit], minlength=m)
    return counts


def _sorted_unique(x: np.ndarray) -> np.ndarray:
    x = np.sort(x)
    if len(x) > 1:
        x = x[np.concatenate([[True], x[1:] != x[:-1]])]
    return x


def _test_and_mark(segs: _Segments, i: np.ndarray, j: np.ndarray, crossed: np.ndarray) -> None:
    hit = segs.cross(i, j)
    crossed[i[hit]] = True
    crossed[j[hit]] = True


def crosses_any(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """For each edge, does it properly cross at least one other edge? Bool (E,).

    Equal to ``crossing_counts(points, edges) > 0`` but stops testing a segment's pairs once
    it is known to cross (see the module note).
    """
    points = np.asarray(points, dtype=np.float64)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    m = len(edges)
    crossed = np.zeros(m, bool)
    if m < 2:
        return crossed
    segs = _Segments(points, edges)
    sweep = _Sweep(segs)
    if sweep.pairs <= _SWEEP_MAX_PAIRS * m:  # step 0: the boxes overlap little
        for i, j in sweep.overlapping_pairs():
            _test_and_mark(segs, i, j, crossed)
        return crossed
    if m <= _ALL_PAIRS_MAX:  # step 1: every pair
        _test_and_mark(segs, *_pairs_below(m), crossed)
        return crossed
    # step 2: each segment against the next few in the grid order of the mid points
    mx, my = 0.5 * (segs.px + segs.qx), 0.5 * (segs.py + segs.qy)
    x0, y0 = mx.min(), my.min()
    w, h = mx.max() - x0, my.max() - y0
    cell = np.sqrt(w * h / m) if w * h > 0 else max(max(w, h) / m, 1e-9)
    key = np.floor((my - y0) / cell) * (np.floor(w / cell) + 1) + np.floor((mx - x0) / cell)
    order = np.argsort(key, kind="stable")
    k = min(_FIRST_PASS_NEIGHBOURS, m - 1)
    i = np.repeat(order[:-1], k)
    pos = np.repeat(np.arange(m - 1), k) + np.tile(np.arange(1, k + 1), m - 1)
    ok = pos < m
    _test_and_mark(segs, i[ok], order[pos[ok]], crossed)
    open_seg = np.flatnonzero(~crossed)
    if len(open_seg) == 0:
        return crossed
    if len(open_seg) <= _DIRECT_MAX_OPEN:
        # step 3, few unsettled segments: each against every other segment
        rows = np.repeat(open_seg, m)
        cols = np.tile(np.arange(m), len(open_seg))
        keep = rows != cols
        _test_and_mark(segs, rows[keep], cols[keep], crossed)
        return crossed
    # step 4, many unsettled (a nearly planar drawing): every cell-mate of their grid registrations
    cell_id, segment = _registrations(segs)
    g_start, g_end = _group_bounds(cell_id)
    open_rows = np.flatnonzero(~crossed[segment])
    for i, j in _candidate_pairs(cell_id, segment, open_rows, g_start[open_rows], g_end[open_rows], m):
        undecided = ~(crossed[i] & crossed[j])
        _test_and_mark(segs, i[undecided], j[undecided], crossed)
    return crossed
