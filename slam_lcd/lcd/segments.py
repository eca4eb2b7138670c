"""Which segments of a drawn graph cross another one, without testing all pairs.

Why: graph verification draws each image's triangulation in the other image and asks, per
edge, whether it properly crosses any other edge. Testing all E^2 pairs made this 3/4 of
loop-detection time once candidates had a few hundred matches (~900 edges, ~20 pruning
rounds, two directions, five candidates per keyframe).

How (sweep and prune): only segments whose bounding boxes overlap can cross. The segments
are sorted by the low end of their boxes along one axis (the one along which the boxes
overlap least); each is paired with the segments that start before its box ends there (a
``searchsorted`` per segment, the pairs expanded in one array), those pairs are kept when
their boxes also overlap on the other axis, and only they get the crossing test. A
triangulation drawn through mostly right matches has short edges: ~1,800 pairs of ~60,000
for 350 edges, so the cost per call is O(E log E) plus the overlapping pairs; only long
segments over the whole image (a drawing scrambled by wrong matches) approach all pairs,
which are then tested in blocks of at most ``_PAIR_CHUNK``.

Every test is the all-pairs reference's own arithmetic (same float64 products, same strict
sign tests), so the answer is the reference's, crossing for crossing. One difference from
the all-pairs reference, by construction: two segments whose padded bounding boxes are
disjoint are never counted. They cannot cross; the reference could report them as crossing
only through rounding, when four end points lie (almost exactly) on one line, which needs
coordinates that are not small integers (those give exact products).

(This replaced a uniform grid with a neighbour pass and a direct pass, 2x slower on the
2-lap demo's drawings and twice the code; docs/lcd.md.)
"""
from __future__ import annotations

import numpy as np

_PAIR_CHUNK = 1 << 20  # candidate pairs expanded and tested per block (bounds the temporaries)


class _Segments:
    """End points, directions, end ids and padded boxes of the segments, as flat arrays (fast gathers)."""

    def __init__(self, points: np.ndarray, edges: np.ndarray):
        p, q = points[edges[:, 0]], points[edges[:, 1]]
        self.px, self.py, self.qx, self.qy = p[:, 0].copy(), p[:, 1].copy(), q[:, 0].copy(), q[:, 1].copy()
        self.dx, self.dy = self.qx - self.px, self.qy - self.py  # the reference's d = q - p
        self.a, self.b = edges[:, 0].copy(), edges[:, 1].copy()
        scale = (float(np.abs(points).max()) + 1.0) if len(points) else 1.0
        tol = 1e-9 * scale  # box padding, far above the rounding of the end points
        self.x0, self.x1 = np.minimum(self.px, self.qx) - tol, np.maximum(self.px, self.qx) + tol
        self.y0, self.y1 = np.minimum(self.py, self.qy) - tol, np.maximum(self.py, self.qy) + tol

    def cross(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        """Do segments ``i`` and ``j`` (pairs whose boxes overlap) properly cross? Shared end points never cross.

        The same float64 expressions as the all-pairs reference: the sign of the cross products, strict tests.
        """
        ai, bi, aj, bj = self.a[i], self.b[i], self.a[j], self.b[j]
        apart = (ai != aj) & (ai != bj) & (bi != aj) & (bi != bj)
        out = np.zeros(len(i), bool)
        if not apart.any():
            return out
        i, j = i[apart], j[apart]
        pxi, pyi, dxi, dyi = self.px[i], self.py[i], self.dx[i], self.dy[i]
        pxj, pyj, dxj, dyj = self.px[j], self.py[j], self.dx[j], self.dy[j]
        qxj, qyj, qxi, qyi = self.qx[j], self.qy[j], self.qx[i], self.qy[i]
        s_ij = ((dxi * (pyj - pyi) - dyi * (pxj - pxi)) * (dxi * (qyj - pyi) - dyi * (qxj - pxi))) < 0
        s_ji = ((dxj * (pyi - pyj) - dyj * (pxi - pxj)) * (dxj * (qyi - pyj) - dyj * (qxi - pxj))) < 0
        out[apart] = s_ij & s_ji
        return out

    def overlapping_pairs(self):
        """Blocks of segment pairs (i, j), each pair once, whose padded boxes overlap (sweep and prune)."""
        m = len(self.a)
        x0, x1, y0, y1 = self.x0, self.x1, self.y0, self.y1
        # sweep along the axis where the boxes overlap least: fewer pairs to expand
        if (x1 - x0).sum() * (y1.max() - y0.min()) <= (y1 - y0).sum() * (x1.max() - x0.min()):
            lo, hi, lo2, hi2 = x0, x1, y0, y1
        else:
            lo, hi, lo2, hi2 = y0, y1, x0, x1
        order = np.argsort(lo, kind="stable")
        lo_s, hi_s, lo2_s, hi2_s = lo[order], hi[order], lo2[order], hi2[order]
        first = np.arange(1, m + 1)  # sorted position of each segment's first partner
        # partners: the later segments whose box starts before this one's ends (they overlap on the sweep axis)
        counts = np.maximum(np.searchsorted(lo_s, hi_s, side="right") - first, 0)
        total = np.cumsum(counts)
        row = 0
        while row < m:
            base = int(total[row - 1]) if row else 0
            stop = max(int(np.searchsorted(total, base + _PAIR_CHUNK, side="right")), row + 1)
            c = counts[row:stop]
            a = np.repeat(np.arange(row, stop), c)
            b = np.arange(len(a)) + np.repeat(first[row:stop] - (np.cumsum(c) - c), c)
            keep = (lo2_s[a] <= hi2_s[b]) & (lo2_s[b] <= hi2_s[a])
            yield order[a[keep]], order[b[keep]]
            row = stop


def _segments(points, edges) -> tuple[_Segments | None, int]:
    points = np.asarray(points, dtype=np.float64)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    return (_Segments(points, edges) if len(edges) >= 2 else None), len(edges)


def crossing_counts(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """For each edge (a segment between ``points``), how many other edges it properly crosses.

    Same counts as testing all pairs (see the module note on disjoint boxes).
    """
    segs, m = _segments(points, edges)
    counts = np.zeros(m, np.int64)
    if segs is None:
        return counts
    for i, j in segs.overlapping_pairs():
        hit = segs.cross(i, j)
        counts += np.bincount(i[hit], minlength=m) + np.bincount(j[hit], minlength=m)
    return counts


def crosses_any(points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """For each edge, does it properly cross at least one other edge? Bool (E,); ``crossing_counts(...) > 0``."""
    segs, m = _segments(points, edges)
    crossed = np.zeros(m, bool)
    if segs is None:
        return crossed
    for i, j in segs.overlapping_pairs():
        hit = segs.cross(i, j)
        crossed[i[hit]] = True
        crossed[j[hit]] = True
    return crossed
