"""A vocabulary tree with uniform depth and a vectorised greedy descent.

Nodes are stored level by level (level 0 is the root, the last level holds the words).
Each level's nodes are sorted by parent so the children of a node are contiguous. For the
descent each level is also kept in a padded ``(n_parents, B, D)`` layout: all descriptors
step one level down together, either by one dense product against every node of the level
(small levels) or by gathering their current node's B children and a batched product
(large levels). Both trees of this package (DP and hierarchical k-means) use this class.
"""
from __future__ import annotations

import numpy as np

from .descriptors import group_sums, normalise_rows

_CHUNK = 64  # descriptors per gathered block: 64 x B x D floats stay in cache
_DENSE_FACTOR = 16  # a level with at most this many nodes per child slot is scored densely


class VocabTree:
    """Levels of unit-vector centres; ``parents[l][i]`` is the parent (in level l-1) of node i of level l."""

    def __init__(self, centres: list[np.ndarray], parents: list[np.ndarray]):
        if len(centres) != len(parents) or not centres:
            raise ValueError("a tree needs at least one level of centres with parents")
        self.centres = [np.ascontiguousarray(c, dtype=np.float32) for c in centres]
        self.parents = [np.asarray(p, dtype=np.int64) for p in parents]
        n_prev = 1
        for lvl, (c, p) in enumerate(zip(self.centres, self.parents, strict=True), start=1):
            if c.ndim != 2 or len(c) != len(p):
                raise ValueError(f"level {lvl}: {len(c)} centres but {len(p)} parents")
            if len(p) and (p.min() < 0 or p.max() >= n_prev or np.any(np.diff(p) < 0)):
                raise ValueError(f"level {lvl}: parents must be sorted indices into the previous level")
            if len(np.unique(p)) != n_prev:
                raise ValueError(f"level {lvl}: every node of level {lvl - 1} needs a child")
            n_prev = len(c)
        self.dim = self.centres[0].shape[1]
        self._build_padded()

    # ------------------------------------------------------------------ layout
    def _build_padded(self) -> None:
        self._padded = []  # per level: (child_centres (P,B,D), child_index (P,B), valid (P,B))
        for lvl, (c, p) in enumerate(zip(self.centres, self.parents, strict=True)):
            n_par = 1 if lvl == 0 else len(self.centres[lvl - 1])
            counts = np.bincount(p, minlength=n_par)
            b = int(counts.max())
            start = np.concatenate([[0], np.cumsum(counts)[:-1]])
            slot = np.arange(len(p)) - start[p]
            index = np.full((n_par, b), -1, dtype=np.int64)
            index[p, slot] = np.arange(len(p))
            cc = np.zeros((n_par, b, self.dim), dtype=np.float32)
            cc[p, slot] = c
            self._padded.append((cc, index, index >= 0))

    @property
    def depth(self) -> int:
        return len(self.centres)

    @property
    def n_words(self) -> int:
        return len(self.centres[-1])

    @property
    def words(self) -> np.ndarray:
        return self.centres[-1]

    def branching(self) -> list[np.ndarray]:
        """Children per node, for each level that has children (root first)."""
        out = []
        for lvl, p in enumerate(self.parents):
            n_par = 1 if lvl == 0 else len(self.centres[lvl - 1])
            out.append(np.bincount(p, minlength=n_par))
        return out

    # ------------------------------------------------------------- quantising
    def quantize(self, x: np.ndarray) -> np.ndarray:
        """Greedy descent: at every level move to the child with the largest dot product."""
        x = np.ascontiguousarray(x, dtype=np.float32)
        n = len(x)
        cur = np.zeros(n, dtype=np.int64)
        if n == 0:
            return cur
        rows = np.arange(n)
        for lvl, (cc, index, _valid) in enumerate(self._padded):
            n_nodes, b = len(self.centres[lvl]), cc.shape[1]
            if n_nodes <= _DENSE_FACTOR * b:
                # small level: one dense product, then look up each descriptor's children
                full = x @ self.centres[lvl].T  # (n, n_nodes)
                kids = index[cur]  # (n, b)
                s = full[rows[:, None], np.maximum(kids, 0)]
            else:
                # gather each descriptor's children in cache-sized chunks (about 2x faster than one big gather)
                s = np.empty((n, b, 1), dtype=np.float32)
                for i in range(0, n, _CHUNK):
                    j = min(n, i + _CHUNK)
                    np.matmul(np.take(cc, cur[i:j], axis=0), x[i:j, :, None], out=s[i:j])
                s = s[:, :, 0]
                kids = index[cur]
            s = np.where(kids >= 0, s, -np.inf)
            cur = kids[rows, s.argmax(axis=1)]
        return cur

    def quantize_exhaustive(self, x: np.ndarray, chunk: int = 256) -> np.ndarray:
        """Brute force nearest word (largest dot product with every leaf); the reference for greedy."""
        x = np.ascontiguousarray(x, dtype=np.float32)
        out = np.empty(len(x), dtype=np.int64)
        w = self.words
        for i in range(0, len(x), chunk):
            out[i : i + chunk] = (x[i : i + chunk] @ w.T).argmax(axis=1)
        return out


def parent_centres(child_centres: np.ndarray, labels: np.ndarray, n_parents: int, weights=None) -> np.ndarray:
    """Normalised (weighted) mean of each parent's children."""
    return normalise_rows(group_sums(child_centres, labels, n_parents, weights))


def tree_from_bottom_up(words: np.ndarray, labels_per_level: list[np.ndarray], weights=None):
    """Assemble a :class:`VocabTree` from parent labels found bottom-up.

    ``labels_per_level[0]`` maps words to level-1 parents, the next maps those to their
    parents, ..., the last maps to a single root (all zeros). Returns ``(tree, word_order)``
    where ``word_order[k]`` is the input word stored as leaf ``k`` (leaves are re-sorted so
    siblings are contiguous).
    """
    # centres of every level bottom-up
    cents = [normalise_rows(words)]
    w = np.ones(len(words), np.float32) if weights is None else np.asarray(weights, np.float32)
    ws = [w]
    for lab in labels_per_level[:-1]:
        n_par = int(lab.max()) + 1
        cents.append(parent_centres(cents[-1], lab, n_par, ws[-1]))
        ws.append(np.bincount(lab, weights=ws[-1], minlength=n_par).astype(np.float32))
    # top-down ordering: sort each level by its (already ordered) parent
    n_levels = len(labels_per_level)
    # orders[k]: nodes of bottom-up level k in stored order (every level's is set below, top first)
    orders: list[np.ndarray] = [np.empty(0, np.int64)] * n_levels
    top_lab = labels_per_level[-1]
    orders[n_levels - 1] = np.argsort(top_lab, kind="stable")
    for k in range(n_levels - 2, -1, -1):
        par_rank = np.empty(len(orders[k + 1]), dtype=np.int64)
        par_rank[orders[k + 1]] = np.arange(len(orders[k + 1]))
        orders[k] = np.lexsort((np.arange(len(labels_per_level[k])), par_rank[labels_per_level[k]]))
    centres, parents = [], []
    for k in range(n_levels - 1, -1, -1):  # from just below the root down to the words
        order = orders[k]
        centres.append(cents[k][order])
        if k == n_levels - 1:
            parents.append(np.zeros(len(order), dtype=np.int64))
        else:
            par_rank = np.empty(len(orders[k + 1]), dtype=np.int64)
            par_rank[orders[k + 1]] = np.arange(len(orders[k + 1]))
            parents.append(par_rank[labels_per_level[k][order]])
    return VocabTree(centres, parents), orders[0]
