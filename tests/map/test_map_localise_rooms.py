"""Localisation where the log never travels far: turning in place, walking a small room.

Every fix is true. A fix is confirmed by a fix to another place, and the views of two walls of
one room are two places: map keyframes that look in directions ``map.localize_min_view_angle_deg``
apart count as distinct however close they stand. The logs are keyframed as the front end does
(every 0.5 m travelled or 15 degrees turned, ``frontend.kf_min_*``); the odometry turns 2 % too far
and walks 3 % too far, with noise on every step; each fix is good to about 2 cm and 0.3 degrees.
"""
from __future__ import annotations

import numpy as np
import pytest
from test_map_sessions import _closure

from slam_lcd.geometry import inv, make_T, so3_exp
from slam_lcd.map.config import MapConfig
from slam_lcd.map.localize import localise

STEP_M, STEP_DEG = 0.5, 15.0  # the front end's keyframe spacing (frontend.kf_min_translation, kf_min_rotation_deg)
# where the mapping session's keyframes stand relative to the log's: 0.1 m aside, 3 degrees off
MAP_OFFSET = make_T(so3_exp(np.radians([0.0, 0.0, 3.0])), np.array([0.05, 0.1, 0.0]))


def _yaw(deg: float) -> np.ndarray:
    return so3_exp(np.radians([0.0, 0.0, deg]))


def _turning(turns: float) -> np.ndarray:
    """Keyframe poses of a log turning in place, 15 degrees a keyframe."""
    n = int(round(turns * 360 / STEP_DEG)) + 1
    return np.array([make_T(_yaw(STEP_DEG * i), np.zeros(3)) for i in range(n)])


def _room(side: float, laps: int) -> np.ndarray:
    """Keyframe poses of a log walking along the walls of a square room: a keyframe every 0.5 m along a side,
    every 15 degrees of each corner's 90-degree turn (made standing)."""
    T = [make_T(np.eye(3), np.array([-side / 2, -side / 2, 0.0]))]
    for _ in range(4 * laps):
        for _ in range(int(round(side / STEP_M))):
            T.append(T[-1] @ make_T(np.eye(3), np.array([STEP_M, 0.0, 0.0])))
        for _ in range(int(round(90 / STEP_DEG))):
            T.append(T[-1] @ make_T(_yaw(STEP_DEG), np.zeros(3)))
    return np.array(T)


def _odometry(gt: np.ndarray, rng) -> np.ndarray:
    """The log's odometry: each step turned 2 % too far and walked 3 % too far, plus noise."""
    out = [np.eye(4)]
    for i in range(1, len(gt)):
        step = inv(gt[i - 1]) @ gt[i]
        yaw = np.degrees(np.arctan2(step[1, 0], step[0, 0])) * 1.02 + rng.normal(0, 0.5)
        t = step[:3, 3] * 1.03 + rng.normal(0, 0.01, 3)
        out.append(out[-1] @ make_T(_yaw(yaw), t))
    return np.array(out)


def _fix_noise(rng) -> np.ndarray:
    return make_T(so3_exp(np.radians(rng.normal(0, 0.3, 3))), rng.normal(0, 0.02, 3))


def _localised_share(gt: np.ndarray, n_map: int, seed: int, conf: MapConfig | None = None) -> tuple[float, float]:
    """Localise a log with a true fix at every keyframe, against a map of the same path's first ``n_map`` keyframes
    (0.1 m and 3 degrees beside it; keyframe i matches map keyframe i mod n_map). Returns the share localised and
    the largest position error of a localised keyframe (m)."""
    rng = np.random.default_rng(seed)
    n = len(gt)
    poses = {1000 + j: gt[j] @ MAP_OFFSET for j in range(n_map)}
    fixes = [_closure(i, 1000 + i % n_map, inv(poses[1000 + i % n_map]) @ gt[i] @ _fix_noise(rng)) for i in range(n)]
    loc = localise(poses, {k: "m" for k in poses}, {k: 0 for k in poses}, list(range(n)), list(range(n)),
                   _odometry(gt, rng), [None] * n, fixes, conf)
    err = [np.linalg.norm(k.T_map[:3, 3] - gt[k.kf_id][:3, 3]) for k in loc.keyframes if k.localised]
    return loc.share_localised, max(err, default=0.0)


def test_a_log_turning_in_place_localises_its_keyframes():
    gt = _turning(1.5)  # 37 keyframes; the map: one full turn at the same spot
    share, err = _localised_share(gt, 24, 1)
    print(f"turning in place: {100 * share:.0f} % of {len(gt)} keyframes localised, largest error {err:.2f} m")
    assert share >= 0.9 and err < 0.1
    # by position alone (the angle rule off) nothing is confirmed: every fix is to the same spot
    off, _ = _localised_share(gt, 24, 1, MapConfig(localize_min_view_angle_deg=360.0))
    assert off == 0.0


@pytest.mark.parametrize("side", [2.0, 3.0, 4.0])
def test_a_log_walking_a_small_room_localises_its_keyframes(side):
    gt = _room(side, 2)  # two laps; the map: the first
    n_map = len(_room(side, 1)) - 1
    share, err = _localised_share(gt, n_map, 2)
    off, _ = _localised_share(gt, n_map, 2, MapConfig(localize_min_view_angle_deg=360.0))
    print(f"walking a {side:g} x {side:g} m room: {100 * share:.0f} % of {len(gt)} keyframes localised "
          f"(by position alone {100 * off:.0f} %), largest error {err:.2f} m")
    assert share >= 0.9 and err < 0.15
