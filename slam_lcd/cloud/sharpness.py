"""How sharp a map is, without ground truth: mean map entropy and mean plane variance.

As LiDAR SLAM evaluations define them (Droeschel & Behnke's MME; the plane variance of the
same neighbourhoods): for a point, the covariance ``S`` of the cloud's points within
``radius`` of it; its entropy ``0.5 ln det(2 pi e S)`` and its smallest eigenvalue (the
variance across the local plane). A wall seen twice by a drifting trajectory is two walls a
few centimetres apart: the neighbourhoods get thicker, both figures grow. Lower is sharper.

Why evaluated at a sample: every point's neighbourhood would cost ~100 neighbours x the
whole cloud; ``n_eval`` points drawn without replacement by a seeded generator (the same
draw for the same cloud) give the mean to well under the difference a correction makes,
with every point of the cloud still counted as a neighbour. Both figures depend on the
voxel size and the radius: compare maps built with the same settings only.

Why the entropy's eigenvalues have a floor (``min_std``, by default a fifth of the voxel): a
mean of logarithms is ruled by its smallest terms. Without the floor, a wall seen once (its
voxel centroids flat to a millimetre) weighs more than anything else, and a wall seen twice
and merged to within a centimetre reads as *less* sharp than the same wall left as two
separate sharp copies half a metre apart: the figure would reward ghosting. Thickness below
the map's resolution says nothing about a correction, so it is not counted. The plane
variance has no floor (it is a mean of variances, ruled by the thick places).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

_LOG_2PIE = float(np.log(2 * np.pi * np.e))
_CHUNK = 2000  # centres per neighbour query


def sample_indices(n: int, n_eval: int, seed: int = 0) -> np.ndarray:
    """Sorted indices of ``min(n, n_eval)`` points drawn without replacement (seeded)."""
    if n <= n_eval:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size=n_eval, replace=False))


def local_covariances(points: np.ndarray, centres: np.ndarray, radius: float,
                      tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(covariances (Q, 3, 3), neighbour counts (Q,))`` of the points within ``radius`` of each centre.

    The pairs come from one ``sparse_distance_matrix`` between a tree of the centres and one of
    the points (arrays, no Python list per centre); the sums are bincounts over the pairs."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    cen = np.asarray(centres, np.float64).reshape(-1, 3)
    q = len(cen)
    if q == 0 or len(pts) == 0:
        return np.zeros((q, 3, 3)), np.zeros(q, np.int64)
    tree = tree if tree is not None else cKDTree(pts)
    if q > _CHUNK:  # pairs of a chunk of centres at a time: memory ~ chunk x neighbours, not all pairs at once
        parts = [local_covariances(pts, cen[s:s + _CHUNK], radius, tree) for s in range(0, q, _CHUNK)]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
    pairs = cKDTree(cen).sparse_distance_matrix(tree, radius, output_type="ndarray")
    owner, flat = pairs["i"].astype(np.int64), pairs["j"].astype(np.int64)
    counts = np.bincount(owner, minlength=q)
    d = pts[flat] - cen[owner]  # centred on the query: no cancellation
    n = np.maximum(counts, 1).astype(np.float64)
    mean = np.column_stack([np.bincount(owner, d[:, i], q) for i in range(3)]) / n[:, None]
    cov = np.empty((q, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            cov[:, i, j] = cov[:, j, i] = np.bincount(owner, d[:, i] * d[:, j], q) / n - mean[:, i] * mean[:, j]
    return cov, counts


def sharpness(points: np.ndarray, radius: float = 0.3, n_eval: int = 20000, min_neighbours: int = 8,
              min_std: float = 0.0, seed: int = 0) -> dict:
    """``{"mme", "plane_variance_m2", "plane_std_mm", "points", "evaluated", "radius_m"}`` of a cloud (None figures
    when it has too few points); ``min_std``: the entropy's floor (m) per direction (see the module docstring)."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    out = {"mme": None, "plane_variance_m2": None, "plane_std_mm": None, "points": int(len(pts)), "evaluated": 0,
           "radius_m": float(radius), "min_std_m": float(min_std)}
    if len(pts) < min_neighbours:
        return out
    idx = sample_indices(len(pts), n_eval, seed)
    cov, counts = local_covariances(pts, pts[idx], radius)
    ok = counts >= min_neighbours
    if not ok.any():
        return out
    ev = np.clip(np.linalg.eigvalsh(cov[ok]), 0.0, None)  # ascending
    entropy = 0.5 * (3 * _LOG_2PIE + np.log(np.maximum(ev, max(min_std, 1e-6) ** 2)).sum(axis=1))
    pv = float(ev[:, 0].mean())
    out.update(mme=float(entropy.mean()), plane_variance_m2=pv, plane_std_mm=1000.0 * float(np.sqrt(pv)),
               evaluated=int(ok.sum()))
    return out
