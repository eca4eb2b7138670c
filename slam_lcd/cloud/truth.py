"""Distance from map points to known true surfaces (flat rectangles): the check of the GT-free figures.

Why: mean map entropy and plane variance say a map got sharper; on a simulated world whose
surfaces are known (the demo world's walls, floor, ceiling, pillars and panels) the distance
of the map's points to the nearest true surface says whether it also got *right*. The map is
first put into the world's frame by the trajectory's own ATE alignment (each map by its own,
as each ATE is), so what is left is the map's shape, not where its frame happens to sit.
"""
from __future__ import annotations

import numpy as np

from ..types import Rectangles

_CHUNK = 2048


def surface_distances(points: np.ndarray, surfaces: Rectangles) -> np.ndarray:
    """Euclidean distance (m) of each point to the nearest rectangle of ``surfaces``."""
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    o, u, v = (np.asarray(a, np.float64) for a in (surfaces.origins, surfaces.u, surfaces.v))
    w, h = np.asarray(surfaces.widths, np.float64), np.asarray(surfaces.heights, np.float64)
    out = np.full(len(pts), np.inf)
    if len(o) == 0:
        return out
    for s in range(0, len(pts), _CHUNK):
        d = pts[s:s + _CHUNK, None, :] - o[None]  # (n, R, 3)
        a = np.clip(np.einsum("nrk,rk->nr", d, u), 0.0, w)
        b = np.clip(np.einsum("nrk,rk->nr", d, v), 0.0, h)
        r = d - a[..., None] * u[None] - b[..., None] * v[None]
        out[s:s + _CHUNK] = np.sqrt(np.einsum("nrk,nrk->nr", r, r).min(axis=1))
    return out


def aligned(points: np.ndarray, R: np.ndarray, t: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """``scale * R @ p + t`` for each point (an ATE alignment applied to a map)."""
    return float(scale) * np.asarray(points, np.float64) @ np.asarray(R, np.float64).T + np.asarray(t, np.float64)


def truth_figures(points: np.ndarray, surfaces: Rectangles, n_eval: int = 20000, seed: int = 0) -> dict:
    """Mean, median and 90th-percentile distance (m) of (a seeded sample of) the points to the surfaces."""
    from .sharpness import sample_indices  # lazy: scipy

    pts = np.asarray(points, np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return {"mean_m": None, "median_m": None, "p90_m": None, "evaluated": 0}
    dist = surface_distances(pts[sample_indices(len(pts), n_eval, seed)], surfaces)
    return {"mean_m": float(dist.mean()), "median_m": float(np.median(dist)), "p90_m": float(np.percentile(dist, 90)),
            "evaluated": int(len(dist))}
