"""Procedural textures for the demo world (RGB uint8 arrays, generated from a seeded RNG).

Why procedural: the demo must run on a fresh machine without downloads, yet a feature
detector needs what real rooms offer -- corners, blobs, edges at many scales. Each
generator paints at a given resolution (texels per metre) so that detail has a physical
size: bricks are 24 cm wide, poster glyphs a few centimetres, whatever the resolution.

All functions take a ``numpy.random.Generator`` and return ``(H, W, 3) uint8`` RGB.
"""
from __future__ import annotations

import string

import cv2
import numpy as np

from ..vision.gray import to_gray_uint8

_GLYPHS = string.ascii_uppercase + string.digits + "#&%@+="
_FONTS = (
    cv2.FONT_HERSHEY_SIMPLEX,
    cv2.FONT_HERSHEY_DUPLEX,
    cv2.FONT_HERSHEY_COMPLEX,
    cv2.FONT_HERSHEY_TRIPLEX,
    cv2.FONT_HERSHEY_PLAIN,
)


def value_noise(rng: np.random.Generator, h: int, w: int, cell_px: float, octaves: int = 4) -> np.ndarray:
    """Smooth fractal noise in [-1, 1], float32 (H, W): random grids upsampled with cubic interpolation."""
    out = np.zeros((h, w), np.float32)
    amp, total = 1.0, 0.0
    cell = float(cell_px)
    for _ in range(octaves):
        gh, gw = max(2, int(np.ceil(h / cell)) + 2), max(2, int(np.ceil(w / cell)) + 2)
        grid = rng.uniform(-1.0, 1.0, size=(gh, gw)).astype(np.float32)
        up = cv2.resize(grid, (int(gw * cell), int(gh * cell)), interpolation=cv2.INTER_CUBIC)
        out += amp * up[:h, :w]
        total += amp
        amp *= 0.55
        cell = max(1.0, cell / 2.0)
    return np.clip(out / total, -1.0, 1.0)


def _tint(noise: np.ndarray, base_rgb, contrast: float) -> np.ndarray:
    base = np.asarray(base_rgb, np.float32)[None, None, :]
    img = base * (1.0 + contrast * noise[..., None])
    return np.clip(img, 0, 255).astype(np.uint8)


def random_color(rng: np.random.Generator, lo: int = 30, hi: int = 230) -> tuple[int, int, int]:
    r, g, b = rng.integers(lo, hi, size=3)
    return int(r), int(g), int(b)


def plaster(rng: np.random.Generator, h: int, w: int, res: float) -> np.ndarray:
    """Painted plaster: low-contrast mottling plus stains (blobs at decimetre scale)."""
    base = random_color(rng, 120, 210)
    n = value_noise(rng, h, w, cell_px=0.25 * res, octaves=5)
    img = _tint(n, base, 0.18)
    for _ in range(int(h * w / (res * res) * 1.5)):  # ~1.5 stains per square metre
        c = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        ax = (int(rng.uniform(0.02, 0.10) * res), int(rng.uniform(0.02, 0.10) * res))
        shade = tuple(int(v * rng.uniform(0.55, 0.85)) for v in base)
        cv2.ellipse(img, c, ax, float(rng.uniform(0, 180)), 0, 360, shade, -1, cv2.LINE_AA)
    return img


def bricks(rng: np.random.Generator, h: int, w: int, res: float) -> np.ndarray:
    """Running-bond brick wall (24 x 8 cm bricks, 1 cm mortar) with per-brick colour and wear."""
    bw, bh, mortar = 0.24 * res, 0.08 * res, max(1.0, 0.012 * res)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    row = np.floor(ys / bh).astype(np.int32)
    xo = xs + (row % 2) * (bw / 2.0)
    col = np.floor(xo / bw).astype(np.int32)
    in_mortar = ((ys - row * bh) < mortar) | ((xo - col * bw) < mortar)
    base = np.asarray(random_color(rng, 110, 190), np.float32)
    nrow, ncol = int(row.max()) + 1, int(col.max()) + 1
    brick_gain = rng.uniform(0.55, 1.25, size=(nrow, ncol, 1)).astype(np.float32)
    brick_hue = rng.uniform(0.85, 1.15, size=(nrow, ncol, 3)).astype(np.float32)
    colour = base[None, None, :] * brick_gain[row, col] * brick_hue[row, col]
    grain = value_noise(rng, h, w, cell_px=0.03 * res, octaves=3)
    colour *= 1.0 + 0.25 * grain[..., None]
    colour[in_mortar] = np.asarray(random_color(rng, 170, 235), np.float32) * 0.9
    return np.clip(colour, 0, 255).astype(np.uint8)


def tiles(rng: np.random.Generator, h: int, w: int, res: float, tile_m: float = 0.5,
          phase_m: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Floor tiles with grout lines, per-tile shade and speckle (terrazzo-like) noise.

    ``phase_m``: (along columns, along rows) shift of the grid in metres; the grout lines
    sit where ``column / res + phase_m[0]`` (and ``row / res + phase_m[1]``) is a multiple of
    ``tile_m``."""
    t = tile_m * res
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    if phase_m[0] or phase_m[1]:
        xs += np.float32(phase_m[0] * res)
        ys += np.float32(phase_m[1] * res)
    r, c = np.floor(ys / t).astype(np.int32), np.floor(xs / t).astype(np.int32)
    grout = ((ys - r * t) < max(1.0, 0.01 * res)) | ((xs - c * t) < max(1.0, 0.01 * res))
    base = np.asarray(random_color(rng, 90, 200), np.float32)
    gain = rng.uniform(0.7, 1.2, size=(r.max() + 1, c.max() + 1, 1)).astype(np.float32)
    img = base[None, None, :] * gain[r, c]
    img *= 1.0 + 0.22 * value_noise(rng, h, w, cell_px=0.05 * res, octaves=3)[..., None]
    speck = rng.random((h, w)) < 0.004
    img[speck] *= 0.45
    img[grout] = base * 0.45
    out = np.clip(img, 0, 255).astype(np.uint8)
    return cv2.GaussianBlur(out, (3, 3), 0.6)


def wood(rng: np.random.Generator, h: int, w: int, res: float) -> np.ndarray:
    """Vertical wooden boards (12 cm) with grain streaks and knots."""
    board = 0.12 * res
    xs = np.arange(w, dtype=np.float32)
    bidx = np.floor(xs / board).astype(np.int32)
    base = np.asarray((150, 105, 65), np.float32) * rng.uniform(0.8, 1.2)
    bgain = rng.uniform(0.75, 1.2, size=bidx.max() + 1).astype(np.float32)
    streak = value_noise(rng, h, w, cell_px=0.01 * res, octaves=2)
    streak = cv2.resize(cv2.resize(streak, (w, max(2, h // 12))), (w, h))
    img = base[None, None, :] * bgain[bidx][None, :, None] * (1.0 + 0.25 * streak[..., None])
    img[:, (xs - bidx * board) < max(1.0, 0.008 * res)] *= 0.4
    out = np.clip(img, 0, 255).astype(np.uint8)
    for _ in range(int(w * h / (res * res) * 3)):
        c = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        ax = (max(1, int(0.012 * res)), max(1, int(0.03 * res)))
        cv2.ellipse(out, c, ax, 0, 0, 360, (70, 45, 25), -1, cv2.LINE_AA)
    return out


def poster(rng: np.random.Generator, h: int, w: int, res: float) -> np.ndarray:
    """A poster: coloured background, shapes, a title and lines of 'text' (corners at cm scale)."""
    img = np.empty((h, w, 3), np.uint8)
    img[:] = random_color(rng, 150, 250)
    n_shapes = int(rng.integers(6, 14))
    for _ in range(n_shapes):
        col = random_color(rng, 0, 255)
        kind = rng.integers(0, 5)
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        s = int(rng.uniform(0.04, 0.2) * res)
        if kind == 0:
            cv2.circle(img, (x, y), s, col, -1, cv2.LINE_AA)
        elif kind == 1:
            cv2.rectangle(img, (x - s, y - s // 2), (x + s, y + s // 2), col, -1, cv2.LINE_AA)
        elif kind == 2:
            pts = np.array([[x + s * np.cos(a), y + s * np.sin(a)] for a in rng.uniform(0, 2 * np.pi, 3)], np.int32)
            cv2.fillPoly(img, [pts], col, cv2.LINE_AA)
        elif kind == 3:
            k = int(rng.integers(5, 8))
            ang = np.linspace(0, 2 * np.pi, 2 * k, endpoint=False)
            rad = np.where(np.arange(2 * k) % 2 == 0, s, s * 0.45)
            pts = np.stack([x + rad * np.cos(ang), y + rad * np.sin(ang)], 1).astype(np.int32)
            cv2.fillPoly(img, [pts], col, cv2.LINE_AA)
        else:  # small checkerboard patch
            cells = int(rng.integers(3, 6))
            cs = max(2, s // 2)
            for i in range(cells):
                for j in range(cells):
                    if (i + j) % 2 == 0:
                        cv2.rectangle(img, (x + j * cs, y + i * cs), (x + (j + 1) * cs, y + (i + 1) * cs), col, -1)
    # title and text lines
    ink = random_color(rng, 0, 90)
    font = _FONTS[int(rng.integers(len(_FONTS)))]
    title_scale = 0.06 * res / 22.0
    title = "".join(rng.choice(list(_GLYPHS), size=int(rng.integers(4, 8))))
    cv2.putText(img, title, (int(0.05 * w), int(0.05 * res) + int(0.06 * res)), font, title_scale,
                ink, max(1, int(0.006 * res)), cv2.LINE_AA)
    line_h = 0.035 * res
    line_y = h * rng.uniform(0.55, 0.7)
    while line_y < h - line_h:
        words = " ".join("".join(rng.choice(list(_GLYPHS), size=int(rng.integers(2, 7)))) for _ in range(4))
        cv2.putText(img, words, (int(0.05 * w), int(line_y)), cv2.FONT_HERSHEY_SIMPLEX, 0.02 * res / 22.0,
                    ink, max(1, int(0.003 * res)), cv2.LINE_AA)
        line_y += line_h
    border = max(2, int(0.015 * res))
    cv2.rectangle(img, (0, 0), (w - 1, h - 1), random_color(rng, 0, 80), border)
    return img


def door(rng: np.random.Generator, h: int, w: int, res: float) -> np.ndarray:
    """A door: frame, panel, handle and a small sign (a deliberately generic, aliasing-prone object)."""
    img = np.empty((h, w, 3), np.uint8)
    frame_col, panel_col = random_color(rng, 40, 120), random_color(rng, 120, 220)
    img[:] = frame_col
    f = max(2, int(0.06 * res))
    cv2.rectangle(img, (f, f), (w - f, h), panel_col, -1)
    inset = int(0.12 * res)
    cv2.rectangle(img, (f + inset, f + inset), (w - f - inset, h // 2 - inset // 2), frame_col, max(1, int(0.01 * res)))
    cv2.rectangle(img, (f + inset, h // 2 + inset // 2), (w - f - inset, h - inset), frame_col, max(1, int(0.01 * res)))
    hx, hy = w - f - int(0.1 * res), int(h * 0.52)
    cv2.rectangle(img, (hx - int(0.05 * res), hy - int(0.012 * res)), (hx + int(0.02 * res), hy + int(0.012 * res)),
                  (40, 40, 40), -1, cv2.LINE_AA)
    sign = poster(rng, int(0.2 * res), int(0.3 * res), res)
    sy, sx = int(0.3 * res), (w - sign.shape[1]) // 2
    img[sy:sy + sign.shape[0], sx:sx + sign.shape[1]] = sign
    return img


def ceiling_panels(rng: np.random.Generator, h: int, w: int, res: float, tile_m: float = 0.6,
                   phase_m: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Suspended-ceiling grid (60 cm unless ``tile_m`` says otherwise) with mottled panels."""
    img = tiles(rng, h, w, res, tile_m=tile_m, phase_m=phase_m)
    gray = to_gray_uint8(img)
    return cv2.cvtColor(cv2.addWeighted(gray, 0.6, np.full_like(gray, 200), 0.4, 0), cv2.COLOR_GRAY2RGB)


def material(rng: np.random.Generator, name: str, h: int, w: int, res: float) -> np.ndarray:
    """A wall's base material by name (``plaster``, ``bricks``, ``wood``, ``tiles``: 20 cm wall tiles)."""
    if name == "tiles":
        return tiles(rng, h, w, res, tile_m=0.2)
    return {"plaster": plaster, "bricks": bricks, "wood": wood}[name](rng, h, w, res)


def paste(dst: np.ndarray, src: np.ndarray, x: int, y: int) -> None:
    """Copy ``src`` into ``dst`` at top-left (x, y), clipped to ``dst``."""
    h, w = dst.shape[:2]
    x0, y0, x1, y1 = max(0, x), max(0, y), min(w, x + src.shape[1]), min(h, y + src.shape[0])
    if x1 > x0 and y1 > y0:
        dst[y0:y1, x0:x1] = src[y0 - y:y1 - y, x0 - x:x1 - x]
