"""Appearance states of the demo world: same geometry, other textures and light, and SuperPoint sees the change.

A lifelong map keeps a new keyframe as an appearance variant when fewer than 30 % of the poorer
keyframe's descriptors are mutual nearest neighbours of a kept keyframe of its place
(:func:`slam_lcd.map.places.alike_ratio`, ``map.redundant_match_ratio``). The states exist so that
this happens: ``renovated`` at the same pose, ``night`` from a pose a little off, as a revisit is;
while two views of one state stay far above it.
"""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.errors import InputError
from slam_lcd.sim import T_body_camera, build_world, demo_camera, make_demo_log, make_path, render
from slam_lcd.sim.appearance import APPEARANCES, RENOVATED_X
from slam_lcd.sim.image_noise import add_noise, noise_bank

CAM = demo_camera(320, 240)
TBC = T_body_camera()


def _east_poses(dy: float = 0.0, dyaw_deg: float = 0.0) -> list[np.ndarray]:
    """Camera poses along the clockwise laps of block B in the renovated east half (optionally moved
    ``dy`` m to the left and turned ``dyaw_deg``: a revisit's offset)."""
    path = make_path("laps-b", laps=1.0, seed=0)
    c, s = np.cos(np.radians(dyaw_deg)), np.sin(np.radians(dyaw_deg))
    D = np.eye(4)
    D[:2, :2] = [[c, -s], [s, c]]
    D[1, 3] = dy
    return [path.pose_at(t)[0] @ D @ TBC for t in np.linspace(12.0, 31.0, 5)]


def _views(state: str, poses, noise: int) -> list[np.ndarray]:
    bank = noise_bank(noise, (CAM.height, CAM.width))
    return [add_noise(render(build_world(0, state), CAM, T, with_depth=False)[0], bank[i]) for i, T in enumerate(poses)]


def test_day_is_the_world_built_without_a_state():
    assert build_world(0, "day") is build_world(0)
    assert build_world(0).appearance == "day"
    with pytest.raises(InputError, match="unknown appearance"):
        build_world(0, "dusk")


@pytest.mark.parametrize("state", [s for s in APPEARANCES if s != "day"])
def test_a_state_keeps_the_geometry_and_changes_what_is_seen(state):
    day, other = build_world(0), build_world(0, state)
    assert other.appearance == state
    assert [p.name for p in other.planes] == [p.name for p in day.planes]
    assert np.array_equal(other.corners, day.corners)
    assert np.array_equal(other.lamp_gains, day.lamp_gains)  # the lighting epochs dim the same lamps
    change = []
    for T in _east_poses():
        img_day, depth_day = render(day, CAM, T)
        img, depth = render(other, CAM, T)
        assert np.array_equal(depth, depth_day)
        change.append(np.abs(img.astype(int) - img_day.astype(int)).mean())
    assert max(change) > 4.0, change


def test_the_renovation_stays_east_of_its_line():
    west = make_path("laps", laps=1.0, seed=0)  # block A's laps: north up the west corridor
    T = west.pose_at(30.0)[0] @ TBC
    assert T[0, 3] < 3.0 and abs(T[1, 2]) > 0.9  # in the west corridor, looking along it
    day, _ = render(build_world(0), CAM, T, with_depth=False)
    new, _ = render(build_world(0, "renovated"), CAM, T, with_depth=False)
    assert np.array_equal(day, new)
    assert all(site["centre"][0] < RENOVATED_X for site in build_world(0, "renovated").alias_sites)


def test_a_session_log_in_a_state(tmp_path):
    info = make_demo_log(tmp_path / "s.mcap", "mcap", frames=3, width=160, height=120, session=3, appearance="night")
    assert info.appearance == "night" and "appearance: night" in info.summary()
    with pytest.raises(InputError, match="unknown appearance"):
        make_demo_log(tmp_path / "x.mcap", "mcap", frames=3, width=160, height=120, appearance="dusk")


def test_superpoint_needs_a_variant_in_the_strong_states(superpoint_weights):
    from slam_lcd.features import FeaturesConfig, load_extractor
    from slam_lcd.map.places import alike_ratio

    ex = load_extractor(FeaturesConfig(weights=str(superpoint_weights), device="cpu"))

    def descriptors(state, poses, noise):
        return [f.descriptors for f in ex.extract_batch(_views(state, poses, noise))]

    def ratio(a, b) -> float:
        return float(np.median([alike_ratio(x, y) for x, y in zip(a, b, strict=True)]))

    poses, off = _east_poses(), _east_poses(dy=0.4, dyaw_deg=6.0)
    day = descriptors("day", poses, 1)
    renovated = descriptors("renovated", poses, 1)
    # same pose, other image noise: the same state matches almost entirely; the renovated walls do not
    assert ratio(day, descriptors("day", poses, 2)) > 0.9
    assert ratio(renovated, descriptors("renovated", poses, 2)) > 0.9
    assert ratio(day, renovated) < 0.2
    # a revisit 0.4 m and 6 deg off: day still matches day; night does not
    assert ratio(day, descriptors("day", off, 2)) > 0.4
    assert ratio(day, descriptors("night", off, 2)) < 0.25
    # posters moved: a mild change, still above the threshold at the same pose
    assert ratio(day, descriptors("moved", poses, 2)) > 0.3
