"""Appearance states of the demo world: the same building at night, with its posters moved, or renovated.

A map kept over many days meets its places in other appearances, and must keep a view of each
(an appearance variant) where what it stored no longer matches. The lighting epochs and exposure
of the sessions (:mod:`slam_lcd.sim.sessions`) change brightness only, which SuperPoint's
descriptors hardly notice; these states change what the camera sees:

- ``day``: the world as it is built for every seed (the default; nothing here touches it);
- ``night``: the ambient light is gone and about 60 % of the lamps are on, each a spotlight
  pointing down: pools of light that burn the texture out under the lamps, dark walls between
  them, the lamp panels glowing on a dark ceiling (:class:`NightLight`);
- ``moved``: on about 60 % of the walls every poster and notice board is replaced by another,
  or taken down (bare wall where it hung) and another one put up elsewhere on that wall; two of
  the four corner panels carry another poster;
- ``renovated``: the east half of the building (everything east of the middle corridor's centre
  line, x >= 12.5 m) has new walls (another base material, other posters, boards and doors,
  the repeated decal groups gone) and a wooden floor; the east corner panels carry new posters.
  The west half, the ceiling and the pillars are as they were.

Geometry, lamps' places and lighting epochs are the same in every state: only textures and baked
light change, so ground truth, loops and the world's surfaces stay valid. Every change is drawn
from its own random stream (``seed``, state), so the ``day`` world is bit for bit the world built
without a state, and a state is the same world every time.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from . import textures as tx
from .building import MATERIALS, wall_ends
from .lighting import DAY, Light

APPEARANCES = ("day", "night", "moved", "renovated")
RENOVATED_X = 12.5  # metres: the renovated part of the building lies east of this line
NIGHT_LAMPS_ON = 0.6  # share of the lamps on at night


def check_appearance(name: str) -> str:
    """``name`` if it is an appearance state, else an InputError naming the valid ones."""
    if name not in APPEARANCES:
        raise InputError(f"unknown appearance {name!r}; use one of {', '.join(APPEARANCES)}")
    return name


@dataclass(frozen=True)
class NightLight(Light):
    """Night: a little ambient light and downward spotlights (``on``: which lamps are on).

    Each lamp that is on lights a surface with the cosine law, a beam of ``cos(angle from the
    vertical) ** beam`` and an inverse-square falloff, bright enough to saturate the floor under
    it; the ceiling only glows around the lamp panels. Finer sampling than the day's keeps the
    pools' edges.
    """

    samples_per_m: float = 10.0
    lo: float = 0.0
    hi: float = 3.0
    on: tuple = ()
    ambient: float = 0.04
    gain: float = 12.0
    beam: float = 4.0
    glow: float = 4.0
    glow_m: float = 0.3

    def factor(self, points: np.ndarray, normal: np.ndarray, lamps: np.ndarray) -> np.ndarray:
        on = np.asarray(self.on, float)
        d = lamps[None, :, :] - points[:, None, :]
        dist2 = (d ** 2).sum(-1)
        dist = np.sqrt(dist2 + 1e-9)
        facing = np.clip((d @ normal) / dist, 0.0, 1.0)
        down = np.clip(d[..., 2] / dist, 0.0, 1.0)  # the lamp above the point
        direct = (on * facing * down ** self.beam / (0.3 + dist2)).sum(1)
        out = self.ambient + self.gain * direct
        if normal[2] < -0.5:  # the ceiling: a glow around each lamp that is on
            horiz2 = d[..., 0] ** 2 + d[..., 1] ** 2
            out = out + self.glow * (on * np.exp(-horiz2 / (2 * self.glow_m ** 2))).sum(1)
        return out


class Look:
    """What one appearance state changes while a world is built (``day``: nothing, no random draw)."""

    def __init__(self, name: str, seed: int, n_lamps: int):
        self.name = check_appearance(name)
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xA99E, APPEARANCES.index(name)]))
        self.light: Light = DAY
        if name == "night":
            on = self.rng.random(n_lamps) < NIGHT_LAMPS_ON
            on[int(self.rng.integers(n_lamps))] = True
            self.light = NightLight(on=tuple(bool(x) for x in on))

    def changed_at(self, xy) -> bool:
        """Whether the state repaints the wall texture at floor point ``xy`` (a decal group's site)."""
        return self.name == "renovated" and float(xy[0]) >= RENOVATED_X

    def change_walls(self, walls: dict, decals: dict, materials: dict, paint, res: float) -> None:
        """Change the painted walls in place (``walls``: name -> texture; ``decals``: name -> poster
        and board boxes; ``paint(rng, name, material)``: a freshly painted wall without decal groups)."""
        if self.name == "moved":
            for name in sorted(walls):
                if self.rng.random() < 0.6:
                    _move_decals(self.rng, walls[name], decals[name], materials[name], res)
        elif self.name == "renovated":
            for name in sorted(walls):
                cols = renovated_columns(name, walls[name].shape[1], res)
                if cols is not None:
                    new = paint(self.rng, name, _other_material(self.rng, materials[name]))
                    walls[name][:, cols] = new[:, cols]

    def change_panel(self, k: int, tex: np.ndarray, res: float) -> np.ndarray:
        """A corner panel's texture in this state (``k``: corner 0-3 counter-clockwise from (0, 0))."""
        if self.name == "moved" and k in (0, 2) or self.name == "renovated" and k in (1, 2):
            tex = tex.copy()
            h, w = tex.shape[:2]
            tex[:] = tx.random_color(self.rng, 40, 120)
            tx.paste(tex, tx.poster(self.rng, int(h - 0.6 * res), int(w - 0.34 * res), res),
                     int(0.17 * res), int(0.15 * res))
        return tex

    def change_floor(self, floor: np.ndarray, res: float) -> None:
        """Change the floor texture in place (row 0 at the plan's north edge, column 0 at x = 0)."""
        if self.name == "renovated":
            c0 = int(round(RENOVATED_X * res))
            h, w = floor.shape[0], floor.shape[1] - c0
            floor[:, c0:] = tx.wood(self.rng, w, h, res).transpose(1, 0, 2)  # boards running east-west


def renovated_columns(name: str, width: int, res: float) -> slice | None:
    """The texture columns of wall ``name`` east of :data:`RENOVATED_X` (None: none)."""
    p0, p1 = (np.asarray(p, float) for p in wall_ends()[name])
    x = p1[0] + (p0[0] - p1[0]) * (np.arange(width) + 0.5) / width  # columns run from p1 to p0
    east = np.nonzero(x >= RENOVATED_X)[0]
    if len(east) == 0:
        return None
    return slice(int(east[0]), int(east[-1]) + 1)


def _other_material(rng: np.random.Generator, material: str) -> str:
    return str(rng.choice([m for m in MATERIALS if m != material]))


def _move_decals(rng: np.random.Generator, img: np.ndarray, boxes: list, material: str, res: float) -> None:
    """Each poster or board on a wall: replaced by another in its frame, or taken down (the bare wall
    shows where it hung) with another poster put up somewhere else along the wall."""
    if not boxes:
        return
    h, w = img.shape[:2]
    bare = tx.material(rng, material, h, w, res)
    for x, y, bw, bh in boxes:
        if rng.random() < 0.5:
            tx.paste(img, tx.poster(rng, bh, bw, res), x, y)
            continue
        img[y:y + bh, x:x + bw] = bare[y:y + bh, x:x + bw]
        pw, ph = int(rng.uniform(0.45, 1.1) * res), int(rng.uniform(0.5, 1.2) * res)
        px, py = int(rng.uniform(0, max(1, w - pw))), int(rng.uniform(0.3 * res, h - ph - 0.4 * res))
        tx.paste(img, tx.poster(rng, ph, pw, res), px, py)
