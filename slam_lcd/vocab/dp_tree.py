"""Word tree by Dirichlet-process mixtures, built bottom-up level by level to a single root.

At each level the current nodes (word centres first) are grouped into parents by a
variational Dirichlet-process Gaussian mixture (scikit-learn ``BayesianGaussianMixture``
with a stick-breaking prior): the mixture starts with ``dp_truncation`` components and the
prior switches off the ones the data do not support, so the number of parents, hence the
branching factor, is inferred rather than chosen. To keep this tractable on 10^4–10^5 words
the centres are first projected by PCA (``dp_pca_dims``) and cut into spatially coherent
blocks of at most ``dp_block_size`` nodes (recursive median split along the principal axis);
one mixture is fitted per block. A parent whose children exceed ``max_branching`` is split by
k-means (this bounds the descent cost). Parent centres are the count-weighted normalised mean
of their children. The loop stops when a level has at most ``max_branching`` nodes: they
become the children of the root.
"""
from __future__ import annotations

import warnings

import numpy as np

from .descriptors import nearest_by_dot
from .kmeans import spherical_kmeans
from .tree import VocabTree, parent_centres, tree_from_bottom_up


def _pca(x: np.ndarray, dims: int) -> np.ndarray:
    if dims <= 0 or dims >= x.shape[1]:
        return x.astype(np.float64)
    xc = x - x.mean(axis=0)
    _, _, vt = np.linalg.svd(xc[:: max(1, len(xc) // 20000)], full_matrices=False)
    return xc @ vt[:dims].T


def _blocks(z: np.ndarray, size: int) -> list[np.ndarray]:
    """Split row indices into spatially coherent blocks of at most ``size`` (median cuts on the main axis)."""
    out, stack = [], [np.arange(len(z))]
    while stack:
        idx = stack.pop()
        if len(idx) <= size:
            out.append(idx)
            continue
        p = z[idx] - z[idx].mean(axis=0)
        # principal axis by a few power iterations (cheaper than an SVD per split)
        v = p[np.argmax((p * p).sum(1))].copy()
        for _ in range(8):
            v = p.T @ (p @ v)
            v /= max(np.linalg.norm(v), 1e-12)
        proj = p @ v
        order = np.argsort(proj, kind="stable")
        half = len(idx) // 2
        stack.append(idx[order[:half]])
        stack.append(idx[order[half:]])
    return out


def _dp_block_labels(z: np.ndarray, conf, seed: int) -> np.ndarray:
    from sklearn.mixture import BayesianGaussianMixture

    n = len(z)
    if n <= 2:
        return np.zeros(n, dtype=np.int64)
    k = max(1, min(conf.dp_truncation, n // 4))  # never above n/4: every level shrinks
    model = BayesianGaussianMixture(
        n_components=k,
        covariance_type="spherical",
        weight_concentration_prior_type="dirichlet_process",
        weight_concentration_prior=conf.dp_concentration,
        max_iter=conf.dp_max_iter,
        init_params="k-means++",
        random_state=seed,
        tol=1e-3,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # ConvergenceWarning at max_iter is expected and harmless
        labels = model.fit(z).predict(z)
    _, labels = np.unique(labels, return_inverse=True)
    return labels.astype(np.int64)


def cap_branching(x: np.ndarray, lab: np.ndarray, max_branching: int, rng: np.random.Generator) -> np.ndarray:
    """Split every group larger than ``max_branching`` (k-means, then even cuts if k-means is lopsided)."""
    lab = lab.copy()
    while True:
        sizes = np.bincount(lab)
        wide = np.flatnonzero(sizes > max_branching)
        if not len(wide):
            return lab
        for p in wide:
            members = np.flatnonzero(lab == p)
            parts = int(np.ceil(len(members) / max_branching))
            sub, _ = spherical_kmeans(x[members], parts, rng)
            if np.bincount(sub).max() >= len(members):  # k-means could not split: cut evenly
                sub = np.arange(len(members)) % parts
            top = lab.max()
            lab[members[sub > 0]] = top + sub[sub > 0]


def dp_level_labels(x: np.ndarray, conf, rng: np.random.Generator) -> np.ndarray:
    """Parent label of each node of one level (labels are 0..P-1)."""
    z = _pca(x, conf.dp_pca_dims)
    labels = np.empty(len(x), dtype=np.int64)
    base = 0
    for block in _blocks(z, conf.dp_block_size):
        lab = _dp_block_labels(z[block], conf, int(rng.integers(2**31)))
        lab = cap_branching(x[block], lab, conf.max_branching, rng)
        _, lab = np.unique(lab, return_inverse=True)
        labels[block] = base + lab
        base += int(lab.max()) + 1
    return labels


def refine_to_voronoi(x: np.ndarray, lab: np.ndarray, w: np.ndarray, iters: int) -> np.ndarray:
    """Hard-EM steps in the full space: every child moves to its nearest parent centre.

    The DP fit (in PCA space, per block) fixes how many parents there are; these steps make
    each child's own parent its nearest one, which is what the greedy descent assumes.
    Parents left without children disappear.
    """
    for _ in range(iters):
        n_par = int(lab.max()) + 1
        c = parent_centres(x, lab, n_par, w)
        new = nearest_by_dot(x, c)
        _, new = np.unique(new, return_inverse=True)
        if np.array_equal(new, lab):
            break
        lab = new.astype(np.int64)
    return lab


def build_dp_tree(words: np.ndarray, weights: np.ndarray | None, conf) -> tuple[VocabTree, np.ndarray]:
    """Returns (tree, word_order): leaf k of the tree is input word ``word_order[k]``."""
    rng = np.random.default_rng(conf.seed)
    x = np.ascontiguousarray(words, dtype=np.float32)
    w = np.ones(len(x), np.float32) if weights is None else np.asarray(weights, np.float32)
    levels = []
    while True:
        n = len(x)
        if n <= conf.max_branching:
            levels.append(np.zeros(n, dtype=np.int64))
            break
        lab = dp_level_labels(x, conf, rng)
        if conf.dp_refine_iters > 0:
            lab = refine_to_voronoi(x, lab, w, conf.dp_refine_iters)
            lab = cap_branching(x, lab, conf.max_branching, rng)
        n_par = int(lab.max()) + 1
        if n_par >= n:  # the mixture kept every node apart: group by k-means so the tree still rises
            lab, _ = spherical_kmeans(x, max(2, n // 4), rng)
            n_par = int(lab.max()) + 1
        levels.append(lab)
        x = parent_centres(x, lab, n_par, w)
        w = np.bincount(lab, weights=w, minlength=n_par).astype(np.float32)
    return tree_from_bottom_up(words, levels, weights)
