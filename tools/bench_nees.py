"""NEES of loop information on the demo world (exact ground truth): is the claimed uncertainty honest?

For every loop the detector accepts on demo-world keyframes (2 laps, 1 Hz, 320x240), the
error ``xi = Log(T_gt^-1 T_match_query)`` (right perturbation, [rx ry rz tx ty tz]) and its
normalised squared size ``NEES = xi^T Info xi``. Honest information gives NEES ~ chi2(6):
median 5.35, 1 % above the 99 % bound 16.81. Prints the figures for the RGB-D and the
stereo keyframes, with the claimed 1-sigma against the actual error.

    python tools/bench_nees.py [--laps 2] [--sensor rgbd stereo]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--laps", type=float, default=2.0)
    ap.add_argument("--size", default="320x240")
    ap.add_argument("--sensor", nargs="+", default=["rgbd", "stereo"], choices=["rgbd", "stereo"])
    ap.add_argument("--weights", default=os.environ.get("SLAM_LCD_SUPERPOINT_WEIGHTS"))
    args = ap.parse_args(argv)
    from slam_lcd.features import FeaturesConfig, load_extractor
    from slam_lcd.lcd.nees import demo_loop_nees

    w, h = (int(x) for x in args.size.split("x"))
    ex = load_extractor(FeaturesConfig(kind="superpoint"), weights=args.weights, device="cpu")
    for sensor in args.sensor:
        t0 = time.perf_counter()
        rep = demo_loop_nees(ex, sensor=sensor, laps=args.laps, width=w, height=h)
        print(f"[{sensor}] {rep.summary()}  ({time.perf_counter() - t0:.0f} s)")
        for line in rep.detail_lines():
            print("   " + line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
