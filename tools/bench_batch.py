#!/usr/bin/env python
"""Benchmark of ``slam-lcd batch``: N demo logs on a local pool of W workers vs one after the other.

Both arms run the same logs with the same configuration in the same process (the feature
cache is off, so each arm does the whole work): the sequential arm is ``--workers 1`` (in
this process, what N ``slam-lcd run`` calls in a row do, without N interpreter starts),
the parallel arm a local process pool of W workers, its process start-up included.
Repeats alternate the arms; the medians and the ratio sequential / parallel (the speed-up)
are printed, and the figures of every log are checked to be the same in both arms.

    python tools/bench_batch.py [--logs 4] [--workers 2] [--frames 120] [--size 320x240] [--repeats 3]
                                [--features orb|superpoint] [--ray]

On a machine shared with other work the absolute seconds move; the ratio, measured in one
run with alternating arms, is the figure to read.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from slam_lcd.batch import run_batch  # noqa: E402
from slam_lcd.config import load_config  # noqa: E402

FIGURES = ("frames", "keyframes", "loops_proposed", "loops_accepted", "ate_before_m", "ate_after_m")


def make_logs(folder: Path, n: int, frames: int, size: tuple[int, int]) -> list[Path]:
    from slam_lcd.sim import make_demo_log

    logs = []
    for seed in range(n):
        p = folder / f"bench_seed{seed}.mcap"
        if not p.exists():
            make_demo_log(p, "mcap", frames=frames, seed=seed, width=size[0], height=size[1])
        logs.append(p)
    return logs


def one_arm(logs, out: Path, cfg, workers: int, ray: str | None) -> tuple[float, list[dict]]:
    t = time.perf_counter()
    res = run_batch(logs, out, cfg, workers=workers, ray=ray, force=True, progress=False,
                    status_stream=open(os.devnull, "w"))
    wall = time.perf_counter() - t
    bad = [r for r in res.rows if r["status"] != "ok"]
    if bad:
        sys.exit(f"bench_batch: {bad[0]['name']}: {bad[0]['status']}: {bad[0]['message']}")
    return wall, res.rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--logs", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--frames", type=int, default=120)
    ap.add_argument("--size", default="320x240")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--features", choices=["orb", "superpoint"], default="orb")
    ap.add_argument("--ray", action="store_true", help="parallel arm on a local Ray instead of the process pool")
    ap.add_argument("--work-dir", default=None, help="where logs and outputs go (default: a temporary folder)")
    a = ap.parse_args()
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    w, h = (int(v) for v in a.size.split("x"))
    cfg = load_config("default", [f"features.kind={a.features}", "features.feature_cache=false"])
    with tempfile.TemporaryDirectory(prefix="bench_batch.", dir=a.work_dir) as tmp:
        tmp = Path(tmp)
        t = time.perf_counter()
        logs = make_logs(tmp, a.logs, a.frames, (w, h))
        print(f"{a.logs} demo logs of {a.frames} frames at {w}x{h} rendered in {time.perf_counter() - t:.1f} s; "
              f"{a.features} features, feature cache off; {os.cpu_count()} CPU cores; load average "
              f"{os.getloadavg()[0]:.1f}")
        engine = "local Ray" if a.ray else "local process pool"
        seq, par = [], []
        rows_seq = rows_par = None
        for r in range(a.repeats):
            ws, rows_seq = one_arm(logs, tmp / "seq", cfg, 1, None)
            wp, rows_par = one_arm(logs, tmp / "par", cfg, a.workers, "local" if a.ray else None)
            seq.append(ws)
            par.append(wp)
            print(f"  repeat {r + 1}: sequential {ws:6.1f} s, {a.workers} workers ({engine}) {wp:6.1f} s, "
                  f"ratio {ws / wp:.2f}")
        same = all({k: x[k] for k in FIGURES} == {k: y[k] for k in FIGURES}
                   for x, y in zip(rows_seq, rows_par, strict=True))
        ms, mp = statistics.median(seq), statistics.median(par)
        print(f"median wall time: sequential {ms:.1f} s, {a.workers} workers {mp:.1f} s")
        print(f"speed-up sequential / {a.workers} workers: {ms / mp:.2f} (ideal {min(a.workers, a.logs)}); "
              f"figures identical in both arms: {same}")
        if not same:
            sys.exit(1)


if __name__ == "__main__":
    main()
