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


def demo_surfaces(seed: int = 0) -> tuple[str, Rectangles]:
    """``(name, surfaces)`` as ``run_log(surfaces=...)`` takes them."""
    return f"demo world {int(seed)}", world_surfaces(seed)
