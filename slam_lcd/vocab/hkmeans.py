"""Hierarchical k-means tree (DBoW2-style branching k, depth L): the baseline vocabulary.

Top-down: every node's descriptors are split by spherical k-means into at most k children,
for L levels; the leaves are the words (up to k^L). A node with k descriptors or fewer gives
each descriptor its own child; below a leaf reached early the node is repeated as a single
child so all words sit at depth L (the descent cost is unchanged and the tree stays uniform).
"""
from __future__ import annotations

import numpy as np

from .kmeans import spherical_kmeans
from .tree import VocabTree


def build_hkmeans_tree(x: np.ndarray, k: int, depth: int, seed: int = 0,
                       iters: int = 10) -> tuple[VocabTree, np.ndarray]:
    """Returns (tree, leaf of every training descriptor)."""
    if k < 2 or depth < 1:
        raise ValueError(f"hierarchical k-means needs k >= 2 and L >= 1, got k={k}, L={depth}")
    rng = np.random.default_rng(seed)
    x = np.ascontiguousarray(x, dtype=np.float32)
    assign = np.zeros(len(x), dtype=np.int64)
    n_prev = 1
    prev_centres = None
    centres, parents = [], []
    for _ in range(depth):
        order = np.argsort(assign, kind="stable")
        bounds = np.searchsorted(assign[order], np.arange(n_prev + 1))
        lvl_c, lvl_p = [], []
        new_assign = np.empty_like(assign)
        base = 0
        for node in range(n_prev):
            members = order[bounds[node] : bounds[node + 1]]
            if len(members) == 1 and prev_centres is not None:
                lab, c = np.zeros(1, dtype=np.int64), prev_centres[node : node + 1]
            else:
                lab, c = spherical_kmeans(x[members], k, rng, iters)
            lvl_c.append(c)
            lvl_p.append(np.full(len(c), node, dtype=np.int64))
            new_assign[members] = base + lab
            base += len(c)
        prev_centres = np.concatenate(lvl_c)
        centres.append(prev_centres)
        parents.append(np.concatenate(lvl_p))
        assign, n_prev = new_assign, base
    return VocabTree(centres, parents), assign
