"""The demo world's true surfaces as plain rectangles: what a map of it should lie on.

Why here: only the renderer's world knows where its walls, floor, ceiling, pillars and panels
are. A run's map cloud is measured against these (:func:`slam_lcd.cloud.surface_distances`)
so that its ground-truth-free sharpness figures can be checked against the truth.
"""
from __future__ import annotations

import numpy as np

from ..types import Rectangles
from .world import build_world


def world_surfaces(seed: int = 0) -> Rectangles:
    """Every plane of the demo world of ``seed`` (in its ``world`` frame), as :class:`~slam_lcd.types.Rectangles`."""
    planes = build_world(int(seed)).planes
    return Rectangles(origins=np.array([p.origin for p in planes], float), u=np.array([p.u for p in planes], float),
                      v=np.array([p.v for p in planes], float), widths=np.array([p.width for p in planes], float),
                      heights=np.array([p.height for p in planes], float))


def moved(r: Rectangles, T: np.ndarray) -> Rectangles:
    """The rectangles seen from another frame: ``T`` maps their frame's points into it."""
    R, t = T[:3, :3], T[:3, 3]
    return Rectangles(r.origins @ R.T + t, r.u @ R.T, r.v @ R.T, r.widths.copy(), r.heights.copy())


def demo_surfaces(seed: int = 0) -> tuple[str, dict[str, Rectangles]]:
    """``(name, {ground-truth frame: surfaces in it})`` as ``OutputOptions(surfaces=...)`` takes them: the demo
    logs' ground truth is in ``world``, the EuRoC layout's in a shifted, turned ``leica`` frame."""
    from .layouts import T_LEICA_WORLD  # lazy: scipy (the layouts' geometry), which the surfaces do without

    r = world_surfaces(seed)
    return f"demo world {int(seed)}", {"world": r, "leica": moved(r, T_LEICA_WORLD)}
