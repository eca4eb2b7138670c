"""Is a row the best row of its own best column? The mutual check of nearest-neighbour matching.

Mutual matching asks, for each row ``i`` with best column ``j``, whether ``i`` is also the
(first) best row of column ``j``: ``s.argmin(axis=0)[j] == i`` (or ``argmax`` for
similarities). numpy reduces a column arg-extreme by walking the matrix with a stride, ~5x
slower than a column *extreme* (a contiguous reduction) at 1000 x 1000. The same answer comes
from the extreme: row ``i`` passes when its value equals its column's extreme, unless an
earlier row ties that extreme. Ties are rare (duplicate descriptors): one count over the
matrix says whether any column reaches its extreme twice; only then are the tied columns
resolved by an arg-extreme of their own. Shared by descriptor matching (distances) and the
vocabulary's word growth (similarities).
"""
from __future__ import annotations

import numpy as np


def first_in_column(s: np.ndarray, cols: np.ndarray, vals: np.ndarray, largest: bool) -> np.ndarray:
    """``(s.argmax if largest else s.argmin)(axis=0)[cols] == arange(len(s))`` for ``vals = s[arange, cols]``."""
    col_best = s.max(axis=0) if largest else s.min(axis=0)
    keep = vals == col_best[cols]
    if keep.any() and np.count_nonzero(s == col_best) > s.shape[1]:  # some column's extreme is reached twice
        tied_cols = np.unique(cols[keep])
        ties = (s[:, tied_cols] == col_best[tied_cols]).sum(axis=0) > 1
        if ties.any():
            tied = tied_cols[ties]
            sub = s[:, tied]
            first = sub.argmax(axis=0) if largest else sub.argmin(axis=0)
            rows = np.flatnonzero(keep & np.isin(cols, tied))
            keep[rows] = first[np.searchsorted(tied, cols[rows])] == rows
    return keep
