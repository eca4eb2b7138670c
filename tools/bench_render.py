#!/usr/bin/env python
"""Benchmark of the demo-world renderer (target: >= 20 frames/s at 640x480 on one core).

Renders frames along the default demo trajectory on ONE OpenCV thread and prints frames/s
from process CPU time (what one core delivers, robust to other load on the machine) and
from wall time, for gray, gray+depth, RGB, and a stereo pair; the baseline measured in
the same run is a plain full-frame ``cv2.warpPerspective`` of a 640x480 texture, i.e.
the cost floor of any warp-based renderer on this machine.

    python tools/bench_render.py [--frames 120] [--size 640x480]
"""
from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from slam_lcd.sim import T_body_camera, T_left_right, build_world, demo_camera, make_trajectory, render


def timed(fn, n):
    c0, w0 = time.process_time(), time.perf_counter()
    for i in range(n):
        fn(i)
    return (time.process_time() - c0) / n, (time.perf_counter() - w0) / n


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--size", default="640x480")
    args = ap.parse_args()
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    w, h = (int(v) for v in args.size.split("x"))
    cv2.setNumThreads(1)
    t0 = time.process_time()
    world = build_world(0)
    print(f"world build: {time.process_time() - t0:.2f} s CPU, {len(world.planes)} planes")
    cam = demo_camera(w, h)
    gt = make_trajectory("laps")
    idx = np.linspace(0, len(gt) - 1, args.frames).astype(int)
    T = [gt.poses[i] @ T_body_camera() for i in idx]
    T_lr = T_left_right()

    tex = np.random.default_rng(0).integers(0, 255, (h, w), dtype=np.uint8)
    H = np.array([[1.05, 0.02, -3.0], [0.01, 0.97, 2.0], [1e-5, 2e-5, 1.0]])
    base_cpu, base_wall = timed(lambda i: cv2.warpPerspective(tex, H, (w, h), flags=cv2.INTER_LINEAR), args.frames)
    print(f"baseline full-frame warpPerspective {w}x{h}: {base_cpu * 1e3:.2f} ms CPU ({1 / base_cpu:.0f}/s)")
    cases = {
        "gray": lambda i: render(world, cam, T[i], with_depth=False),
        "gray+depth": lambda i: render(world, cam, T[i]),
        "rgb+depth": lambda i: render(world, cam, T[i], color=True),
        "stereo gray (2 views)+depth": lambda i: (render(world, cam, T[i]),
                                                  render(world, cam, T[i] @ T_lr, with_depth=False)),
    }
    print(f"{'case':30s} {'ms/frame CPU':>12s} {'frames/s (1 core)':>18s} {'wall fps':>9s} {'x baseline':>10s}")
    for name, fn in cases.items():
        cpu, wall = timed(fn, args.frames)
        print(f"{name:30s} {cpu * 1e3:12.2f} {1 / cpu:18.1f} {1 / wall:9.1f} {cpu / base_cpu:10.1f}")
    cpu, _ = timed(cases["gray+depth"], args.frames)
    verdict = "PASS" if 1 / cpu >= 20 else "FAIL"
    print(f"target >= 20 frames/s at {w}x{h} gray+depth on one core: {1 / cpu:.1f} -> {verdict}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
