"""Sessions: the demo world recorded several times, as logs for a multi-session map.

A session is one recording: its own route and start point through the corridors, its own
odometry noise, its own lighting, and its own day (stamps start ``session`` days after the
plain demo log's). Its odometry starts at the identity (the robot's start pose is the
origin of its ``odom`` frame), so two sessions share no frame: a map must find how they
relate by loop closure. Ground truth stays in the world frame, which all sessions of one
world share; a session in another world publishes its ground truth in that world's frame
(:func:`world_frame`), so an evaluation can tell that no place is shared.

The presets (``make_demo_log(session=K)``, ``slam-lcd make-demo-log OUT --session K``):

== ======================= ======== ======== ========= ========== ======== ===== ========================
K  route                   start_at laps     seed      world_seed lighting expo  role
== ======================= ======== ======== ========= ========== ======== ===== ========================
1  laps of block A         3.0 m    1.3      1         0          0        1.0   mapping, its own loop
2  figure eight (A and B)  55.0 m   1.0      2         0          0        1.0   mapping, from north of B
3  figure eight (A and B)  26.0 m   0.9      3         0          3        0.75  mapping, changed lighting
4  laps of block A         3.0 m    1.3      4         1000       0        1.0   another building
5  laps of block A         24.0 m   1.0      5         0          0        1.0   localisation in 1-3
6  laps of block A         9.0 m    1.0      6         2000       0        1.0   look-alike world: P1
7  laps of block B (cw)    38.0 m   1.3      7         2000       0        1.0   look-alike world: P2
8  laps of block B (cw)    12.0 m   1.0      8         2000       0        1.0   localisation through P2
== ======================= ======== ======== ========= ========== ======== ===== ========================

``start_at``: arc length of the start point along the route's centre line
(:func:`slam_lcd.sim.trajectory.make_path`); ``lighting``: offset added to every frame's
lighting epoch; ``expo``: a global exposure factor of the renderer. Every preset records the
world in its ``day`` appearance; ``appearance=`` (``night``, ``moved``, ``renovated``:
:mod:`slam_lcd.sim.appearance`) records it in another. Every field is only a default: explicit
arguments override it.

World seeds 1000-1999 (:data:`slam_lcd.sim.world_seeds.OTHER_PLACE_SEED` on) are another
building on the demo corridors: lamps, floor and ceiling grids, wall materials, decal
sites, pillars and corner panels stand elsewhere, so session 4 shares neither textures nor
the 3-D places of its keypoints with sessions 1-3 (below 1000 only textures change).
World seeds from 2000 on (:data:`slam_lcd.sim.world_seeds.LOOKALIKE_SEED`) are the demo building
with its west corridor beside block A (P1) repeated as the east corridor beside block B (P2),
:mod:`slam_lcd.sim.lookalike`: sessions 6-8 record it. Session 6 drives through P1 and never
P2, session 7 through P2 and never P1, both north through the middle corridor; session 8, to
be localised in their map, drives through P2.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..errors import InputError
from .world_seeds import LOOKALIKE_SEED

DAY_NS = 86_400 * 1_000_000_000


@dataclass(frozen=True)
class SessionPreset:
    """Defaults one session sets (each overridable by an explicit argument)."""

    session: int
    kind: str  # route: 'laps' (block A), 'figure8' (A and B) or 'laps-b' (block B, clockwise)
    start_at: float  # arc length (m) of the start point along the route's centre line
    laps: float
    seed: int  # path weave, odometry noise and image noise
    world_seed: int  # the world's textures and lighting
    lighting: float  # offset added to the lighting epoch of every frame
    exposure: float  # global exposure factor of the renderer
    role: str
    appearance: str = "day"  # the world's appearance state (slam_lcd.sim.appearance)

    def describe(self) -> str:
        route = {"laps": "laps of block A", "figure8": "figure eight around A and B",
                 "laps-b": "laps of block B (clockwise)"}.get(self.kind, self.kind)
        return (f"session {self.session}: {self.role}; {self.laps:g} {route} from {self.start_at:g} m, seed "
                f"{self.seed}, world {self.world_seed}, lighting +{self.lighting:g}, exposure {self.exposure:g}")


SESSIONS: dict[int, SessionPreset] = {
    1: SessionPreset(1, "laps", 3.0, 1.3, 1, 0, 0.0, 1.0, "mapping, with a loop of its own"),
    2: SessionPreset(2, "figure8", 55.0, 1.0, 2, 0, 0.0, 1.0, "mapping, figure eight from the corridor north of B"),
    3: SessionPreset(3, "figure8", 26.0, 0.9, 3, 0, 3.0, 0.75, "mapping, figure eight under changed lighting"),
    4: SessionPreset(4, "laps", 3.0, 1.3, 4, 1000, 0.0, 1.0,
                     "another world, another building on the same corridors: shares no place with 1-3"),
    5: SessionPreset(5, "laps", 24.0, 1.0, 5, 0, 0.0, 1.0, "localisation inside the area of 1-3"),
    6: SessionPreset(6, "laps", 9.0, 1.0, 6, LOOKALIKE_SEED, 0.0, 1.0,
                     "look-alike world, mapping: the west corridor (P1), never the east one (P2)"),
    7: SessionPreset(7, "laps-b", 38.0, 1.3, 7, LOOKALIKE_SEED, 0.0, 1.0,
                     "look-alike world, mapping: P2 (P1's look-alike) once, the middle corridor shared with 6 twice"),
    8: SessionPreset(8, "laps-b", 12.0, 1.0, 8, LOOKALIKE_SEED, 0.0, 1.0,
                     "look-alike world, localisation in the map of 6 and 7 through P2"),
}


def session_preset(session: int) -> SessionPreset:
    """The preset of ``session`` (1-8); an InputError names the valid ones otherwise."""
    if session not in SESSIONS:
        raise InputError(f"unknown session {session!r}; use one of {', '.join(map(str, SESSIONS))}")
    return SESSIONS[session]


def session_start_ns(session: int) -> int:
    """First stamp of a session: ``session`` days after the plain demo log's."""
    from .trajectory import START_NS  # lazy: numpy, which the presets do without (the command line reads them)

    return START_NS + int(session) * DAY_NS


def world_frame(world_seed: int) -> str:
    """Frame of a session's ground truth: ``world`` for world 0, ``world_<seed>`` for another world."""
    from . import rig  # lazy: numpy, which the presets do without (the command line reads them)

    return rig.WORLD_FRAME if int(world_seed) == 0 else f"{rig.WORLD_FRAME}_{int(world_seed)}"
