"""A fixed budget of matches per loop candidate: which one-to-one matches go to verification.

Why: graph pruning, RANSAC and PnP cost grows with the number of matches (graph: ~20 rounds
of two triangulations and two crossing tests), and a revisit with a textured view can have
700 mutual matches where 300 decide the verdict as well. Capping the matches bounds what one
candidate costs, whatever the images.

Which ones: the best by descriptor distance, taken round-robin over a coarse grid of the
query image (``spread``): first the best match of every occupied cell, then the second best
of every cell, and so on (ties by distance). Taking the globally best matches alone tends to
gather them on the most distinctive texture patch; spreading them keeps the graph, the
essential matrix and the pose conditioned over the whole overlap.
"""
from __future__ import annotations

import numpy as np


def select_matches(
    matches: np.ndarray,
    distances: np.ndarray,
    kpts_q: np.ndarray,
    budget: int,
    image_size: tuple[int, int] | None = None,
    spread_cells: int = 0,
) -> np.ndarray:
    """Row indices of ``matches`` to keep (sorted), at most ``budget`` of them.

    ``distances`` (M,) are the matches' descriptor distances, ``kpts_q`` the query keypoints
    (pixels), ``image_size`` (width, height) the query image. ``spread_cells`` > 0: round-robin
    over a ``spread_cells x spread_cells`` grid (see the module note); 0: the globally best.
    ``budget <= 0`` keeps everything.
    """
    m = len(matches)
    if budget <= 0 or m <= budget:
        return np.arange(m)
    distances = np.asarray(distances, dtype=np.float64)
    if spread_cells <= 0:
        order = np.argsort(distances, kind="stable")
        return np.sort(order[:budget])
    pts = np.asarray(kpts_q, dtype=np.float64)[matches[:, 0]]
    if image_size is not None:
        w, h = float(image_size[0]), float(image_size[1])
        lo = np.zeros(2)
    else:
        lo = pts.min(0)
        w, h = np.maximum(pts.max(0) - lo, 1e-9)
    cx = np.clip(((pts[:, 0] - lo[0]) / max(w, 1e-9) * spread_cells).astype(np.int64), 0, spread_cells - 1)
    cy = np.clip(((pts[:, 1] - lo[1]) / max(h, 1e-9) * spread_cells).astype(np.int64), 0, spread_cells - 1)
    cell = cy * spread_cells + cx
    by_dist = np.argsort(distances, kind="stable")
    # rank of each match inside its cell (0 = best of the cell)
    by_cell = by_dist[np.argsort(cell[by_dist], kind="stable")]
    sorted_cells = cell[by_cell]
    starts = np.flatnonzero(np.concatenate([[True], sorted_cells[1:] != sorted_cells[:-1]]))
    sizes = np.diff(np.append(starts, m))
    rank = np.empty(m, np.int64)
    rank[by_cell] = np.arange(m) - np.repeat(starts, sizes)
    # by rank first, then by distance (the stable sort keeps the distance order within a rank)
    order = by_dist[np.argsort(rank[by_dist], kind="stable")]
    return np.sort(order[:budget])
