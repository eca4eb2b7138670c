#!/usr/bin/env python3
"""Time slam-lcd's trajectory reading + ATE against evo's on the shared real trajectories.

Prints, for each case, the wall time of slam-lcd and of evo (same machine, same run), the
ratio, and both RMSE figures (they must agree to 1e-4). Usage:
    python tools/bench_eval.py [--shared ../shared] [--repeat 3]
"""
from __future__ import annotations

import argparse
import copy
import functools
import os
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from slam_lcd.eval import ate  # noqa: E402
from slam_lcd.io.trajectory_files import read_trajectory  # noqa: E402

CASES = [
    # name, reference, estimate, evo reader, alignment, t_max_diff
    ("KITTI 00 ORB, SE(3)", "KITTI_00_gt.txt", "KITTI_00_ORB.txt", "kitti", "se3"),
    ("fr2/desk ORB, Sim(3)", "fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt", "tum", "sim3"),
    ("V1_02 (EuRoC csv), Sim(3)", "V102_groundtruth.csv", "V102.txt", "euroc", "sim3"),
]


def ours(d: Path, ref: str, est: str, mode: str) -> float:
    return ate(read_trajectory(d / ref), read_trajectory(d / est), mode, t_max_diff=0.01).rmse


def theirs(d: Path, ref: str, est: str, kind: str, mode: str) -> float:
    from evo.core import metrics, sync
    from evo.tools import file_interface as fi

    if kind == "kitti":
        r, e = fi.read_kitti_poses_file(str(d / ref)), fi.read_kitti_poses_file(str(d / est))
    else:
        r = fi.read_euroc_csv_trajectory(str(d / ref)) if kind == "euroc" else fi.read_tum_trajectory_file(str(d / ref))
        e = fi.read_tum_trajectory_file(str(d / est))
        r, e = sync.associate_trajectories(r, e, max_diff=0.01)
    e = copy.deepcopy(e)
    e.align(r, correct_scale=mode == "sim3")
    m = metrics.APE(metrics.PoseRelation.translation_part)
    m.process_data((r, e))
    return m.get_statistic(metrics.StatisticsType.rmse)


def best_time(fn, repeat: int) -> tuple[float, float]:
    times, value = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        value = fn()
        times.append(time.perf_counter() - t0)
    return min(times), value


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shared", default=os.environ.get("SLAM_LCD_SHARED", str(REPO.parent / "shared")))
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    d = Path(args.shared) / "data" / "trajectories"
    if not d.is_dir():
        print(f"no shared trajectories at {d}", file=sys.stderr)
        return 2
    print(f"{'case':28s} {'slam-lcd s':>10s} {'evo s':>8s} {'ratio':>6s}  {'slam-lcd RMSE':>15s} {'evo RMSE':>15s}")
    for name, ref, est, kind, mode in CASES:
        t_ours, v_ours = best_time(functools.partial(ours, d, ref, est, mode), args.repeat)
        t_evo, v_evo = best_time(functools.partial(theirs, d, ref, est, kind, mode), args.repeat)
        print(f"{name:28s} {t_ours:10.3f} {t_evo:8.3f} {t_ours / t_evo:6.2f}  {v_ours:15.9f} {v_evo:15.9f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
