#!/usr/bin/env python
"""Trade-off table of the configuration presets: SuperPoint's cost against loop-closure quality, in one run.

Per preset (a shipped name such as ``default``, ``fast``, ``accurate``, or a YAML file):

- ``forward``: SuperPoint on a 640x480 demo frame, the network alone (``forward_raw`` on the
  input the preset gives it, ``features.resize_max`` applied) and the whole extraction
  (image in, full-resolution keypoints out); medians of ``--reps`` over 3 frames, in this process;
- ``demo``: ``slam-lcd run`` on the 2-lap demo log (640x480, 84.6 s of log) in a fresh process
  with an empty feature cache, as a new user's first run: wall time against the log's
  duration, keyframes, loops accepted, false loops, ATE after / ATE before;
- ``corridor``: ``slam-lcd eval-lcd`` on the RTAB-Map corridor (84 real 512x384 frames; the
  shared data), recall at 100 % precision of the preset's verification chain;
- ``wide``: the wide-baseline demo (every second lap 0.45 m aside, camera turned 30 deg;
  320x240 keyframes at 1 Hz, 2.3 laps): revisit keyframes with a loop / revisit keyframes,
  false loops (cameras >= 2 m or >= 60 deg apart), as ``tests/lcd/test_lcd_demo_wide.py`` counts them;
- ``euroc``: the demo world as an EuRoC bag (raw stereo pair, stereo VO, position-only ground
  truth; ``tools/bench_layouts.py``) run with ``--config euroc`` plus the preset's own keys:
  ATE after / the VO's ATE, false loops.

Every figure is measured in this one run on this machine (the first line names it). To measure
AVX2 on a CPU with AVX-512 or AMX, limit the libraries:
``ATEN_CPU_CAPABILITY=avx2 ONEDNN_MAX_CPU_ISA=AVX2 python tools/bench_presets.py`` (the
variables reach the child processes; the machine line says they were set).

    python tools/bench_presets.py [--presets default,fast,accurate] [--parts forward,demo,corridor,wide,euroc]
                                  [--skip-euroc] [--weights W] [--work DIR] [--json FILE]

``--json FILE`` keeps the rows: a later run in parts (other presets or parts) adds to them and
prints the whole table (each row names the machine it was measured on).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parent.parent
PARTS = ("forward", "demo", "corridor", "wide", "euroc")
SHARED = Path(os.environ.get("SLAM_LCD_SHARED") or REPO.parent / "shared")


def _cli(*args) -> list[str]:
    return [sys.executable, "-m", "slam_lcd", *map(str, args)]


def preset_config(name: str):
    from slam_lcd.config import load_config

    return load_config(name)


def preset_overrides(name: str) -> list[str]:
    """The keys the preset file sets, as ``--set section.key=value`` (to lay it over another preset)."""
    from slam_lcd.config import preset_text

    path = Path(name)
    text = path.read_text() if path.suffix else preset_text(name)
    data = yaml.safe_load(text) or {}
    return [f"{sec}.{k}={yaml.safe_dump(v, default_flow_style=True).strip().removesuffix('...').strip()}"
            for sec, keys in data.items() for k, v in (keys or {}).items()]


def demo_frames(n: int = 3) -> list[np.ndarray]:
    """``n`` demo-world frames at 640x480 along the demo path."""
    from slam_lcd import sim

    world, cam, T_bc = sim.build_world(0), sim.demo_camera(640, 480), sim.T_body_camera()
    traj = sim.make_trajectory("laps", laps=1.0, rate_hz=1.0)
    return [sim.render(world, cam, traj.poses[k] @ T_bc)[0] for k in np.linspace(5, len(traj) - 5, n).astype(int)]


def part_forward(cfg, weights, reps: int) -> dict:
    import torch

    from slam_lcd.features import load_extractor
    from slam_lcd.features.resize import downscale
    from slam_lcd.vision.gray import to_gray_float

    conf = dataclasses.replace(cfg.features, kind="superpoint", feature_cache=False)
    ex = load_extractor(conf, weights=weights, device="cpu")
    fwd, cpu, full, kps = [], [], [], []
    for img in demo_frames():
        x = torch.from_numpy(downscale(to_gray_float(img), conf.resize_max))[None, None]
        if conf.cpu_channels_last:
            x = x.contiguous(memory_format=torch.channels_last)
        with torch.inference_mode():
            ex.model.forward_raw(x)  # one-off set-up
            for _ in range(reps):
                t0, c0 = time.perf_counter(), time.process_time()
                ex.model.forward_raw(x)
                fwd.append(time.perf_counter() - t0)
                cpu.append(time.process_time() - c0)
        for _ in range(reps):
            t0 = time.perf_counter()
            f = ex.extract(img)
            full.append(time.perf_counter() - t0)
        kps.append(len(f.keypoints))
    return {"input": f"{x.shape[3]}x{x.shape[2]}", "forward_ms": 1e3 * float(np.median(fwd)),
            "forward_cpu_ms": 1e3 * float(np.median(cpu)),
            "extract_ms": 1e3 * float(np.median(full)), "keypoints": float(np.mean(kps))}


def demo_log(work: Path) -> Path:
    from slam_lcd.sim import make_demo_log

    log = work / "demo_2laps_640x480.mcap"
    if not log.exists():
        print(f"rendering the 2-lap demo log into {log} ...", flush=True)
        make_demo_log(log, "mcap", laps=2.0, seed=0, depth=True)
    return log


def part_demo(name: str, work: Path, weights) -> dict:
    log = demo_log(work)
    cache = Path(tempfile.mkdtemp(prefix="cold-cache-", dir=work))  # empty: a first run extracts every keyframe
    out = work / f"demo_{Path(name).stem}"
    shutil.rmtree(out, ignore_errors=True)
    cmd = _cli("run", log, "-o", out, "--config", name, "--set", f"features.cache_dir={cache}", "--no-progress")
    if weights:
        cmd += ["--weights", weights]
    t0, c0 = time.perf_counter(), _children_cpu()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall, cpu = time.perf_counter() - t0, _children_cpu() - c0
    shutil.rmtree(cache, ignore_errors=True)
    if proc.returncode:
        raise SystemExit(f"{' '.join(map(str, cmd))}: {(proc.stderr.strip().splitlines() or ['?'])[-1]}")
    rep = json.loads((out / "report.json").read_text())
    ate = rep["eval"]["ate"]
    before, after = ate["before"]["translation_m"]["rmse"], ate["after"]["translation_m"]["rmse"]
    return {"demo_wall_s": wall, "demo_cpu_s": cpu, "demo_log_s": rep["log_duration_s"],
            "demo_keyframes": rep["keyframes"], "demo_loops": rep["loops"]["accepted"],
            "demo_false": rep["loops"]["false_accepted"],
            "demo_ate_before": before, "demo_ate_after": after, "demo_ate_ratio": after / before}


def _children_cpu() -> float:
    """CPU seconds (user + system) of the finished child processes: on a shared machine the wall time
    grows with the other users' load, the CPU time much less."""
    import resource

    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def part_corridor(name: str, cfg, work: Path, weights) -> dict:
    folder = SHARED / "data" / "rtabmap_corridor"
    if not folder.is_dir():
        raise SystemExit(f"no corridor frames at {folder} (set SLAM_LCD_SHARED)")
    out = work / f"corridor_{Path(name).stem}"
    shutil.rmtree(out, ignore_errors=True)
    cmd = _cli("eval-lcd", folder, "--gt", folder / "samples_GT.bmp", "--verify", cfg.lcd.verify, "-o", out,
               "--config", name, "--set", f"features.cache_dir={work / 'feature-cache'}", "--no-progress")
    if weights:
        cmd += ["--weights", weights]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode:
        raise SystemExit(f"{' '.join(map(str, cmd))}: {(proc.stderr.strip().splitlines() or ['?'])[-1]}")
    res = json.loads((out / "summary.json").read_text())["results"][0]
    return {"corridor_r100p": res["recall_at_100_precision"], "corridor_chain": res["mode"]}


def _relative_error(T: np.ndarray, T_gt: np.ndarray) -> tuple[float, float]:
    D = np.linalg.inv(T_gt) @ T
    return float(np.linalg.norm(D[:3, 3])), float(np.degrees(np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1, 1))))


def part_wide(cfg, weights) -> dict:
    """The wide-baseline demo: rendered keyframes with simulated wheel odometry, the preset's features and
    loop detection (graph+ransac, the last 20 s excluded, as the demo-world loop tests run it)."""
    from slam_lcd import sim
    from slam_lcd.features import load_extractor
    from slam_lcd.lcd import LoopDetector
    from slam_lcd.sim.odometry import simulate_odometry
    from slam_lcd.types import Keyframe

    world, cam, T_bc = sim.build_world(0), sim.demo_camera(320, 240), sim.T_body_camera()
    traj = sim.make_trajectory("laps-wide", laps=2.3, rate_hz=1.0)
    odom = simulate_odometry(traj, seed=0)
    ex = load_extractor(dataclasses.replace(cfg.features, kind="superpoint", feature_cache=False), weights=weights,
                        device="cpu")
    lcd = dataclasses.replace(cfg.lcd, verify="graph+ransac", exclude_recent_s=20.0, exclude_recent_n=0)
    det = LoopDetector(lcd, extractor=ex)
    for k in range(len(traj)):
        img, depth = sim.render(world, cam, traj.poses[k] @ T_bc)
        det.add(Keyframe(k, int(traj.stamps[k]), odom.poses[k], image=img, camera=cam, T_body_camera=T_bc, depth=depth))
    pairs = sim.gt_loop_pairs(traj, T_body_camera=T_bc, max_dist=1.0, max_angle_deg=45.0)
    cams = traj.poses @ T_bc
    queries = set(np.unique(pairs[:, 0]).tolist())
    found = {c.query_id for c in det.closures if c.query_id in queries}
    false = 0
    for c in det.closures:
        t, a = _relative_error(cams[c.match_id], cams[c.query_id])
        false += not (t < 2.0 and a < 60.0)
    return {"wide_recall": len(found) / len(queries), "wide_found": len(found), "wide_queries": len(queries),
            "wide_false": false}


def part_euroc(name: str, work: Path) -> dict:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_layouts

    log, path_m = bench_layouts.make_log(work, "euroc", 2.0, "640x480")
    sets = preset_overrides(name) if name != "default" else []
    sub = work / f"euroc_{Path(name).stem}"
    sub.mkdir(exist_ok=True)
    for f in (log, log.with_name(f"camchain-{log.stem}.yaml")):  # the layout's log, linked beside each preset's outputs
        if not (sub / f.name).exists():
            (sub / f.name).symlink_to(f.resolve())
    r = bench_layouts.run_one(sub, "euroc", sub / log.name, path_m,
                              sets + [f"features.cache_dir={work / 'feature-cache'}"])
    if "error" in r:
        raise SystemExit(f"euroc: {r['error']} ({r['command']})")
    return {"euroc_ate_ratio": r["after_ate"] / r["vo_ate"], "euroc_vo_ate": r["vo_ate"], "euroc_after": r["after_ate"],
            "euroc_loops": r["loops"], "euroc_false": r["false"]}


TIMED = ("forward", "demo")
TIMED_KEYS = ("forward_ms", "forward_cpu_ms", "extract_ms", "demo_wall_s", "demo_cpu_s")


def measure(part: str, name: str, cfg, work: Path, args) -> dict:
    if part == "forward":
        return part_forward(cfg, args.weights, args.reps)
    if part == "demo":
        return part_demo(name, work, args.weights)
    if part == "corridor":
        return part_corridor(name, cfg, work, args.weights)
    if part == "wide":
        return part_wide(cfg, args.weights)
    return part_euroc(name, work)


COLUMNS = [  # (header, key, format)
    ("resize_max", "resize_max", "{}"), ("input", "input", "{}"), ("fwd ms (CPU ms)", "fwd", "{}"),
    ("extract ms", "extract_ms", "{:.0f}"), ("kpts", "keypoints", "{:.0f}"),
    ("demo wall/log", "demo_rt", "{}"), ("loops", "demo_loops", "{}"), ("false", "demo_false", "{}"),
    ("ATE after/before", "demo_ate_ratio", "{:.1%}"), ("corridor R@100P", "corridor_r100p", "{:.3f}"),
    ("wide recall", "wide", "{}"), ("EuRoC after/VO", "euroc_ate_ratio", "{:.1%}"),
    ("EuRoC false", "euroc_false", "{}"),
]


def print_table(rows: dict) -> None:
    machines = sorted({r.get("machine", "?") for r in rows.values()})
    print()
    for m in machines:
        print(m)
    print("| preset | " + " | ".join(h for h, _, _ in COLUMNS) + " |")
    print("|---" * (len(COLUMNS) + 1) + "|")
    for name, r in rows.items():
        r = dict(r)
        if "forward_ms" in r:
            r["fwd"] = f"{r['forward_ms']:.0f} ({r.get('forward_cpu_ms', float('nan')):.0f})"
        if "demo_wall_s" in r:
            r["demo_rt"] = (f"{r['demo_wall_s']:.1f} / {r['demo_log_s']:.1f} s "
                            f"= {r['demo_wall_s'] / r['demo_log_s']:.2f}x"
                            f" (CPU {r.get('demo_cpu_s', float('nan')):.0f} s)")
        if "wide_recall" in r:
            r["wide"] = f"{r['wide_recall']:.0%} ({r['wide_found']}/{r['wide_queries']}, false {r['wide_false']})"
        cells = [fmt.format(r[key]) if r.get(key) is not None or key == "resize_max" else "-"
                 for _, key, fmt in COLUMNS]
        print(f"| {name} | " + " | ".join(cells) + " |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--presets", default="default,fast,accurate", help="preset names or YAML files, comma-separated")
    ap.add_argument("--parts", default=",".join(PARTS), help=f"comma-separated subset of {','.join(PARTS)}")
    ap.add_argument("--skip-euroc", action="store_true", help="leave out the EuRoC layout (the longest part)")
    ap.add_argument("--weights", default=os.environ.get("SLAM_LCD_SUPERPOINT_WEIGHTS"), help="SuperPoint weights")
    ap.add_argument("--work", default=None, help="folder for logs and outputs, reused by a rerun (default: temporary)")
    ap.add_argument("--reps", type=int, default=5, help="forward: timed repetitions per frame (median)")
    ap.add_argument("--repeat", type=int, default=1, help="runs of the timed parts (forward, demo), presets in "
                    "turn; medians are printed (default 1)")
    ap.add_argument("--json", default=None, help="file the rows are kept in (a rerun in parts adds to it)")
    args = ap.parse_args(argv)
    from slam_lcd.runtime.machine import machine_line

    machine = machine_line()
    print(f"{machine}; load average {os.getloadavg()[0]:.1f} at the start", flush=True)
    parts = [p for p in args.parts.split(",") if p and not (p == "euroc" and args.skip_euroc)]
    unknown = set(parts) - set(PARTS)
    if unknown:
        ap.error(f"unknown part(s) {sorted(unknown)}; parts: {','.join(PARTS)}")
    if args.weights:  # the child processes (EuRoC's runs) find them too
        os.environ["SLAM_LCD_SUPERPOINT_WEIGHTS"] = str(Path(args.weights).resolve())
    rows = json.loads(Path(args.json).read_text()) if args.json and Path(args.json).exists() else {}
    names = [p for p in args.presets.split(",") if p]
    cfgs = {name: preset_config(name) for name in names}
    for name in names:
        rows.setdefault(Path(name).stem, {}).update(machine=machine, resize_max=cfgs[name].features.resize_max)
    # timed parts repeated with the presets in turn, so that a change of the machine's load hits all alike
    order = [(part, name) for part in parts for _ in range(args.repeat if part in TIMED else 1) for name in names]
    runs: dict[tuple[str, str], list[dict]] = {}
    with tempfile.TemporaryDirectory(prefix="bench-presets-") as tmp:
        work = Path(args.work or tmp)
        work.mkdir(parents=True, exist_ok=True)
        for part, name in order:
            t0 = time.perf_counter()
            res = measure(part, name, cfgs[name], work, args)
            done = runs.setdefault((name, part), [])
            done.append(res)
            row = rows[Path(name).stem]
            row.update(res)
            row.update({k: float(np.median([r[k] for r in done])) for k in TIMED_KEYS if k in res})
            if part in TIMED:
                row[f"{part}_runs"] = len(done)
            shown = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in res.items()}
            print(f"[{Path(name).stem}] {part} ({time.perf_counter() - t0:.0f} s): {shown}", flush=True)
            if args.json:
                Path(args.json).write_text(json.dumps(rows, indent=1))
    print(f"load average {os.getloadavg()[0]:.1f} at the end (above the core count: other processes shared the CPU)")
    print_table(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
