#!/usr/bin/env python3
"""Decode throughput of slam-lcd's log reader against plain rosbags, measured in one run.

Writes a log with 640x480 mono8 images (raw sensor_msgs/Image and JPEG CompressedImage),
then reads every image back to a numpy array twice:

- baseline: plain ``rosbags`` (Reader + deserialize_cdr/ros1 + np.frombuffer / cv2.imdecode),
- slam-lcd: ``open_log(...).messages(topic)`` + ``decode_image`` / ``decode_compressed_image``.

Runs alternate and the best of ``--repeat`` is kept for each; times are this process's CPU
time (``--wall`` for wall-clock), because on a shared machine wall time mostly measures the
neighbours' load. Both sides read the same file, so file-system caching is equal.
The overhead of slam-lcd's streaming layer is ``t_slam / t_rosbags - 1``; the target is
< 20 % for raw images. Usage: ``python tools/bench_io.py [--frames 200] [--formats mcap rosbag1]``.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from slam_lcd.io import message_builders as M  # noqa: E402
from slam_lcd.io import open_log  # noqa: E402
from slam_lcd.io.decode import decode_compressed_image, decode_image  # noqa: E402
from slam_lcd.io.writers import open_writer  # noqa: E402

RAW, JPEG = "/camera/image_raw", "/camera/image_raw/compressed"
# CPU time of this process: on a shared machine, wall time mostly measures the neighbours
CLOCK = time.process_time


def source_frames(n: int) -> list[np.ndarray]:
    """640x480 gray frames: real TUM fr2/desk frames if ../shared is there, else textured noise."""
    folder = REPO.parent / "shared" / "data" / "frames" / "tum_fr2_desk"
    files = sorted(folder.glob("*.png")) if folder.is_dir() else []
    base = [cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in files[:20]]
    base = [b for b in base if b is not None and b.shape == (480, 640)]
    if not base:
        rng = np.random.default_rng(0)
        base = [cv2.GaussianBlur(rng.integers(0, 256, (480, 640), dtype=np.uint8), (5, 5), 0) for _ in range(8)]
    return [base[i % len(base)] for i in range(n)]


def write_log(path: Path, fmt: str, frames: list[np.ndarray]) -> None:
    with open_writer(path, fmt) as w:
        for i, img in enumerate(frames):
            s = 1_000_000_000 + i * 33_333_333
            w.write(RAW, M.image_msg(img, s, "camera"), s)
            w.write(JPEG, M.compressed_image_msg(img, s, "camera", "jpeg"), s)


def rosbags_pass(path: Path, fmt: str, topic: str) -> int:
    """Plain rosbags: iterate, deserialise, make the numpy image. Returns a checksum."""
    from rosbags.highlevel import AnyReader

    total = 0
    with AnyReader([path]) as r:
        conns = [c for c in r.connections if c.topic == topic]
        deser = r.typestore.deserialize_ros1 if fmt == "rosbag1" else r.typestore.deserialize_cdr
        for c, _t, raw in r.messages(connections=conns):
            msg = deser(raw, c.msgtype)
            if topic == RAW:
                img = np.frombuffer(msg.data, np.uint8).reshape(msg.height, msg.width)
            else:
                img = cv2.imdecode(np.asarray(msg.data), cv2.IMREAD_UNCHANGED)
            total += int(img[0, 0])
    return total


def slam_pass(path: Path, fmt: str, topic: str) -> int:
    total = 0
    dec = decode_image if topic == RAW else decode_compressed_image
    with open_log(path) as r:
        for m in r.messages(topic):
            img = dec(m.msg)
            total += int(img[0, 0])
    return total


def bench(path: Path, fmt: str, topic: str, n: int, repeat: int) -> tuple[float, float]:
    best_b = best_s = float("inf")
    for _ in range(repeat):
        t = CLOCK()
        cb = rosbags_pass(path, fmt, topic)
        best_b = min(best_b, CLOCK() - t)
        t = CLOCK()
        cs = slam_pass(path, fmt, topic)
        best_s = min(best_s, CLOCK() - t)
        if cb != cs:
            raise SystemExit(f"checksum mismatch on {fmt} {topic}: rosbags {cb} vs slam-lcd {cs}")
    return n / best_b, n / best_s


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--formats", nargs="+", default=["mcap", "rosbag2", "rosbag1"],
                    choices=["mcap", "rosbag2", "rosbag1"])
    ap.add_argument("--wall", action="store_true", help="measure wall-clock instead of CPU time")
    args = ap.parse_args(argv)
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    global CLOCK
    if args.wall:
        CLOCK = time.perf_counter
    frames = source_frames(args.frames)
    names = {"mcap": "bench.mcap", "rosbag2": "bench_rosbag2", "rosbag1": "bench.bag"}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for fmt in args.formats:
            path = Path(tmp) / names[fmt]
            write_log(path, fmt, frames)
            for label, topic in (("raw mono8", RAW), ("jpeg", JPEG)):
                base, ours = bench(path, fmt, topic, len(frames), args.repeat)
                rows.append((fmt, label, base, ours))
    clock = "wall-clock" if args.wall else "CPU"
    print(f"decode throughput, {args.frames} images 640x480 per run, best of {args.repeat}, {clock} time")
    print(f"{'format':<8} {'images':<10} {'rosbags img/s':>14} {'slam-lcd img/s':>15} {'ratio':>7} {'overhead':>9}")
    worst_raw = 0.0
    for fmt, label, base, ours in rows:
        overhead = base / ours - 1.0
        if label.startswith("raw"):
            worst_raw = max(worst_raw, overhead)
        print(f"{fmt:<8} {label:<10} {base:>14.0f} {ours:>15.0f} {ours / base:>7.2f} {overhead * 100:>8.1f}%")
    verdict = "PASS" if worst_raw < 0.20 else "FAIL"
    print(f"raw-image streaming overhead (worst format): {worst_raw * 100:.1f}% (target < 20%): {verdict}")
    return 0 if verdict == "PASS" else 1


if __name__ == "__main__":
    sys.exit(main())
