"""Where things stand in a demo world: lamps, floor and ceiling grids, wall materials, decal-group
sites, pillars and corner panels (:class:`Building`), on the floor plan of :mod:`slam_lcd.sim.world`.

Three kinds of world share these corridors (:func:`building`). Seeds below
:data:`OTHER_PLACE_SEED` (1000) are the demo building: its lamps, tile and ceiling grids,
materials per wall, decal-group sites, pillars and corner panels stand where this module's
constants put them, and the seed only re-draws textures and lamp states. Seeds from 1000
to 1999 are another building on the same footprint: all of those are drawn from the seed too,
away from where the demo building has them, so nothing but the corridors themselves sits
at the same 3-D place (session 4 records world 1000: a place a map of world 0 must not
recognise). Seeds from :data:`LOOKALIKE_SEED` (2000) on are the demo building again, with its
west corridor repeated as the east one (:mod:`slam_lcd.sim.lookalike`): two places that look
the same.

Why apart from :mod:`slam_lcd.sim.world`: the placement is cheap and needs no texture, so
sessions and tests can ask where things stand without building (painting, baking) a world.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .world_seeds import LOOKALIKE_SEED, OTHER_PLACE_SEED

HEIGHT = 3.0  # wall height (m)
OUTER = (0.0, 0.0, 25.0, 14.0)  # x0, y0, x1, y1 of the outer walls
BLOCKS = ((3.0, 3.0, 11.0, 11.0), (14.0, 3.0, 22.0, 11.0))  # solid blocks A and B
# the look-alike corridor: the west corridor beside block A (x0, y0, x1, y1) stands again, shifted
# this far east (x, y; metres), as the east corridor beside block B
LOOKALIKE_P1 = (0.0, 3.0, 3.0, 11.0)
LOOKALIKE_SHIFT = (22.0, 0.0)
LOOKALIKE_PILLAR = "pillarB2"  # the west corridor's pillar, repeated on block B's east face
MATERIALS = ("plaster", "bricks", "wood", "tiles")


@dataclass(frozen=True)
class Building:
    """Where things stand in a world (everything but the textures' contents and lamp states).

    ``lamps`` (L, 3) ceiling lamp positions; ``lamp_half_px`` the lamp panels' half size
    (along x, along y) in ceiling texels; ``floor_tile_m`` / ``ceil_tile_m`` the floor tile
    and ceiling panel sizes and ``floor_phase_m`` / ``ceil_phase_m`` their grids' shifts
    (along x, along y; metres); ``materials`` the base material of every wall by name
    (``outer0``-``outer3``, ``A0``-``A3``, ``B0``-``B3``); ``slots`` the decal-group sites,
    wall name -> [(metres along the wall's texture, group)]; ``pillars`` (name, x, y,
    inward, along) of each pillar; ``panels`` (corner index 0-3 counter-clockwise from
    (0, 0), metres along the x wall, metres along the y wall, height) of each corner panel.
    """

    other_place: bool
    lamps: np.ndarray
    lamp_half_px: tuple[int, int]
    floor_tile_m: float
    floor_phase_m: tuple[float, float]
    ceil_tile_m: float
    ceil_phase_m: tuple[float, float]
    materials: dict
    slots: dict
    pillars: tuple
    panels: tuple
    lookalike: bool = False  # the east corridor repeats the west one (LOOKALIKE_P1, LOOKALIKE_SHIFT)


def _lamp_positions() -> np.ndarray:
    """Ceiling lamps every 3 m along the corridor centre lines."""
    pts = []
    for y in (1.5, 12.5):
        pts += [(x, y) for x in np.arange(1.5, 25.0, 3.0)]
    for x in (1.5, 12.5, 23.5):
        pts += [(x, y) for y in np.arange(4.5, 11.0, 3.0)]
    xy = np.unique(np.round(np.array(pts), 3), axis=0)
    return np.column_stack([xy, np.full(len(xy), HEIGHT - 0.05)])

_DEMO_MATERIALS = {"outer0": "plaster", "outer1": "plaster", "outer2": "plaster", "outer3": "plaster",
                   "A0": "bricks", "A1": "plaster", "A2": "bricks", "A3": "wood",
                   "B0": "tiles", "B1": "plaster", "B2": "tiles", "B3": "bricks"}
# aliasing: each decal group appears on two or three walls at different places
_DEMO_SLOTS = {"outer0": [(4.0, 0), (15.0, 1)], "outer2": [(2.2, 0), (8.0, 2)], "A1": [(2.5, 1)], "B3": [(3.0, 2)],
               "outer3": [(1.8, 0)]}
_GROUP_W = 2.2  # width of a decal group (m)


def wall_ends() -> dict:
    """Every wall by name: (p0, p1), free space on the left of p0 -> p1."""
    X0, Y0, X1, Y1 = OUTER
    # outer walls counter-clockwise seen from above so free space (inside) is on the left
    outer = [((X0, Y0), (X1, Y0)), ((X1, Y0), (X1, Y1)), ((X1, Y1), (X0, Y1)), ((X0, Y1), (X0, Y0))]
    ends = {f"outer{k}": e for k, e in enumerate(outer)}
    for bi, (bx0, by0, bx1, by1) in enumerate(BLOCKS):
        # block faces clockwise seen from above so free space (outside) is on the left
        faces = [((bx0, by0), (bx0, by1)), ((bx0, by1), (bx1, by1)), ((bx1, by1), (bx1, by0)), ((bx1, by0), (bx0, by0))]
        ends.update({f"{'AB'[bi]}{k}": e for k, e in enumerate(faces)})
    return ends


def _demo_building() -> Building:
    X0, Y0, X1, Y1 = OUTER
    pillars = []
    for x in (7.0, 18.0):
        pillars.append((f"pillarS{x:g}", x, Y0, (0, 1), (1, 0)))
        pillars.append((f"pillarN{x:g}", x, Y1, (0, -1), (-1, 0)))
    pillars += [("pillarW", X0, 7.0, (1, 0), (0, -1)), ("pillarE", X1, 7.0, (-1, 0), (0, 1))]
    return Building(other_place=False, lamps=_lamp_positions(), lamp_half_px=(12, 5), floor_tile_m=0.5,
                    floor_phase_m=(0.0, 0.0), ceil_tile_m=0.6, ceil_phase_m=(0.0, 0.0),
                    materials=dict(_DEMO_MATERIALS), slots={k: list(v) for k, v in _DEMO_SLOTS.items()},
                    pillars=tuple(pillars), panels=tuple((k, 1.3, 1.3, 2.2) for k in range(4)))


def _away(g: np.random.Generator, lo: float, hi: float, avoid, gap: float, tries: int = 200) -> float:
    """A uniform draw in [lo, hi] at least ``gap`` from every value of ``avoid``."""
    for _ in range(tries):
        x = float(g.uniform(lo, hi))
        if all(abs(x - a) >= gap for a in avoid):
            return x
    raise RuntimeError("no room left for a draw")  # pragma: no cover - the ranges below leave plenty


def _other_building(seed: int) -> Building:
    """Another building on the demo corridors: everything placed from ``seed``, away from the demo's places."""
    g = np.random.default_rng(np.random.SeedSequence([seed, 0xB1D6]))
    X0, Y0, X1, Y1 = OUTER
    demo = _demo_building()
    # lamps: another spacing and phase, off the corridors' centre lines (>= 0.55 m from every demo lamp)
    spacing = float(g.uniform(2.2, 2.7))
    pts = []
    for yc in (1.5, 12.5):  # south and north corridors
        y = yc + float(g.choice([-1.0, 1.0]) * g.uniform(0.55, 0.9))
        pts += [(x, y) for x in np.arange(g.uniform(0.6, 0.6 + spacing), X1 - 0.5, spacing)]
    for xc in (1.5, 12.5, 23.5):  # west, middle and east corridors, between the blocks' ends
        x = xc + float(g.choice([-1.0, 1.0]) * g.uniform(0.55, 0.9))
        pts += [(x, y) for y in np.arange(g.uniform(3.6, 3.6 + spacing), BLOCKS[0][3] - 0.4, spacing)]
    xy = np.round(np.array(pts), 3)
    d = np.linalg.norm(xy[:, None] - demo.lamps[None, :, :2], axis=2).min(1)
    xy = xy[d >= 0.5]
    lamps = np.column_stack([xy, np.full(len(xy), HEIGHT - 0.05)])
    lamp_half = [(5, 12), (8, 8), (16, 4)][int(g.integers(3))]
    # floor tiles and ceiling panels: other sizes, grids shifted
    floor_tile = float(g.choice([0.6, 0.75]))
    floor_phase = (float(g.uniform(0.15, floor_tile - 0.15)), float(g.uniform(0.15, floor_tile - 0.15)))
    ceil_tile = float(g.choice([0.5, 0.75]))
    ceil_phase = (float(g.uniform(0.1, ceil_tile - 0.1)), float(g.uniform(0.1, ceil_tile - 0.1)))
    # every wall another material than the demo's
    materials = {w: str(g.choice([m for m in MATERIALS if m != mat])) for w, mat in _DEMO_MATERIALS.items()}
    # decal groups at other walls and places (>= 2.5 m from a demo site of the same wall)
    ends = wall_ends()
    lengths = {w: float(np.hypot(p1[0] - p0[0], p1[1] - p0[1])) for w, (p0, p1) in ends.items()}
    slots: dict = {}
    for gi in range(3):  # each group on two or three walls
        want, placed = int(g.integers(2, 4)), 0
        for w in g.permutation(sorted(ends)):
            w = str(w)
            taken = [a for a, _ in slots.get(w, [])]
            try:
                a = _away(g, 0.4, lengths[w] - _GROUP_W - 0.3, [a for a, _ in _DEMO_SLOTS.get(w, [])], 2.5, tries=50)
            except RuntimeError:
                continue
            if any(abs(a - t) < _GROUP_W + 0.4 for t in taken):
                continue
            slots.setdefault(w, []).append((round(a, 2), gi))
            placed += 1
            if placed == want:
                break
    # pillars: two on each long outer wall, one on each short one, away from the demo's
    pillars = []
    xs_s = [_away(g, 2.2, 11.0, [7.0], 1.5), _away(g, 14.0, 22.8, [18.0], 1.5)]
    xs_n = [_away(g, 2.2, 11.0, [7.0], 1.5), _away(g, 14.0, 22.8, [18.0], 1.5)]
    for x in xs_s:
        pillars.append((f"pillarS{x:.2f}", x, Y0, (0, 1), (1, 0)))
    for x in xs_n:
        pillars.append((f"pillarN{x:.2f}", x, Y1, (0, -1), (-1, 0)))
    pillars.append(("pillarW", X0, _away(g, 2.2, 11.8, [7.0], 1.5), (1, 0), (0, -1)))
    pillars.append(("pillarE", X1, _away(g, 2.2, 11.8, [7.0], 1.5), (-1, 0), (0, 1)))
    # corner panels: other reach along each wall and another height

    def off(c, lo, hi):
        return c + float(g.choice([-1.0, 1.0]) * g.uniform(lo, hi))

    panels = tuple((k, off(1.3, 0.25, 0.4), off(1.3, 0.25, 0.4), off(2.2, 0.2, 0.4)) for k in range(4))
    return Building(other_place=True, lamps=lamps, lamp_half_px=lamp_half, floor_tile_m=floor_tile,
                    floor_phase_m=floor_phase, ceil_tile_m=ceil_tile, ceil_phase_m=ceil_phase, materials=materials,
                    slots=slots, pillars=tuple(pillars), panels=panels)


def _lookalike_building() -> Building:
    """The demo building with the east pillar moved from the outer east wall to block B's east face,
    where the west pillar stands in the west corridor once shifted by :data:`LOOKALIKE_SHIFT`: the
    east corridor then has the west one's pillar too (its textures are copied when the world is painted)."""
    demo = _demo_building()
    dx, dy = LOOKALIKE_SHIFT
    west = [(LOOKALIKE_PILLAR, x + dx, y + dy, inward, along) for name, x, y, inward, along in demo.pillars
            if name == "pillarW"]
    pillars = tuple(p for p in demo.pillars if p[0] != "pillarE") + tuple(west)
    return Building(other_place=False, lamps=demo.lamps, lamp_half_px=demo.lamp_half_px,
                    floor_tile_m=demo.floor_tile_m, floor_phase_m=demo.floor_phase_m, ceil_tile_m=demo.ceil_tile_m,
                    ceil_phase_m=demo.ceil_phase_m, materials=demo.materials, slots=demo.slots, pillars=pillars,
                    panels=demo.panels, lookalike=True)


def building(seed: int = 0) -> Building:
    """Where things stand in world ``seed``: the demo building below :data:`OTHER_PLACE_SEED`,
    another building on the same corridors from it to :data:`LOOKALIKE_SEED`, and from that on the demo
    building with a look-alike corridor."""
    seed = int(seed)
    if seed >= LOOKALIKE_SEED:
        return _lookalike_building()
    return _other_building(seed) if seed >= OTHER_PLACE_SEED else _demo_building()
