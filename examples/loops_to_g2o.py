"""Example (b): verified loops written as a g2o file for a user's offline solver.

A user with their own trajectory (any odometry) and our loop closures writes one g2o file:
``VERTEX_SE3:QUAT`` per keyframe (the odometry pose), ``EDGE_SE3:QUAT`` per odometry step
and per loop (``T_match_query`` with its information, converted to g2o's ``[t, r]`` order).
g2o, Ceres, GTSAM's ``readG2o`` or slam-lcd's :func:`~slam_lcd.backend.read_g2o` read it.

    python examples/loops_to_g2o.py out.g2o    # demo world keyframes, our detector's loops
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from slam_lcd.backend.g2o import G2oEdge, write_g2o
from slam_lcd.backend.loop_factors import closure_edges
from slam_lcd.geometry import inv


def write_loops_g2o(path, ids: list[int], odometry: np.ndarray, odom_information: np.ndarray, closures) -> int:
    """Keyframes ``ids`` with odometry poses ``(N, 4, 4)``, a chain of odometry edges, and the loops.

    Returns the number of edges written. Vertex ids are the keyframe ids.
    """
    edges = [G2oEdge(ids[k - 1], ids[k], inv(odometry[k - 1]) @ odometry[k], odom_information)
             for k in range(1, len(ids))]
    edges += closure_edges(closures)
    write_g2o(path, {kid: odometry[k] for k, kid in enumerate(ids)}, edges)
    return len(edges)


def main(argv=None) -> int:
    import argparse
    import os

    from slam_lcd.errors import SlamLcdError
    from slam_lcd.features import FeaturesConfig, load_extractor
    from slam_lcd.lcd import LcdConfig, LoopDetector
    from slam_lcd.sim import simulate_odometry
    from slam_lcd.sim.keyframes import demo_keyframes
    from slam_lcd.types import Trajectory

    ap = argparse.ArgumentParser(description="demo-world loops + odometry as a g2o file")
    ap.add_argument("out", help="g2o file to write")
    ap.add_argument("--weights", default=os.environ.get("SLAM_LCD_SUPERPOINT_WEIGHTS"), help="SuperPoint weights")
    args = ap.parse_args(argv)
    try:
        ex = load_extractor(FeaturesConfig(kind="superpoint"), weights=args.weights, device="cpu")
        dk = demo_keyframes(ex)
        odom = simulate_odometry(Trajectory(dk.gt.stamps, dk.gt.poses)).poses
        det = LoopDetector(LcdConfig(exclude_recent_s=20.0, exclude_recent_n=0), extractor=ex)
        closures = [c for kf in dk.keyframes for c in det.add(kf)]
        info = np.diag(1.0 / np.array([1e-3, 1e-3, 0.01, 0.03, 0.03, 1e-3]) ** 2)
        n = write_loops_g2o(args.out, [kf.id for kf in dk.keyframes], odom, info, closures)
    except SlamLcdError as e:
        print(f"loops_to_g2o: {e}", file=sys.stderr)
        return 2
    print(f"{args.out}: {len(dk.keyframes)} vertices, {n} edges ({len(closures)} loops)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
