"""The look-alike world: the demo building with its west corridor repeated as the east corridor.

World seeds from :data:`~slam_lcd.sim.world_seeds.LOOKALIKE_SEED` on build the demo building
(textures and lamp states from the seed, as below 1000) and make the east corridor beside
block B (P2: x 22-25 m, y 3-11 m) a copy of the west corridor beside block A (P1: x 0-3 m,
y 3-11 m) shifted 22 m east:

- the wall on the corridor's west side (the outer west wall in P1, block B's east face in P2)
  and on its east side (block A's west face, the outer east wall) carry the same texture over
  the corridor's 8 m;
- the floor (tiles and scuffs) and the ceiling (panel grid and lamp panels) over it are the same;
- it is lit as P1 is, in every lighting epoch (:func:`lamps_lighting`);
- a pillar stands out of its west wall at the same place (:func:`~slam_lcd.sim.building.building`).

The two corridors are then the same place as far as a camera inside either can see, up to the
corridors' ends (P1's south end opens to the east, P2's to the west, one corner panel on the
right, the other on the left) and the image noise: a robot driving south through one sees what
it would see driving south through the other until the end of the corridor fills its view.
This is perceptual aliasing with a whole place, not a poster: a map that takes one for the other
puts a robot 22 m away, with loop closures that agree with each other.

Why a copy and not two walls painted from one seed: the painting of every wall draws from one
random stream, so a copy leaves the rest of the world exactly as the demo building of the same
textures would be.
"""
from __future__ import annotations

import numpy as np

from .building import LOOKALIKE_P1, LOOKALIKE_PILLAR, LOOKALIKE_SHIFT, OUTER

# P2's walls (name, first texture column there) take P1's (name, first column, columns). Texture
# columns run from a wall's p1 end towards its p0 end (:func:`slam_lcd.sim.world._wall_planes`):
# the outer west wall from y = 0 up, block B's east face from y = 3 up, block A's west face from
# y = 11 down, the outer east wall from y = 14 down; y 3-11 m is then columns 3-11 m of the
# outer west wall and 3-11 m of the outer east wall.
_WALL_COPIES = (("B2", 0.0, "outer3", 3.0, 8.0), ("outer1", 3.0, "A0", 0.0, 8.0))
_P2_WALLS = {"B2", "outer1", LOOKALIKE_PILLAR}  # lit as their P1 counterparts (the outer east wall all along)


def copy_walls(textures: dict[str, np.ndarray], res: float) -> None:
    """Paint P2's walls with P1's textures (``textures``: wall name -> full-wall texture, ``res`` texels/m)."""
    for dst, dst_m, src, src_m, length_m in _WALL_COPIES:
        c0, c1, n = int(round(dst_m * res)), int(round(src_m * res)), int(round(length_m * res))
        textures[dst][:, c0:c0 + n] = textures[src][:, c1:c1 + n]


def copy_floor_or_ceiling(tex: np.ndarray, res: float) -> None:
    """Copy P1's part of a floor or ceiling texture (row 0 at the plan's north edge, column 0 at x = 0) onto P2's."""
    x0, y0, x1, y1 = LOOKALIKE_P1
    dx, dy = LOOKALIKE_SHIFT
    r0, r1 = int(round((OUTER[3] - y1) * res)), int(round((OUTER[3] - y0) * res))
    c0, c1 = int(round(x0 * res)), int(round(x1 * res))
    s0, d0 = int(round(-dy * res)) + r0, int(round(dx * res)) + c0  # rows run south, columns east
    tex[s0:s0 + r1 - r0, d0:d0 + c1 - c0] = tex[r0:r1, c0:c1]


def lamps_lighting(bld, lamps: np.ndarray, where) -> np.ndarray:
    """The lamps that light a wall (``where``: its name) or a floor or ceiling tile (its centre (x, y)).

    In the look-alike world P2's walls, pillar and tiles are lit by the lamps shifted as P2 is
    from P1: their baked light and their weights over the lamps (hence their brightness in every
    lighting epoch) are then P1's. Elsewhere, and in every other world, the lamps as they stand.
    """
    if not bld.lookalike:
        return lamps
    if isinstance(where, str):
        in_p2 = where in _P2_WALLS
    else:
        in_p2 = bool(np.any(to_p1(np.asarray(where, float)) != np.asarray(where, float)))
    return lamps + np.array([*LOOKALIKE_SHIFT, 0.0]) if in_p2 else lamps


def to_p1(xy: np.ndarray) -> np.ndarray:
    """Points (N, 2) in P2 moved to where they would be in P1 (others unchanged): where P2's views look."""
    xy = np.array(xy, float).reshape(-1, 2)
    x0, y0, x1, y1 = LOOKALIKE_P1
    dx, dy = LOOKALIKE_SHIFT
    inside = (xy[:, 0] >= x0 + dx) & (xy[:, 0] <= x1 + dx) & (xy[:, 1] >= y0 + dy) & (xy[:, 1] <= y1 + dy)
    xy[inside] -= np.array([dx, dy])
    return xy
