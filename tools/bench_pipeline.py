"""Time per stage and overall rate of `slam-lcd run` on the demo log.

Prints, for one run: seconds and calls per stage (decode, features, keyframe selection,
loop detection, back end), keyframes per second, and log seconds per wall second.

    python tools/bench_pipeline.py [--frames N] [--weights W] [--features superpoint|orb] [--no-cache]
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=None, help="demo frames (default: the full ~2-lap demo)")
    ap.add_argument("--weights", default=os.environ.get("SLAM_LCD_SUPERPOINT_WEIGHTS"))
    ap.add_argument("--features", default="superpoint", choices=["superpoint", "orb"])
    ap.add_argument("--no-cache", action="store_true", help="do not use (or fill) the on-disk feature cache")
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    args = ap.parse_args()
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named

    from slam_lcd.config import load_config
    from slam_lcd.run import OutputOptions, run_log
    from slam_lcd.sim.demo_cache import ensure_demo_log

    overrides = [f"features.kind={args.features}", *args.overrides]
    if args.weights:
        overrides.append(f"features.weights={args.weights}")
    if args.no_cache:
        overrides.append("features.feature_cache=false")
    cfg = load_config("default", overrides)
    t0 = time.perf_counter()
    log = ensure_demo_log(frames=args.frames, progress=False)
    t_log = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as out:
        res = run_log(log, out, cfg, output=OutputOptions(progress=False))
    print(f"demo log: {log} (ready in {t_log:.1f} s)")
    print(f"{'stage':<20} {'seconds':>9} {'calls':>7} {'ms/call':>9}")
    for k, v in sorted(res.stages.items(), key=lambda kv: -kv[1]["seconds"]):
        ms = 1000 * v["seconds"] / max(v["calls"], 1)
        print(f"{k:<20} {v['seconds']:>9.2f} {v['calls']:>7d} {ms:>9.1f}")
    print(f"overall: {res.wall_s:.1f} s wall, {res.n_frames} frames, {res.n_keyframes} keyframes "
          f"-> {res.n_keyframes / res.wall_s:.2f} keyframes/s, {res.n_frames / res.wall_s:.2f} frames/s, "
          f"{res.log_duration_s / res.wall_s:.3f} log s per wall s")
    for line in res.summary_lines():
        print(line)


if __name__ == "__main__":
    main()
