"""What the map cloud costs and what it shows, measured in one go on a demo log.

    python tools/bench_map_cloud.py [--laps 2] [--size 640x480] [--features orb|superpoint]
                                    [--layout demo|euroc] [--repeats 3] [--weights PATH]

Renders (or reuses, under --work) a demo log, then runs `slam-lcd run` on it in child processes,
with the map cloud and without it (``map_cloud.enabled=false``), ``--repeats`` pairs interleaved
(off/on, then on/off, ...: a machine shared with other jobs slows both alike), and prints: the CPU
(model, cores, torch's CPU capability); each run's wall time and peak resident memory (the child's
own ``ru_maxrss``, from ``wait4``); the medians, the wall ratio with/without and the resident memory
added; the cloud's own seconds in the run's thread (handing keyframes over, merging, files,
figures) and in its own thread; and the figures (points, MME, plane variance, distance to the true
surfaces, before -> after) of the last run with the cloud.
Targets: the cloud adds <= 300 MB resident and <= 10 % of the run's wall.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

from slam_lcd.runtime.machine import machine_line


def child(argv: list[str]) -> tuple[float, float, float]:
    """(wall s, peak resident MB, CPU s) of one child process: its own peak, whatever ran before it."""
    t = time.perf_counter()
    p = subprocess.Popen(argv, stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode != 0:
        raise SystemExit(f"{' '.join(argv)}: exit status {p.returncode}")
    return wall, usage.ru_maxrss / 1024.0, usage.ru_utime + usage.ru_stime


def make_log(py: list[str], a, work: Path) -> tuple[Path, str]:
    name = f"{a.layout}-laps{a.laps:g}-{a.size}"
    log = work / (f"{name}.bag" if a.layout == "euroc" else f"{name}.mcap")
    if not log.exists():
        subprocess.run([*py, "make-demo-log", str(log), "--laps", str(a.laps), "--size", a.size, "--layout", a.layout,
                        "--no-progress"], check=True, stdout=subprocess.DEVNULL)
    return log, name


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--laps", type=float, default=2.0)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--features", default="orb", choices=["orb", "superpoint"])
    ap.add_argument("--weights", default=None, help="SuperPoint weights (with --features superpoint)")
    ap.add_argument("--layout", default="demo", choices=["demo", "euroc"])
    ap.add_argument("--repeats", type=int, default=3, help="pairs of runs (without / with the cloud), interleaved")
    ap.add_argument("--work", default="/tmp/bench_map_cloud")
    a = ap.parse_args()
    work = Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    py = [sys.executable, "-m", "slam_lcd"]
    log, name = make_log(py, a, work)
    run = [*py, "run", str(log), "--features", a.features, "--truth-world", "0", "--no-progress", "--no-feature-cache"]
    if a.weights:
        run += ["--weights", a.weights]
    if a.layout == "euroc":
        run += ["--config", "euroc", "--calib", str(work / f"camchain-{name}.yaml")]
    print(machine_line(), flush=True)
    walls: dict[str, list[float]] = {"off": [], "on": []}
    peaks: dict[str, list[float]] = {"off": [], "on": []}
    cpus: dict[str, list[float]] = {"off": [], "on": []}
    own = []
    for r in range(a.repeats):
        for kind in (("off", "on") if r % 2 == 0 else ("on", "off")):
            extra = ["--set", "map_cloud.enabled=false"] if kind == "off" else []
            w, m, c = child([*run, "--out", str(work / f"{name}-{kind}"), *extra])
            walls[kind].append(w)
            peaks[kind].append(m)
            cpus[kind].append(c)
            line = f"  pair {r + 1} {kind:>3}: {w:6.1f} s wall, {c:6.1f} s CPU, peak {m:5.0f} MB"
            if kind == "on":
                rep = json.loads((work / f"{name}-on" / "report.json").read_text())
                sec = rep["map_cloud"]["seconds"]
                own.append((sum(v for k, v in sec.items() if k != "keyframes_thread"), rep["wall_s"]))
                line += f" (the cloud's own time in the run's thread {own[-1][0]:.2f} s)"
            print(line, flush=True)
    med = {k: statistics.median(v) for k, v in walls.items()}
    mem = {k: statistics.median(v) for k, v in peaks.items()}
    pair_ratios = [b / a_ for a_, b in zip(walls["off"], walls["on"], strict=True)]
    rep = json.loads((work / f"{name}-on" / "report.json").read_text())
    mc = rep["map_cloud"]
    sec = mc["seconds"]
    print(f"log: {log.name}: {rep['frames']} frames, {rep['keyframes']} keyframes; features {a.features}; "
          f"{a.repeats} interleaved pairs")
    print(f"median wall without the cloud {med['off']:.1f} s, with it {med['on']:.1f} s: "
          f"ratio {med['on'] / med['off']:.3f} "
          f"(median of the pairs' ratios {statistics.median(pair_ratios):.3f}; target <= 1.10)")
    cpu = {k: statistics.median(v) for k, v in cpus.items()}
    print(f"median CPU time (user + system, all threads) without {cpu['off']:.1f} s, with {cpu['on']:.1f} s: "
          f"ratio {cpu['on'] / cpu['off']:.3f} (less sensitive to other jobs on the machine than the wall)")
    print(f"median peak resident without {mem['off']:.0f} MB, with {mem['on']:.0f} MB: "
          f"added {mem['on'] - mem['off']:+.0f} MB "
          f"(target <= 300 MB)")
    shares = [100 * s / w for s, w in own]
    print(f"the cloud's own time in the run's thread: median {statistics.median(shares):.1f} % of the run's wall "
          f"(last run: handing keyframes over {sec['keyframes']:.2f} s, merge {sec['merge']:.2f}, "
          f"files {sec['files']:.2f}, "
          f"figures {sec['figures']:.2f}); in its own thread {sec['keyframes_thread']:.2f} s; "
          f"on-disk store {mc['store_mb']} MB")
    s, t = mc["sharpness"], mc["truth"]
    print(f"points: {mc['points']['odometry']} -> {mc['points']['corrected']}")
    print(f"MME: {s['odometry']['mme']:.3f} -> {s['corrected']['mme']:.3f};  plane variance: "
          f"{1e6 * s['odometry']['plane_variance_m2']:.0f} -> {1e6 * s['corrected']['plane_variance_m2']:.0f} mm^2")
    if t:
        print(f"distance to the true surfaces: {t['odometry']['mean_m']:.4f} -> {t['corrected']['mean_m']:.4f} m "
              f"({100 * t['ratio_after_before']:.1f} %, target <= 35 %)")
    a_ = rep["eval"]["ate"] if rep["eval"] else None
    if a_:
        print(f"ATE: {a_['before']['translation_m']['rmse']:.3f} -> {a_['after']['translation_m']['rmse']:.3f} m; "
              f"loops accepted {rep['loops']['accepted']}, false {rep['loops']['false_accepted']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
