#!/usr/bin/env python
"""Write a PNG mosaic of what the demo camera sees, so a person can check the world.

Top rows: frames along the default trajectory (first lap, and the same places on the second
lap, with the lighting change); bottom row: depth (colour-mapped) of some of them, the
figure-eight path, and a top view of the map with the trajectory and odometry drift.

    python tools/show_demo_frames.py [OUT.png] [--seed 0] [--color]
"""
from __future__ import annotations

import argparse

import cv2
import numpy as np

from slam_lcd.sim import (
    T_body_camera,
    build_world,
    demo_camera,
    gt_loop_pairs,
    make_path,
    make_trajectory,
    render,
    simulate_odometry,
)
from slam_lcd.sim.trajectory import START_NS
from slam_lcd.sim.world import BLOCKS, OUTER
from slam_lcd.vision.gray import to_gray_uint8


def label(img, text):
    img = img.copy()
    cv2.rectangle(img, (0, 0), (img.shape[1], 22), (0, 0, 0), -1)
    cv2.putText(img, text, (5, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def top_view(gt, odom, pairs, size=(320, 240)):
    W, H = size
    s = min((W - 20) / OUTER[2], (H - 20) / OUTER[3])
    img = np.full((H, W, 3), 255, np.uint8)

    def px(x, y):
        return int(10 + x * s), int(H - 10 - y * s)

    cv2.rectangle(img, px(OUTER[0], OUTER[1]), px(OUTER[2], OUTER[3]), (0, 0, 0), 2)
    for b in BLOCKS:
        cv2.rectangle(img, px(b[0], b[1]), px(b[2], b[3]), (120, 120, 120), -1)
    for traj, col in ((gt, (0, 150, 0)), (odom, (220, 0, 0))):
        pts = np.array([px(x, y) for x, y in traj.positions[:, :2]], np.int32)
        cv2.polylines(img, [pts], False, col, 1, cv2.LINE_AA)
    return label(img, f"top view: gt (green) odom (red), {len(pairs)} loop pairs")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default="demo_frames.png")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--color", action="store_true")
    args = ap.parse_args()
    world = build_world(args.seed)
    cam = demo_camera()
    Tbc = T_body_camera()
    path = make_path("laps", seed=args.seed)
    gt = make_trajectory("laps", seed=args.seed)
    tiles, depths = [], []
    half = len(gt) // 2
    for i in (60, 150, 260, 360, 60 + half, 150 + half):
        t = (gt.stamps[i] - START_NS) * 1e-9
        lap = float(path.laps_at(t))
        img, dep = render(world, cam, gt.poses[i] @ Tbc, epoch=lap, color=True)
        tiles.append(label(img if args.color else cv2.cvtColor(to_gray_uint8(img), cv2.COLOR_GRAY2RGB),
                           f"frame {i}  lap {lap:.2f}"))
        depths.append(dep)

    def small(im):
        return cv2.resize(im, (320, 240), interpolation=cv2.INTER_AREA)

    dep_tiles = []
    for k in (0, 2):
        d = np.clip(depths[k] / 12.0, 0, 1)
        coloured = cv2.applyColorMap((255 * (1 - d)).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1]
        dep_tiles.append(label(small(coloured), "depth 0-12 m"))
    gt50 = make_trajectory("laps", seed=args.seed, rate_hz=50.0)
    odom = simulate_odometry(gt50, seed=args.seed)
    pairs = gt_loop_pairs(gt, T_body_camera=Tbc)
    f8 = make_trajectory("figure8", laps=1.0)
    tv = top_view(gt50, odom, pairs)
    f8v = top_view(f8, f8, np.zeros((0, 2)))
    f8v = label(f8v, "figure-eight path")
    top = np.hstack([cv2.resize(t, (480, 360), interpolation=cv2.INTER_AREA) for t in tiles[:3]])
    mid = np.hstack([cv2.resize(t, (480, 360), interpolation=cv2.INTER_AREA) for t in tiles[3:]])
    bottom = np.hstack(dep_tiles + [tv, f8v])
    bottom = np.hstack([bottom, np.full((240, top.shape[1] - bottom.shape[1], 3), 255, np.uint8)])
    mosaic = np.vstack([top, mid, bottom])
    cv2.imwrite(args.out, cv2.cvtColor(mosaic, cv2.COLOR_RGB2BGR))
    print(f"wrote {args.out} ({mosaic.shape[1]}x{mosaic.shape[0]})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
