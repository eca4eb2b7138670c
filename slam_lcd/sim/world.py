"""The demo world: textured rectangles forming corridors around two solid blocks.

Layout (metres, z up, floor at z=0, ceiling at z=3)::

    y=14 +-----------------------------------------------+
         |   corridor (3 m)                              |
    y=11 |   +-----------+   +-----------+               |
         |   |  block A  |   |  block B  |               |
         |   | 8 x 8 m   |   | 8 x 8 m   |               |
    y=3  |   +-----------+   +-----------+               |
         |                                               |
    y=0  +-----------------------------------------------+
         x=0 3          11  14          22              25

The robot can circle block A (a 44 m loop) or run a figure eight around both blocks
through the middle corridor. Walls carry a base material (plaster, bricks, wood, tiles)
with posters, doors and notice boards pasted on; pillars stand out of the outer walls;
free-standing panels cut the four outer corners. A few decal groups (a door with its
posters) are pasted unchanged at several places: that is deliberate perceptual aliasing.

Static lighting from ceiling lamps is baked into the textures; each plane also keeps its
weights over the lamps so that the renderer can dim or brighten lamps between laps.
Every number comes from ``numpy.random.default_rng(seed)``: the same seed gives the
same world, bit for bit.

Where things stand (lamps, grids, materials, decal sites, pillars, panels) is
:mod:`slam_lcd.sim.building`'s: the demo building below :data:`OTHER_PLACE_SEED`, another
building on the same corridors from it on, the demo building with its west corridor repeated
as the east one from ``LOOKALIKE_SEED`` on (:mod:`slam_lcd.sim.lookalike`). This module paints
and lights what stands there.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..vision.gray import to_gray_uint8
from . import lookalike
from . import textures as tx
from .appearance import Look, check_appearance
from .building import BLOCKS, HEIGHT, OUTER, Building, building, wall_ends
from .lighting import DAY, Light, bake, mips
from .world_seeds import OTHER_PLACE_SEED as OTHER_PLACE_SEED  # public here too: where the world's seeds split

WALL_RES = 160.0  # texels per metre on walls and panels (6 mm texels)
FLOOR_RES = 80.0
CEIL_RES = 40.0
MAX_SEGMENT = 2.5  # walls are cut into pieces at most this wide (culling, mip choice)
N_LIGHT_EPOCHS = 12  # lighting states prepared (laps); later epochs repeat the last one


@dataclass
class Plane:
    """A textured rectangle ``origin + a*u + b*v`` for ``a in [0, width]``, ``b in [0, height]``.

    Mip levels carry a one-texel border: texel (row r, column c) of level L (shape
    ``(H_L + 2, W_L + 2)``) sits at ``a = (c - 0.5) * width / W_L``, ``b = (r - 0.5) * height / H_L``.
    ``normal = v x u`` points into free space, towards the viewer: seen from there, ``u`` runs
    to the right and ``v`` down, so textures appear upright and unmirrored.
    """

    name: str
    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    width: float
    height: float
    gray: list[np.ndarray]  # mip pyramid, level 0 first
    rgb: list[np.ndarray]
    lamp_weights: np.ndarray = field(default_factory=lambda: np.zeros(0))
    double_sided: bool = False

    @property
    def normal(self) -> np.ndarray:
        return np.cross(self.v, self.u)

    @property
    def corners(self) -> np.ndarray:
        o, a, b = self.origin, self.u * self.width, self.v * self.height
        return np.array([o, o + a, o + a + b, o + b])

    def point(self, a: float, b: float) -> np.ndarray:
        return self.origin + a * self.u + b * self.v


@dataclass
class DemoWorld:
    """All planes of the world plus lamp positions and per-epoch lamp gains."""

    seed: int
    planes: list[Plane]
    lamps: np.ndarray  # (L, 3)
    lamp_gains: np.ndarray  # (N_LIGHT_EPOCHS, L) multiplicative gain per lamp and lighting epoch
    exposure: np.ndarray  # (N_LIGHT_EPOCHS,) global gain per epoch
    alias_sites: list[dict] = field(default_factory=list)  # repeated decal groups: group, wall, centre, normal
    building: Building | None = None  # where lamps, grids, materials, decals, pillars and panels stand
    appearance: str = "day"  # the appearance state it was built in (slam_lcd.sim.appearance)
    # stacked geometry for vectorised culling
    corners: np.ndarray = field(init=False)
    normals: np.ndarray = field(init=False)
    origins: np.ndarray = field(init=False)

    def __post_init__(self):
        self.corners = np.stack([p.corners for p in self.planes])
        self.normals = np.stack([p.normal for p in self.planes])
        self.origins = np.stack([p.origin for p in self.planes])
        self._weights = np.stack([p.lamp_weights for p in self.planes])

    def plane_gains(self, epoch: float) -> np.ndarray:
        """Per-plane brightness gain for a lighting epoch (lap number; fractional values blend)."""
        e = float(np.clip(epoch, 0.0, N_LIGHT_EPOCHS - 1))
        i0 = int(np.floor(e))
        i1 = min(i0 + 1, N_LIGHT_EPOCHS - 1)
        f = e - i0
        lamp = (1 - f) * self.lamp_gains[i0] + f * self.lamp_gains[i1]
        expo = (1 - f) * self.exposure[i0] + f * self.exposure[i1]
        return (self._weights @ lamp) * expo

    def is_free(self, xy: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """True where a floor point is inside the outer walls and outside both blocks (with margin)."""
        xy = np.atleast_2d(xy)
        x, y = xy[:, 0], xy[:, 1]
        x0, y0, x1, y1 = OUTER
        ok = (x > x0 + margin) & (x < x1 - margin) & (y > y0 + margin) & (y < y1 - margin)
        for bx0, by0, bx1, by1 in BLOCKS:
            ok &= ~((x > bx0 - margin) & (x < bx1 + margin) & (y > by0 - margin) & (y < by1 + margin))
        return ok


# --------------------------------------------------------------------------- wall painting

def _decal_groups(rng: np.random.Generator) -> list[np.ndarray]:
    """Decal groups pasted at several places (aliasing): a door flanked by posters, a sign board."""
    r = WALL_RES
    groups = []
    for _ in range(3):
        g = np.zeros((int(2.3 * r), int(2.2 * r), 3), np.uint8)
        g[:] = tx.random_color(rng, 90, 200)
        tx.paste(g, tx.door(rng, int(2.1 * r), int(0.9 * r), r), int(0.65 * r), int(0.2 * r))
        tx.paste(g, tx.poster(rng, int(0.6 * r), int(0.45 * r), r), int(0.05 * r), int(0.5 * r))
        tx.paste(g, tx.poster(rng, int(0.6 * r), int(0.45 * r), r), int(1.65 * r), int(0.7 * r))
        groups.append(g)
    return groups


def _paint_wall(rng: np.random.Generator, length: float, material: str, groups, group_slots,
                decals: list | None = None) -> np.ndarray:
    """Paint one full wall (base material + decals). ``group_slots``: [(a_m, group_index)];
    ``decals`` (if given) receives the (x, y, w, h) texel box of every poster and board pasted."""
    r = WALL_RES
    h, w = int(round(HEIGHT * r)), int(round(length * r))
    img = tx.material(rng, material, h, w, r)
    if material == "plaster" and rng.random() < 0.6:  # wooden dado on the lower metre
        dado = tx.wood(rng, int(0.9 * r), w, r)
        img[h - dado.shape[0]:] = dado
    reserved = [(a - 0.1, a + 2.3) for a, _ in group_slots]
    for a, gi in group_slots:
        g = groups[gi]
        tx.paste(img, g, int(a * r), h - g.shape[0])
    a = float(rng.uniform(0.2, 0.8))
    while a < length - 0.4:
        kind = rng.choice(["poster", "poster", "poster", "door", "board", "gap"])
        # all three widths are drawn whatever the kind: the random stream, hence the world, depends on that
        wid = {"poster": rng.uniform(0.45, 1.1), "door": 0.9, "board": rng.uniform(1.2, 1.8),
               "gap": rng.uniform(0.2, 0.8)}[kind]
        if a + wid > length - 0.1 or any(a < e and a + wid > s for s, e in reserved):
            a += 0.3
            continue
        if kind == "poster":
            ph = float(rng.uniform(0.5, 1.2))
            top = float(rng.uniform(0.4, HEIGHT - 0.9 - ph + 0.4))
            tx.paste(img, tx.poster(rng, int(ph * r), int(wid * r), r), int(a * r), int(top * r))
            if decals is not None:
                decals.append((int(a * r), int(top * r), int(wid * r), int(ph * r)))
        elif kind == "door":
            tx.paste(img, tx.door(rng, int(2.1 * r), int(0.9 * r), r), int(a * r), h - int(2.1 * r))
        elif kind == "board":
            bh = float(rng.uniform(0.8, 1.1))
            board = np.empty((int(bh * r), int(wid * r), 3), np.uint8)
            board[:] = tx.random_color(rng, 60, 160)
            for _ in range(int(rng.integers(4, 9))):
                pw, ph = rng.uniform(0.15, 0.35), rng.uniform(0.15, 0.3)
                tx.paste(board, tx.poster(rng, int(ph * r), int(pw * r), r),
                         int(rng.uniform(0, wid - pw) * r), int(rng.uniform(0, bh - ph) * r))
            tx.paste(img, board, int(a * r), int(0.8 * r))
            if decals is not None:
                decals.append((int(a * r), int(0.8 * r), board.shape[1], board.shape[0]))
        a += wid + float(rng.uniform(0.15, 0.9))
    return img


def _wall_planes(name, p0, p1, tex, lamps, z_top=HEIGHT, double_sided=False, light: Light = DAY) -> list[Plane]:
    """Cut a wall from floor point p0 to p1 (free space on the left of p0->p1) into segments.

    Seen from the free side, p1 is on the viewer's left: texture column 0 is at p1 and the
    wall's ``u`` runs from p1 to p0 (so posters read left to right).
    """
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    length = float(np.linalg.norm(p1 - p0))
    u = np.array([*((p0 - p1) / length), 0.0])
    v = np.array([0.0, 0.0, -1.0])
    n_seg = int(np.ceil(length / MAX_SEGMENT - 1e-9))
    cuts = np.round(np.linspace(0, tex.shape[1], n_seg + 1)).astype(int)
    out = []
    for k in range(n_seg):
        a0, a1 = cuts[k] / tex.shape[1] * length, cuts[k + 1] / tex.shape[1] * length
        seg_tex = np.ascontiguousarray(tex[:, cuts[k]:cuts[k + 1]])
        origin = np.array([*(p1[:2] + u[:2] * a0), z_top])
        pl = Plane(f"{name}#{k}", origin, u, v, a1 - a0, z_top, [], [], double_sided=double_sided)
        lit, pl.lamp_weights = bake(pl, seg_tex, lamps, light)
        pl.rgb = mips(lit)
        pl.gray = [to_gray_uint8(m) for m in pl.rgb]
        out.append(pl)
    return out


def _horizontal_planes(name, tex_full, res, z, lamps_at, facing_up: bool, light: Light = DAY) -> list[Plane]:
    """Floor (facing up) or ceiling tiles over the free area, cut on the layout grid; ``lamps_at(x, y)``: the
    lamps that light the tile centred at (x, y)."""
    xs = [0.0, 3.0, 5.67, 8.33, 11.0, 14.0, 16.67, 19.33, 22.0, 25.0]
    ys = [0.0, 3.0, 5.67, 8.33, 11.0, 14.0]
    out = []
    for i in range(len(xs) - 1):
        for j in range(len(ys) - 1):
            x0, x1, y0, y1 = xs[i], xs[i + 1], ys[j], ys[j + 1]
            cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
            if any(bx0 < cx < bx1 and by0 < cy < by1 for bx0, by0, bx1, by1 in BLOCKS):
                continue
            c0, c1 = int(round(x0 * res)), int(round(x1 * res))
            # texture rows run from y=14 (row 0) downwards in y
            r0, r1 = int(round((OUTER[3] - y1) * res)), int(round((OUTER[3] - y0) * res))
            seg = np.ascontiguousarray(tex_full[r0:r1, c0:c1])
            if facing_up:  # u=+x, v=-y (rows from y1 down): normal v x u = +z
                origin, u, v = np.array([x0, y1, z]), np.array([1.0, 0, 0]), np.array([0, -1.0, 0])
            else:  # ceiling seen from below: u=+x, v=+y, normal -z
                origin, u, v = np.array([x0, y0, z]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0])
                seg = np.ascontiguousarray(seg[::-1])
            pl = Plane(f"{name}[{i},{j}]", origin, u, v, x1 - x0, y1 - y0, [], [])
            lit, pl.lamp_weights = bake(pl, seg, lamps_at(cx, cy), light)
            pl.rgb = mips(lit)
            pl.gray = [to_gray_uint8(m) for m in pl.rgb]
            out.append(pl)
    return out


def _pillar_planes(name, x, y, inward, along, tex_front, tex_side, lamps, light: Light = DAY) -> list[Plane]:
    """A 0.4 m wide, 0.3 m deep pillar standing out of a wall at (x, y) (front and two sides)."""
    inward, along = np.asarray(inward, float), np.asarray(along, float)
    base = np.array([x, y])
    half, depth = 0.2, 0.3
    a, b = base - along * half, base + along * half
    fa, fb = a + inward * depth, b + inward * depth
    planes = _wall_planes(f"{name}.front", fa, fb, tex_front, lamps, light=light)
    planes += _wall_planes(f"{name}.left", a, fa, tex_side, lamps, light=light)
    planes += _wall_planes(f"{name}.right", fb, b, tex_side, lamps, light=light)
    return planes


def _corner_panel(name, corner, dx, dy, tex, lamps, reach_x=1.3, reach_y=1.3, height=2.2,
                  light: Light = DAY) -> list[Plane]:
    """Free-standing panel across an outer corner, from ``reach_x`` m along the x wall to
    ``reach_y`` m along the y wall (1.3 m both in the demo building), ``height`` m tall."""
    c = np.asarray(corner, float)
    p0 = c + np.array([0.0, reach_y * dy])
    p1 = c + np.array([reach_x * dx, 0.0])
    # free space must be on the left of p0->p1
    d = p1 - p0
    left = np.array([-d[1], d[0]])
    if np.dot(left, np.array([dx, dy])) < 0:
        p0, p1 = p1, p0
    return _wall_planes(name, p0, p1, tex, lamps, z_top=height, light=light)


def build_world(seed: int = 0, appearance: str = "day") -> DemoWorld:
    """Build (and cache) the demo world for ``seed`` in an appearance state; ~1 s, ~100 MB of textures.

    Seeds from :data:`OTHER_PLACE_SEED` on build another building on the same corridors,
    seeds from :data:`~slam_lcd.sim.world_seeds.LOOKALIKE_SEED` on the demo building with a
    look-alike corridor (see :func:`building` and :mod:`slam_lcd.sim.lookalike`).
    ``appearance``: ``day`` (the world as the seed paints it), ``night``, ``moved`` or
    ``renovated`` (:mod:`slam_lcd.sim.appearance`)."""
    return _build_world(int(seed), check_appearance(str(appearance)))


@functools.lru_cache(maxsize=4)
def _build_world(seed: int, appearance: str) -> DemoWorld:
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5EED]))
    bld = building(seed)
    lamps = bld.lamps
    look = Look(appearance, seed, len(lamps))
    light = look.light

    def lit_by(where):  # the lamps lighting a wall (by name) or a floor or ceiling tile (by centre)
        return lookalike.lamps_lighting(bld, lamps, where)
    groups = _decal_groups(rng)
    planes: list[Plane] = []
    X0, Y0, X1, Y1 = OUTER
    slots = bld.slots
    sites: list[dict] = []

    def record_sites(name, p0, p1):
        p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
        d = (p0 - p1) / np.linalg.norm(p1 - p0)  # texture columns run from p1 towards p0
        for a, gi in slots.get(name, []):
            w_m, h_m = groups[gi].shape[1] / WALL_RES, groups[gi].shape[0] / WALL_RES
            centre = np.array([*(p1 + d * (a + w_m / 2)), h_m / 2])
            if look.changed_at(centre):
                continue  # painted over in this appearance state
            sites.append({"group": gi, "wall": name, "centre": centre, "normal": np.array([d[1], -d[0], 0.0])})

    # outer walls, then the faces of blocks A and B (names and ends: wall_ends)
    length = {name: float(np.hypot(p1[0] - p0[0], p1[1] - p0[1])) for name, (p0, p1) in wall_ends().items()}
    decals: dict[str, list] = {name: [] for name in length}
    walls = {name: _paint_wall(rng, length[name], bld.materials[name], groups, slots.get(name, []), decals[name])
             for name in length}
    if bld.lookalike:
        lookalike.copy_walls(walls, WALL_RES)
    look.change_walls(walls, decals, bld.materials, lambda g, name, material: _paint_wall(
        g, length[name], material, groups, []), WALL_RES)
    for name, (p0, p1) in wall_ends().items():
        planes += _wall_planes(name, p0, p1, walls[name], lit_by(name), light=light)
        record_sites(name, p0, p1)
    # pillars out of the outer walls (identical textures: more aliasing)
    front = tx.plaster(rng, int(HEIGHT * WALL_RES), int(0.4 * WALL_RES), WALL_RES)
    tx.paste(front, tx.poster(rng, int(0.3 * WALL_RES), int(0.3 * WALL_RES), WALL_RES),
             int(0.05 * WALL_RES), int(0.9 * WALL_RES))
    side = tx.plaster(rng, int(HEIGHT * WALL_RES), int(0.3 * WALL_RES), WALL_RES)
    for name, x, y, inward, along in bld.pillars:
        planes += _pillar_planes(name, x, y, inward, along, front, side, lit_by(name), light)
    # free-standing panels across the outer corners
    corners = [((X0, Y0), 1, 1), ((X1, Y0), -1, 1), ((X1, Y1), -1, -1), ((X0, Y1), 1, -1)]
    for k, reach_x, reach_y, height in bld.panels:
        corner, dx, dy = corners[k]
        if bld.other_place:
            width = float(np.hypot(reach_x, reach_y))
            ptex = np.empty((int(height * WALL_RES), int(width * WALL_RES), 3), np.uint8)
            ptex[:] = tx.random_color(rng, 40, 120)
            tx.paste(ptex, tx.poster(rng, int((height - 0.6) * WALL_RES), int((width - 0.34) * WALL_RES), WALL_RES),
                     int(0.17 * WALL_RES), int(0.15 * WALL_RES))
        else:
            ptex = np.empty((int(2.2 * WALL_RES), int(1.84 * WALL_RES), 3), np.uint8)
            ptex[:] = tx.random_color(rng, 40, 120)
            tx.paste(ptex, tx.poster(rng, int(1.6 * WALL_RES), int(1.5 * WALL_RES), WALL_RES),
                     int(0.17 * WALL_RES), int(0.15 * WALL_RES))
        ptex = look.change_panel(k, ptex, WALL_RES)
        planes += _corner_panel(f"panel{k}", corner, dx, dy, ptex, lamps, reach_x, reach_y, height, light)
    # floor and ceiling (texture row 0 at y = Y1, column 0 at x = X0)
    fh, fw = int(round((Y1 - Y0) * FLOOR_RES)), int(round((X1 - X0) * FLOOR_RES))
    fpx, fpy = bld.floor_phase_m
    floor = tx.tiles(rng, fh, fw, FLOOR_RES, tile_m=bld.floor_tile_m, phase_m=(fpx, fpy))
    for _ in range(60):  # scuffs and markings make the floor less periodic
        c = (int(rng.integers(0, fw)), int(rng.integers(0, fh)))
        cv2.ellipse(floor, c, (int(rng.uniform(3, 25)), int(rng.uniform(2, 8))), float(rng.uniform(0, 180)),
                    0, 360, tx.random_color(rng, 20, 120), -1, cv2.LINE_AA)
    if bld.lookalike:
        lookalike.copy_floor_or_ceiling(floor, FLOOR_RES)
    look.change_floor(floor, FLOOR_RES)
    planes += _horizontal_planes("floor", floor, FLOOR_RES, 0.0, lambda x, y: lit_by((x, y)), True, light)
    ch, cw = int(round((Y1 - Y0) * CEIL_RES)), int(round((X1 - X0) * CEIL_RES))
    ceil = tx.ceiling_panels(rng, ch, cw, CEIL_RES, tile_m=bld.ceil_tile_m, phase_m=bld.ceil_phase_m)
    hx, hy = bld.lamp_half_px
    for lx, ly, _ in lamps:  # lamp panels: bright rectangles
        lc, lr = int(lx * CEIL_RES), int((Y1 - ly) * CEIL_RES)
        cv2.rectangle(ceil, (lc - hx, lr - hy), (lc + hx, lr + hy), (250, 250, 245), -1)
    if bld.lookalike:
        lookalike.copy_floor_or_ceiling(ceil, CEIL_RES)
    planes += _horizontal_planes("ceiling", ceil, CEIL_RES, HEIGHT, lambda x, y: lit_by((x, y)), False, light)
    # lighting epochs: epoch 0 nominal; later epochs dim/brighten lamps and change exposure
    n_l = len(lamps)
    gains = np.ones((N_LIGHT_EPOCHS, n_l))
    gains[1:] = rng.uniform(0.7, 1.15, size=(N_LIGHT_EPOCHS - 1, n_l))
    expo = np.ones(N_LIGHT_EPOCHS)
    expo[1:] = rng.uniform(0.88, 1.08, size=N_LIGHT_EPOCHS - 1)
    return DemoWorld(seed=seed, planes=planes, lamps=lamps, lamp_gains=gains, exposure=expo, alias_sites=sites,
                     building=bld, appearance=appearance)
