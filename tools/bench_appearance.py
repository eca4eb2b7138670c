#!/usr/bin/env python
"""How far each appearance state of the demo world is from ``day``, in the map's own measure.

A lifelong map keeps a new keyframe as an appearance variant when less than
``map.redundant_match_ratio`` (0.3) of the poorer keyframe's descriptors are mutual nearest
neighbours of a kept keyframe of its place (:func:`slam_lcd.map.places.alike_ratio`). This tool
renders views of one route (session 2's figure eight, both blocks) in every state, extracts
SuperPoint, and prints the median ratio of same-place pairs:

- *same pose*: the state against ``day`` at identical camera poses (other image noise), and the
  state against itself (other image noise): what the state alone changes;
- *nearby pose*: the same route driven with another weave (``--seed``): each view paired with the
  nearest view of the other drive within 1 m and 20 deg, in the state against ``day`` and against
  itself: the pairs a map meets.

``renovated`` changes the east half only: its rows are given over the whole route and over the
views from the east half (camera x >= 12.5 m).

    python tools/bench_appearance.py --weights W.pth [--views 40] [--size 320x240]
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def render_views(state: str, poses: list[np.ndarray], cam, noise_seed: int) -> list[np.ndarray]:
    """Gray views of the demo world (seed 0) in ``state`` at camera poses ``poses``, with image noise."""
    from slam_lcd.sim import build_world, render
    from slam_lcd.sim.image_noise import NOISE_BANK, add_noise, noise_bank

    world = build_world(0, state)
    bank = noise_bank(noise_seed, (cam.height, cam.width))
    return [add_noise(render(world, cam, T, with_depth=False)[0], bank[i % NOISE_BANK]) for i, T in enumerate(poses)]


def ratios(extractor, a: list[np.ndarray], b: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """alike_ratio of each pair (a[i], b[i]), and the keypoint counts of a."""
    from slam_lcd.map.places import alike_ratio

    fa, fb = extractor.extract_batch(a), extractor.extract_batch(b)
    return (np.array([alike_ratio(x.descriptors, y.descriptors) for x, y in zip(fa, fb, strict=True)]),
            np.array([len(x.descriptors) for x in fa]))


def route_poses(seed: int, views: int, width: int, height: int):
    """Camera poses of ``views`` frames spread along session 2's route driven with ``seed``, and all of its poses."""
    from slam_lcd.sim.demo_log import session_scenario

    sc = session_scenario(2, seed=seed, width=width, height=height)
    every = np.array([T @ sc.T_bc for T in sc.gt_cam.poses])
    pick = np.linspace(0, len(every) - 1, views).round().astype(int)
    return sc, every, pick


def nearby_pairs(sc_a, pick_a, sc_b) -> tuple[np.ndarray, np.ndarray]:
    """For each picked frame of drive a, the nearest frame of drive b within 1 m and 20 deg (kept: those found)."""
    from slam_lcd.sim import gt_cross_pairs

    pairs = gt_cross_pairs(sc_a.gt_cam, sc_b.gt_cam, T_body_camera=sc_a.T_bc)
    pa, pb = sc_a.gt_cam.poses[:, :3, 3], sc_b.gt_cam.poses[:, :3, 3]
    keep_a, keep_b = [], []
    for i in pick_a:
        cand = pairs[pairs[:, 0] == i, 1]
        if len(cand):
            keep_a.append(i)
            keep_b.append(int(cand[np.argmin(np.linalg.norm(pb[cand] - pa[i], axis=1))]))
    return np.array(keep_a), np.array(keep_b)


def row(label: str, r: np.ndarray) -> str:
    return (f"{label:44s} median {np.median(r):.3f}  p10 {np.percentile(r, 10):.3f}  "
            f"p90 {np.percentile(r, 90):.3f}  (n = {len(r)})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--weights", required=True)
    ap.add_argument("--views", type=int, default=40)
    ap.add_argument("--size", default="320x240")
    ap.add_argument("--seed", type=int, default=12, help="weave of the second drive (nearby-pose pairs)")
    ap.add_argument("--states", default="night,moved,renovated")
    args = ap.parse_args()
    from slam_lcd.config import load_config
    from slam_lcd.features import load_extractor
    from slam_lcd.runtime.machine import machine_line
    from slam_lcd.sim import demo_camera
    from slam_lcd.sim.appearance import RENOVATED_X

    print(machine_line(), flush=True)
    w, h = (int(v) for v in args.size.split("x"))
    cam = demo_camera(w, h)
    extractor = load_extractor(load_config("default", [f"features.weights={args.weights}"]).features)
    sc_a, every_a, pick = route_poses(2, args.views, w, h)
    sc_b, every_b, _ = route_poses(args.seed, args.views, w, h)
    ia, ib = nearby_pairs(sc_a, pick, sc_b)
    east = every_a[pick, 0, 3] >= RENOVATED_X
    east_near = every_a[ia, 0, 3] >= RENOVATED_X
    t0 = time.perf_counter()
    day = render_views("day", list(every_a[pick]), cam, 1)
    day_near = render_views("day", list(every_b[ib]), cam, 2)
    same, n_day = ratios(extractor, day, render_views("day", list(every_a[pick]), cam, 2))
    print(f"SuperPoint at {w}x{h}, {len(pick)} views along session 2's figure eight, {len(ia)} with a nearby "
          f"view of the drive with seed {args.seed}; keypoints per day view: median {np.median(n_day):.0f}")
    print(row("day vs day, same pose", same))
    print(row("day vs day, nearby pose", ratios(extractor, [day[list(pick).index(i)] for i in ia], day_near)[0]))
    for state in args.states.split(","):
        views = render_views(state, list(every_a[pick]), cam, 2)
        again = render_views(state, list(every_a[pick]), cam, 3)
        near = render_views(state, list(every_b[ib]), cam, 2)
        vs_day, n = ratios(extractor, views, day)
        own, _ = ratios(extractor, views, again)
        sel = [list(pick).index(i) for i in ia]
        near_day, _ = ratios(extractor, [day[j] for j in sel], near)
        near_own, _ = ratios(extractor, [views[j] for j in sel], near)
        print(f"{state} (keypoints per view: median {np.median(n):.0f})")
        print(row(f"  {state} vs day, same pose", vs_day))
        print(row(f"  {state} vs {state}, same pose", own))
        print(row(f"  {state} vs day, nearby pose", near_day))
        print(row(f"  {state} vs {state}, nearby pose", near_own))
        if state == "renovated":
            print(row("  east half: renovated vs day, same pose", vs_day[east]))
            print(row("  east half: renovated vs day, nearby pose", near_day[east_near]))
            print(row("  west half: renovated vs day, same pose", vs_day[~east]))
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
