"""Acceptance of the dataset layouts: the demo world as EuRoC, TUM RGB-D and KITTI bags, run with their presets.

For each layout: ``slam-lcd make-demo-log LOG --layout L`` (2 laps, 640x480 by default),
then ``slam-lcd run LOG --config PRESET [--calib camchain-LOG.yaml]`` with no other flag, and
one line of the table from its report.json: path length, the VO's ATE (metres and % of the
path), the ATE after loop closure (metres and % of the VO's), loops accepted, false loops
accepted (judged against the exact ground truth) and wall time, with PASS when

    VO ATE <= 3 % of the path, ATE after <= 25 % of the VO's, 0 false loops.

    python tools/bench_layouts.py [--layouts euroc,tum,kitti] [--laps 2] [--size 640x480]
                                  [--exact-depth] [--work DIR] [--set section.key=value ...]

TUM's depth carries the Kinect v1 errors (``slam_lcd.sim.kinect``); ``--exact-depth``
writes the exact rendered depth instead (log ``tum_exact-depth.mcap``), to compare both.
``--work DIR`` keeps the logs and outputs there (a rerun reuses a log made with the same
size, laps and depth model); by default a temporary folder. Runs go through the CLI in a subprocess, as a user
types them.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PRESETS = {"euroc": "euroc", "tum": "tum-rgbd", "kitti": "kitti"}
MAX_VO_PERCENT_OF_PATH = 3.0
MAX_AFTER_PERCENT_OF_VO = 25.0


def _cli(*args) -> list[str]:
    return [sys.executable, "-m", "slam_lcd", *map(str, args)]


def log_name(layout: str, exact_depth: bool) -> str:
    """The log's stem: ``tum_exact-depth`` for TUM with exact depth (the other layouts have no depth)."""
    from slam_lcd.sim.layouts import DEPTH_MODELS

    return f"{layout}_exact-depth" if exact_depth and layout in DEPTH_MODELS else layout


def make_log(work: Path, layout: str, laps: float, size: str, exact_depth: bool = False) -> tuple[Path, float]:
    """The layout's log (made once per work folder and settings) and its ground-truth path length (m)."""
    from slam_lcd.sim import make_demo_log
    from slam_lcd.sim.layouts import depth_model

    name = log_name(layout, exact_depth)
    log, meta = work / f"{name}.mcap", work / f"{name}.json"
    model = depth_model(layout, not exact_depth)
    settings = {"laps": laps, "size": size, "depth": model.describe() if model else "exact"}
    old = json.loads(meta.read_text()) if meta.exists() else {}
    if not (log.exists() and all(old.get(k) == v for k, v in settings.items())):
        w, h = (int(x) for x in size.lower().split("x"))
        info = make_demo_log(log, "mcap", layout=layout, laps=laps, width=w, height=h, depth_noise=not exact_depth)
        meta.write_text(json.dumps({"path_length_m": info.path_length_m, "frames": info.frames, **settings}))
    return log, json.loads(meta.read_text())["path_length_m"]


def run_one(work: Path, layout: str, log: Path, path_m: float, overrides: list[str]) -> dict:
    out = work / f"{log.stem}_out"
    cmd = _cli("run", log, "-o", out, "--config", PRESETS[layout], "--no-progress", "--no-mcap")
    if layout == "euroc":
        cmd += ["--calib", log.with_name(f"camchain-{log.stem}.yaml")]
    for o in overrides:
        cmd += ["--set", o]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        return {"layout": log.stem, "error": (proc.stderr.strip().splitlines() or ["?"])[-1], "wall": wall,
                "command": " ".join(map(str, cmd[3:]))}
    rep = json.loads((out / "report.json").read_text())
    ate = rep["eval"]["ate"]
    return {"layout": log.stem, "preset": PRESETS[layout], "path_m": path_m,
            "vo_ate": ate["before"]["translation_m"]["rmse"], "after_ate": ate["after"]["translation_m"]["rmse"],
            "loops": rep["loops"]["accepted"], "false": rep["loops"]["false_accepted"], "keyframes": rep["keyframes"],
            "frames": rep["frames"], "wall": wall, "alignment": rep["eval"]["alignment"],
            "command": " ".join(map(str, cmd[3:]))}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layouts", default="euroc,tum,kitti")
    ap.add_argument("--laps", type=float, default=2.0)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--exact-depth", action="store_true",
                    help="TUM with the exact rendered depth instead of the Kinect v1 depth errors")
    ap.add_argument("--work", default=None, help="folder for logs and outputs (default: a temporary one)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = ap.parse_args()
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    layouts = [x for x in args.layouts.split(",") if x]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(args.work) if args.work else Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        rows = []
        for layout in layouts:
            log, path_m = make_log(work, layout, args.laps, args.size, args.exact_depth)
            rows.append(run_one(work, layout, log, path_m, args.overrides))
            _print_row(rows[-1], header=len(rows) == 1)
        ok = all("error" not in r and _verdict(r) == "PASS" for r in rows)
        print(f"\n{'all PASS' if ok else 'some FAIL'}: VO ATE <= {MAX_VO_PERCENT_OF_PATH:g} % of the path, "
              f"ATE after <= {MAX_AFTER_PERCENT_OF_VO:g} % of the VO's, 0 false loops")
        for r in rows:
            print(f"  {r['layout']}: slam-lcd {r['command']}")
    return 0 if ok else 1


def _verdict(r) -> str:
    vo_pct = 100 * r["vo_ate"] / r["path_m"]
    after_pct = 100 * r["after_ate"] / r["vo_ate"] if r["vo_ate"] > 0 else float("inf")
    good = vo_pct <= MAX_VO_PERCENT_OF_PATH and after_pct <= MAX_AFTER_PERCENT_OF_VO and r["false"] == 0
    return "PASS" if good else "FAIL"


def _print_row(r, header: bool) -> None:
    if header:
        print(f"{'layout':<16} {'preset':<9} {'frames':>6} {'kf':>4} {'path m':>7} {'VO ATE m':>9} {'% path':>7} "
              f"{'after m':>8} {'% VO':>6} {'loops':>6} {'false':>5} {'wall s':>7}  verdict")
    if "error" in r:
        print(f"{r['layout']:<16} FAIL: {r['error']} ({r['wall']:.0f} s)")
        return
    vo_pct = 100 * r["vo_ate"] / r["path_m"]
    after_pct = 100 * r["after_ate"] / r["vo_ate"] if r["vo_ate"] > 0 else float("inf")
    print(f"{r['layout']:<16} {r['preset']:<9} {r['frames']:>6d} {r['keyframes']:>4d} {r['path_m']:>7.1f} "
          f"{r['vo_ate']:>9.3f} {vo_pct:>7.2f} {r['after_ate']:>8.3f} {after_pct:>6.1f} {r['loops']:>6d} "
          f"{r['false']:>5d} {r['wall']:>7.1f}  {_verdict(r)}", flush=True)


if __name__ == "__main__":
    sys.exit(main())
