"""The map seen from above: one image per cloud, several clouds at the same scale, for the report.

Why a density image: a wall seen once is a thin bright line from above; a wall seen twice
by a drifting trajectory is two lines (ghosting), which a person sees at a glance. Pixels
count the points above them (log-scaled; only points in the middle of the height range, so
floor and ceiling do not cover the walls: :func:`height_band`); the same bounds and scale
for every cloud, so before and after can be laid side by side. Drawn with numpy and written
as PNG with OpenCV (no matplotlib figure).
"""
from __future__ import annotations

import cv2
import numpy as np


def common_bounds(clouds, margin: float = 0.5) -> tuple[float, float, float, float]:
    """``(x0, y0, x1, y1)`` covering every cloud's points (plus ``margin`` m)."""
    pts = [np.asarray(c.points)[:, :2] for c in clouds if len(c)]
    if not pts:
        return (-1.0, -1.0, 1.0, 1.0)
    lo = np.min([p.min(axis=0) for p in pts], axis=0) - margin
    hi = np.max([p.max(axis=0) for p in pts], axis=0) + margin
    return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


def height_band(clouds, low: float = 0.15, high: float = 0.8) -> tuple[float, float]:
    """``(z_min, z_max)``: the part of the clouds' height range (2nd-98th percentile) between ``low`` and ``high``."""
    z = np.concatenate([np.asarray(c.points)[:, 2] for c in clouds if len(c)] or [np.zeros(1)])
    z0, z1 = np.percentile(z, [2, 98])
    return float(z0 + low * (z1 - z0)), float(z0 + high * (z1 - z0))


def top_view(points: np.ndarray, bounds, px: int = 900, band: tuple[float, float] | None = None,
             label: str = "") -> np.ndarray:
    """A BGR uint8 image of the point density seen from above (x right, y up) within ``bounds``."""
    x0, y0, x1, y1 = bounds
    scale = (px - 1) / max(x1 - x0, y1 - y0, 1e-6)
    w, h = int((x1 - x0) * scale) + 1, int((y1 - y0) * scale) + 1
    p = np.asarray(points, np.float64).reshape(-1, 3)
    if band is not None:
        p = p[(p[:, 2] >= band[0]) & (p[:, 2] <= band[1])]
    c = np.clip(((p[:, 0] - x0) * scale).astype(int), 0, w - 1)
    r = np.clip(((y1 - p[:, 1]) * scale).astype(int), 0, h - 1)
    count = np.bincount(r * w + c, minlength=w * h).reshape(h, w).astype(np.float32)
    top = max(float(np.percentile(count[count > 0], 99)) if (count > 0).any() else 1.0, 1.0)
    g = np.clip(np.log1p(count) / np.log1p(top), 0, 1)
    img = cv2.applyColorMap((255 * g).astype(np.uint8), cv2.COLORMAP_INFERNO)
    img[count == 0] = (255, 255, 255)
    bar = max(1, int(round(scale)))  # 1 m scale bar, bottom left
    cv2.rectangle(img, (10, h - 14), (10 + bar, h - 10), (0, 0, 0), -1)
    cv2.putText(img, "1 m", (12 + bar, h - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    if label:
        cv2.putText(img, label, (10, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    return img


def top_view_png(points: np.ndarray, bounds, px: int = 900, band: tuple[float, float] | None = None,
                 label: str = "") -> bytes:
    ok, buf = cv2.imencode(".png", top_view(points, bounds, px, band, label))
    if not ok:
        raise RuntimeError("PNG coding of the top view failed")
    return buf.tobytes()
