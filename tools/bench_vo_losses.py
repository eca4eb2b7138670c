"""Tracking losses and ATE of the built-in visual odometry on demo logs in the dataset layouts.

Writes each log once (``slam-lcd make-demo-log LOG --session S --layout L --size WxH --rate R``,
kept in ``--dir`` and reused), runs the VO alone the way ``slam-lcd run --config PRESET``
drives it (the preset's topics; the EuRoC layout's camchain file as ``--calib``) and prints
one row per log: frames, tracking losses (new segments, the "visual odometry lost tracking"
warnings), frames without a pose, relocalised frames, the VO's ATE against the log's ground
truth (SE(3)-aligned RMSE; translation only for EuRoC's position-only ground truth) and the
time. Usage:

    python tools/bench_vo_losses.py [--dir /tmp/vo_logs] [--set frontend.KEY=VALUE ...] \\
        [--logs tum:1:320x240:10 euroc:3:640x480:30 ...]

Without ``--logs`` the table of ``docs/frontend.md`` is measured (TUM and EuRoC layouts at
320x240, 5/10/30 Hz, sessions 1 and 3; KITTI session 3 at 10 Hz; TUM session 1 and EuRoC
session 3 at 640x480, 30 Hz).
"""
from __future__ import annotations

import argparse
import logging
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from slam_lcd.config import load_config
from slam_lcd.eval.metrics import ate
from slam_lcd.io import open_log
from slam_lcd.run.sources import calibrated_camera, calibration_of, ground_truth_tf, odometry_and_stereo
from slam_lcd.runtime.machine import machine_line
from slam_lcd.sensors.ground_truth import decode_ground_truth
from slam_lcd.sensors.topics import choose_topics, configured_topics
from slam_lcd.types import Trajectory

PRESETS = {"tum": "tum-rgbd", "euroc": "euroc", "kitti": "kitti"}
DOC_TABLE = ([f"{lay}:{s}:320x240:{r}" for lay in ("tum", "euroc") for s in (1, 3) for r in (5, 10, 30)]
             + ["kitti:3:320x240:10", "tum:1:640x480:30", "euroc:3:640x480:30"])


def make_log(folder: Path, layout: str, session: str, size: str, rate: str) -> Path:
    path = folder / f"{layout}_s{session}_{size}_r{rate}.bag"
    if not path.exists():
        subprocess.run([sys.executable, "-m", "slam_lcd", "make-demo-log", str(path), "--session", session,
                        "--layout", layout, "--size", size, "--rate", rate, "--no-progress"], check=True,
                       stdout=subprocess.DEVNULL)
    return path


def ground_truth(reader, topics) -> Trajectory:
    """The log's ground truth: a TF chain, or a pose / point topic."""
    gt = ground_truth_tf(reader, topics)
    if gt is not None:
        return gt
    stamps, poses = [], []
    for m in reader.messages([topics.gt]):
        stamps.append(m.stamp)
        poses.append(decode_ground_truth(m))
    order = np.argsort(stamps, kind="stable")
    return Trajectory(np.asarray(stamps, np.int64)[order], np.asarray(poses)[order])


def measure(path: Path, layout: str, overrides: list[str]) -> dict:
    cfg = load_config(PRESETS[layout], overrides)
    camchain = path.with_name(f"camchain-{path.stem}.yaml")
    calibration = calibration_of([camchain] if layout == "euroc" else None)
    t0 = time.perf_counter()
    with open_log(path, conf=cfg.io) as reader:
        flags = configured_topics(reader, cfg.sensors)
        right_topic = flags.pop("right_topic")
        topics = choose_topics(reader, **flags)
        calibrated = calibrated_camera(calibration, topics, path)
        vo, _, _ = odometry_and_stereo(reader, topics, right_topic, cfg, calibration, calibrated, path)
        gt = ground_truth(reader, topics)
    seconds = time.perf_counter() - t0
    res = vo.result
    status = [f.status for f in res.frames]
    return {"frames": len(status), "losses": res.n_segments - 1, "lost": status.count("lost"),
            "relocalised": status.count("relocalised"), "ate": ate(gt, res.trajectory(), "se3").rmse,
            "seconds": seconds}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--dir", type=Path, default=Path("/tmp/vo_logs"), help="where the logs are written and reused")
    ap.add_argument("--logs", nargs="*", default=DOC_TABLE, help="LAYOUT:SESSION:WxH:RATE (default: the docs table)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="config override (frontend.KEY=V)")
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    args.dir.mkdir(parents=True, exist_ok=True)
    print("| layout | session | size | rate | frames | losses | lost frames | relocalised | VO ATE (m) | time (s) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for spec in args.logs:
        layout, session, size, rate = spec.split(":")
        r = measure(make_log(args.dir, layout, session, size, rate), layout, args.overrides)
        print(f"| {layout} | {session} | {size} | {rate} Hz | {r['frames']} | {r['losses']} | {r['lost']} | "
              f"{r['relocalised']} | {r['ate']:.3f} | {r['seconds']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
