#!/usr/bin/env python
"""What the Rerun recording costs: `run --rerun FILE.rrd` against a plain run, and `view` of a long run.

Section ``live``: the 2-lap demo log run with and without ``--rerun FILE.rrd``, in interleaved pairs
(plain, rerun, plain, rerun, ...; each run a Python process of its own, so each pays its imports as
a user's does, and a drift of the machine's speed hits both alike); the median of the pairs'
wall-time ratios is printed (the bound: 1.10), with the recording's size per keyframe.

Section ``build``: the 10-lap demo log run once (plain), then its recording built from the run
folder (`slam-lcd view RUN --save`), timed in a process of its own; size and time printed.

    python tools/bench_viewer.py live --weights W.pth [--pairs 5] [--features superpoint] [--no-cache] [--work DIR]
    python tools/bench_viewer.py build --weights W.pth [--laps 10] [--work DIR]

The runs take their features from a cache filled by a first run (``--no-cache``: each run extracts
them, as a user's first run of a log does): the cached run is the shorter one, so the ratio is the
larger.
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def _demo_log(path: Path, laps: float, size: str) -> Path:
    from slam_lcd.sim import make_demo_log

    if not path.exists():
        w, h = (int(v) for v in size.split("x"))
        print(f"rendering a {laps:g}-lap demo log ({size}) into {path} ...", flush=True)
        make_demo_log(path, "mcap", laps=laps, seed=0, depth=True, width=w, height=h)
    return path


def _slam(args: list[str]) -> float:
    """Wall seconds of ``slam-lcd ARGS`` in a fresh Python process (output discarded; a failure stops)."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "slam_lcd", *args, "--no-progress"], capture_output=True, text=True,
                          cwd=REPO)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"slam-lcd {' '.join(args)} failed ({proc.returncode}): {proc.stderr.strip()[-500:]}")
    return wall


def _keyframes(out: Path) -> int:
    return sum(1 for ln in (out / "keyframes_corrected.tum").read_text().splitlines() if ln and ln[0] != "#")


def _features(a) -> list[str]:
    return ["--features", a.features, *(["--weights", a.weights] if a.weights else [])]


def bench_live(a) -> None:
    work = Path(a.work)
    log = _demo_log(work / f"demo_2laps_{a.size}.mcap", 2.0, a.size)
    cache = ["--no-feature-cache"] if a.no_cache else ["--set", f"features.cache_dir={work / 'cache'}"]
    common = _features(a) + cache
    _slam(["run", str(log), "--out", str(work / "warm"), *common])  # fills the feature cache for both
    ratios, plain_w, rerun_w = [], [], []
    rrd = work / "live.rrd"
    for i in range(a.pairs):
        p = _slam(["run", str(log), "--out", str(work / "plain"), *common])
        r = _slam(["run", str(log), "--out", str(work / "rerun"), *common, "--rerun", str(rrd)])
        plain_w.append(p)
        rerun_w.append(r)
        ratios.append(r / p)
        print(f"pair {i + 1}: plain {p:.2f} s, --rerun {r:.2f} s, ratio {r / p:.3f}", flush=True)
    n = _keyframes(work / "rerun")
    size = rrd.stat().st_size
    how = "extracted" if a.no_cache else "cached"
    print(f"2-lap demo ({a.size}, {a.features}, features {how}): plain median {statistics.median(plain_w):.2f} s, "
          f"--rerun median {statistics.median(rerun_w):.2f} s; median ratio {statistics.median(ratios):.3f} "
          f"(min {min(ratios):.3f}, max {max(ratios):.3f}; bound 1.10)")
    print(f"recording: {size / 1e6:.2f} MB for {n} keyframes = {size / n / 1e3:.1f} kB per keyframe")


def _read_back(rrd: Path) -> tuple[int, int]:
    """Open the recording with Rerun's own reader: its entity paths and rows (the file is whole and readable)."""
    from rerun.chunk import RrdReader

    entities: set[str] = set()
    rows = 0
    for c in RrdReader(rrd).stream().to_chunks():
        entities.add(c.entity_path)
        rows += c.to_record_batch().num_rows
    return len(entities), rows


def bench_build(a) -> None:
    work = Path(a.work)
    log = _demo_log(work / f"demo_{a.laps:g}laps_{a.size}.mcap", a.laps, a.size)
    out = work / f"run_{a.laps:g}laps"
    if not (out / "report.json").is_file():
        wall = _slam(["run", str(log), "--out", str(out), *_features(a),
                      "--set", f"features.cache_dir={work / 'cache'}"])
        print(f"{a.laps:g}-lap run: {wall:.1f} s", flush=True)
    rrd = work / f"view_{a.laps:g}laps.rrd"
    walls = [_slam(["view", str(out), "--save", str(rrd)]) for _ in range(a.repeat)]
    n = _keyframes(out)
    loops = sum(1 for _ in (out / "loops.csv").open()) - 1
    t0 = time.perf_counter()
    entities, rows = _read_back(rrd)
    print(f"recording read back with Rerun's reader in {time.perf_counter() - t0:.1f} s: {entities} entities, "
          f"{rows} rows", flush=True)
    print(f"{a.laps:g}-lap demo ({a.size}, {a.features}): {n} keyframes, {loops} loop candidates; `view --save` "
          f"median {statistics.median(walls):.2f} s (process wall, imports included; {a.repeat} runs), recording "
          f"{rrd.stat().st_size / 1e6:.2f} MB = {rrd.stat().st_size / n / 1e3:.1f} kB per keyframe")


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("section", choices=["live", "build"])
    p.add_argument("--pairs", type=int, default=5)
    p.add_argument("--laps", type=float, default=10.0)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--features", default="superpoint", choices=["orb", "superpoint"])
    p.add_argument("--weights", default=None, help="SuperPoint weights (default: the configured ones)")
    p.add_argument("--no-cache", action="store_true", help="every run extracts its features (no feature cache)")
    p.add_argument("--size", default="640x480")
    p.add_argument("--work", default=str(REPO / ".bench_viewer"))
    a = p.parse_args(argv)
    Path(a.work).mkdir(parents=True, exist_ok=True)
    sys.path.insert(0, str(REPO))
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    bench_live(a) if a.section == "live" else bench_build(a)


if __name__ == "__main__":
    main()
