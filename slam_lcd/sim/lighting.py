"""How the demo world's lamps light its planes: the light baked into each texture, and the mip pyramid.

Why baked: lighting that does not change within a recording costs nothing at render time when it
is multiplied into the textures once; what does change between laps (lamp gains, exposure) is a
gain per plane (:meth:`slam_lcd.sim.world.DemoWorld.plane_gains`), which needs each plane's
weights over the lamps, kept beside its texture.

:class:`Light` is the daytime light every world is built with: a generous ambient share plus a
soft pool under each lamp. Other appearance states bring their own light
(:mod:`slam_lcd.sim.appearance`), baked the same way.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


def irradiance(points: np.ndarray, normal: np.ndarray, lamps: np.ndarray) -> np.ndarray:
    """(N, L) lamp contributions at points with the given normal (cosine law, soft falloff)."""
    d = lamps[None, :, :] - points[:, None, :]
    dist2 = (d ** 2).sum(-1)
    cos = np.clip((d @ normal) / np.sqrt(dist2 + 1e-9), 0.0, 1.0)
    return (0.25 + cos) / (1.0 + dist2 / 4.0)


@dataclass(frozen=True)
class Light:
    """The daytime light: ambient plus soft lamp pools, as a factor on the painted texture.

    ``samples_per_m``: the light is computed on a grid this fine over a plane and interpolated
    between; ``lo`` / ``hi``: the factor's range after interpolation.
    """

    samples_per_m: float = 5.0
    lo: float = 0.3
    hi: float = 1.15

    def factor(self, points: np.ndarray, normal: np.ndarray, lamps: np.ndarray) -> np.ndarray:
        """(N,) light factor at ``points`` of a plane facing ``normal``, before clipping to [lo, hi]."""
        light = irradiance(points, normal, lamps).sum(1)
        return 0.35 + 0.65 * light / 2.2


DAY = Light()


def bake(plane, tex: np.ndarray, lamps: np.ndarray, light: Light = DAY) -> tuple[np.ndarray, np.ndarray]:
    """Multiply ``light`` into ``tex`` over ``plane``; return (lit texture, lamp weights at the centre).

    The weights (what share of the plane's daytime light each lamp gives) are the daytime ones
    whatever ``light`` is: lighting epochs dim and brighten the same lamps in every state.
    """
    h, w = tex.shape[:2]
    n = light.samples_per_m
    gh, gw = max(2, int(plane.height * n) + 1), max(2, int(plane.width * n) + 1)
    a = np.linspace(0, plane.width, gw)
    b = np.linspace(0, plane.height, gh)
    A, B = np.meshgrid(a, b)
    pts = plane.origin + A.reshape(-1, 1) * plane.u + B.reshape(-1, 1) * plane.v
    factor = light.factor(pts, plane.normal, lamps).reshape(gh, gw)
    factor = cv2.resize(factor.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR)
    lit = np.clip(tex.astype(np.float32) * np.clip(factor, light.lo, light.hi)[..., None], 0, 255).astype(np.uint8)
    centre = plane.origin + 0.5 * plane.width * plane.u + 0.5 * plane.height * plane.v
    wts = irradiance(centre[None], plane.normal, lamps)[0]
    return lit, wts / wts.sum()


def mips(img: np.ndarray) -> list[np.ndarray]:
    """Box-filtered pyramid (INTER_AREA halving) down to ~8 texels, each level padded by one
    replicated texel on every side (so bilinear lookups at a plane's edge never blend with black)."""
    levels = [np.ascontiguousarray(img)]
    while min(levels[-1].shape[:2]) >= 16:
        h, w = levels[-1].shape[:2]
        levels.append(cv2.resize(levels[-1], ((w + 1) // 2, (h + 1) // 2), interpolation=cv2.INTER_AREA))
    return [cv2.copyMakeBorder(m, 1, 1, 1, 1, cv2.BORDER_REPLICATE) for m in levels]
