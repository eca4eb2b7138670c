"""NEES of loop information on the demo world (exact ground truth): is the claimed uncertainty honest?

For every loop the detector accepts on demo-world keyframes (2 laps, 1 Hz, 320x240), the
error ``xi = Log(T_gt^-1 T_match_query)`` (right perturbation, [rx ry rz tx ty tz]) and its
normalised squared size ``NEES = xi^T Info xi``. Honest information gives NEES ~ chi2(6):
median 5.35, 1 % above the 99 % bound 16.81. Prints the figures for the RGB-D and the
stereo keyframes, with the claimed 1-sigma against the actual error.

    python tools/bench_nees.py [--laps 2] [--sensor rgbd stereo]
    python tools/bench_nees.py --run-dir OUT --log DEMO.mcap   # loops of a `slam-lcd demo` / run

With ``--run-dir`` the loops are those of a finished pipeline run (``graph.g2o``: the back
end's accepted loops with their information; ``loops.csv``: keyframe stamps) against the
ground-truth topic of its log.
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
    ap.add_argument("--run-dir", help="output folder of `slam-lcd demo` / `slam-lcd run`")
    ap.add_argument("--log", help="the log of that run (for its ground-truth topic)")
    args = ap.parse_args(argv)
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    if args.run_dir:
        rep = run_dir_nees(Path(args.run_dir), Path(args.log))
        print(f"[run {args.run_dir}] {rep.summary()}")
        for line in rep.detail_lines():
            print("   " + line)
        return 0
    from slam_lcd.features import FeaturesConfig, load_extractor
    from slam_lcd.sim.keyframes import demo_loop_nees

    w, h = (int(x) for x in args.size.split("x"))
    ex = load_extractor(FeaturesConfig(kind="superpoint"), weights=args.weights, device="cpu")
    for sensor in args.sensor:
        t0 = time.perf_counter()
        rep = demo_loop_nees(ex, sensor=sensor, laps=args.laps, width=w, height=h)
        print(f"[{sensor}] {rep.summary()}  ({time.perf_counter() - t0:.0f} s)")
        for line in rep.detail_lines():
            print("   " + line)
    return 0


def run_dir_nees(run_dir: Path, log: Path):
    """NEES of the accepted loops of a pipeline run (graph.g2o + loops.csv) against the log's ground truth."""
    import csv

    import numpy as np

    from slam_lcd.backend.g2o import read_g2o
    from slam_lcd.eval.nees import report
    from slam_lcd.geometry import interpolate_poses
    from slam_lcd.io import open_log
    from slam_lcd.io.decode import decode_pose
    from slam_lcd.types import LoopClosure

    stamp, pairs = {}, set()
    with open(run_dir / "loops.csv", newline="") as fh:
        for row in csv.DictReader(fh):
            q, m = int(row["query_id"]), int(row["match_id"])
            stamp[q], stamp[m] = int(row["query_stamp_ns"]), int(row["match_stamp_ns"])
            if row["backend_verdict"] == "accepted":
                pairs.add((q, m))
    _, edges = read_g2o(run_dir / "graph.g2o")
    loops = [LoopClosure(e.j, e.i, e.T_i_j, e.information, evidence={}) for e in edges if (e.j, e.i) in pairs]
    st, T = [], []
    with open_log(log) as reader:
        topic = next(t for t in reader.topics if "ground_truth" in t or "groundtruth" in t)
        for msg in reader.messages([topic]):
            st.append(int(msg.stamp))
            T.append(decode_pose(msg.msg)[0])
    order = np.argsort(st)
    ids = sorted(stamp)
    P = interpolate_poses(np.array(st)[order], np.array(T)[order], np.array([stamp[i] for i in ids], np.int64))
    return report(loops, dict(zip(ids, P, strict=True)))


if __name__ == "__main__":
    raise SystemExit(main())
