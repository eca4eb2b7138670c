"""What the map cloud costs and what it shows, measured in one go on a demo log.

    python tools/bench_map_cloud.py [--laps 2] [--size 640x480] [--features orb] [--layout demo|euroc]

Renders (or reuses, under /tmp) a demo log, then runs `slam-lcd run` on it twice in child
processes, with the map cloud and without (``map_cloud.enabled=false``), and prints: the CPU
(model, cores, torch's CPU capability), both runs' wall time and peak resident memory, their
ratio and difference, the cloud's own seconds (per keyframe, merging, files, figures) as a share
of the run's wall, and the figures (points, MME, plane variance, distance to the true surfaces,
before -> after). Targets: the cloud adds <= 300 MB resident and <= 10 % of the run's wall.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path


def cpu_line() -> str:
    model = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), "?")
    try:
        import torch

        cap = torch.backends.cpu.get_cpu_capability()
    except Exception:  # noqa: BLE001 - only printed
        cap = "?"
    return f"CPU: {model}, {os.cpu_count()} cores visible, torch CPU capability {cap}"


def child(argv: list[str]) -> tuple[float, float]:
    """(wall s, peak resident MB) of one child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    return wall, max(peak, before) / 1024.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--laps", type=float, default=2.0)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--features", default="orb", choices=["orb", "superpoint"])
    ap.add_argument("--layout", default="demo", choices=["demo", "euroc"])
    ap.add_argument("--work", default="/tmp/bench_map_cloud")
    a = ap.parse_args()
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    py = [sys.executable, "-m", "slam_lcd"]
    name = f"{a.layout}-laps{a.laps:g}-{a.size}"
    log = work / (f"{name}.bag" if a.layout == "euroc" else f"{name}.mcap")
    if not log.exists():
        subprocess.run([*py, "make-demo-log", str(log), "--laps", str(a.laps), "--size", a.size, "--layout", a.layout,
                        "--no-progress"], check=True, stdout=subprocess.DEVNULL)
    run = [*py, "run", str(log), "--features", a.features, "--truth-world", "0", "--no-progress"]
    if a.layout == "euroc":
        run += ["--config", "euroc", "--calib", str(work / f"camchain-{name}.yaml")]
    print(cpu_line())
    # the run without the cloud first (RUSAGE_CHILDREN's peak only grows: the larger run last)
    w0, m0 = child([*run, "--out", str(work / f"{name}-off"), "--set", "map_cloud.enabled=false"])
    w1, m1 = child([*run, "--out", str(work / f"{name}-on")])
    rep = json.loads((work / f"{name}-on" / "report.json").read_text())
    mc = rep["map_cloud"]
    sec = mc["seconds"]
    own = sum(sec.values())
    print(f"log: {log.name}: {rep['frames']} frames, {rep['keyframes']} keyframes; features {a.features}")
    print(f"run without the cloud: {w0:.1f} s wall, peak {m0:.0f} MB;  with it: {w1:.1f} s wall, peak {m1:.0f} MB")
    print(f"wall ratio with/without: {w1 / w0:.3f};  resident memory added: {m1 - m0:+.0f} MB (target <= 300 MB)")
    print(f"cloud's own time: {own:.2f} s = {100 * own / rep['wall_s']:.1f} % of the run's wall {rep['wall_s']:.1f} s "
          f"(per keyframe {sec['keyframes']:.2f}, merge {sec['merge']:.2f}, files {sec['files']:.2f}, "
          f"figures {sec['figures']:.2f}; target <= 10 %); on-disk store {mc['store_mb']} MB")
    s, t = mc["sharpness"], mc["truth"]
    print(f"points: {mc['points']['odometry']} -> {mc['points']['corrected']}")
    print(f"MME: {s['odometry']['mme']:.3f} -> {s['corrected']['mme']:.3f};  plane variance: "
          f"{1e6 * s['odometry']['plane_variance_m2']:.0f} -> {1e6 * s['corrected']['plane_variance_m2']:.0f} mm^2")
    if t:
        print(f"distance to the true surfaces: {t['odometry']['mean_m']:.4f} -> {t['corrected']['mean_m']:.4f} m "
              f"({100 * t['ratio_after_before']:.1f} %, target <= 35 %)")
    a_ = rep["eval"]["ate"] if rep["eval"] else None
    if a_:
        print(f"ATE: {a_['before']['translation_m']['rmse']:.3f} -> {a_['after']['translation_m']['rmse']:.3f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
