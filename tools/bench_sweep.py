"""The run off the friendly path: layouts, camera rates, sizes, features and bad stretches, one row per case.

Each case renders a demo-world log with ``slam-lcd make-demo-log`` (its layout, rate, size and
bad stretches) and runs ``slam-lcd run`` on it through the CLI in a subprocess, as a user types
it (each layout with its preset, EuRoC with the calibration file written beside the log).
A row gives: exit status, tracking losses (the built-in VO's "lost tracking" lines), segments
and the components loops joined them into, loops accepted / false, ATE before -> after
(per joined component when there are several, docs/tracking_loss.md) and wall time.

    python tools/bench_sweep.py [--quick] [--only SUBSTRING] [--work DIR] [--weights W.pth]
                                [--markdown TABLE.md]

``--quick``: three short cases (.ci/run runs them; the loss bound, which is about whole
sessions, is printed but not checked there). ``--weights``: SuperPoint weights for the SuperPoint cases (without
them those cases are left out, said in the output). ``--work``: keeps logs and outputs there (a
rerun reuses the logs); by default a temporary folder. The checks printed at the end:
every case exits 0 (or 2 with one line where the case is marked unusable), 0 false loops,
ATE after <= before on the low-resolution TUM and EuRoC cases, at most 3 losses per session at
10 and 30 Hz, and on the 2-lap demo every bad stretch within 2x the clean run's ATE.
"""
from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from slam_lcd.runtime.machine import machine_line

PRESETS = {"demo": None, "euroc": "euroc", "tum": "tum-rgbd", "kitti": "kitti"}
# the 2-lap demo's bad stretches, at the strength the checks name (seconds from the first frame; the log is ~85 s)
STRETCHES = {
    "blur": ["--blur", "20:5:15"],
    "dark": ["--dark", "30:3"],
    "drop-frames": ["--drop-frames", "40:3"],
    "freeze": ["--freeze", "50:3"],
    "stamp-jump": ["--stamp-jump", "25:5"],
    "odom-zero-covariance": ["--odom-zero-covariance"],
    "odom-dropout": ["--odom-dropout", "60:3"],
}


@dataclass
class Case:
    name: str
    layout: str = "demo"
    session: int | None = 1
    rate: float | None = None
    size: str = "320x240"
    features: str = "orb"
    log_args: list[str] = field(default_factory=list)
    unusable: bool = False  # the log is unusable as a whole: exit 2 with one line is the right answer
    stretch_of: str | None = None  # a bad stretch of this clean case (ATE after within 2x its)


def cases(weights: Path | None) -> list[Case]:
    out = []
    for layout in ("tum", "euroc", "kitti"):
        for rate in (5, 10, 30):
            out.append(Case(f"{layout} s1 320x240 {rate}Hz", layout, 1, rate))
    out += [Case("euroc s3 320x240 10Hz", "euroc", 3, 10), Case("kitti s3 320x240 10Hz", "kitti", 3, 10),
            Case("demo s1 320x240 5Hz", "demo", 1, 5), Case("demo s1 320x240 30Hz", "demo", 1, 30),
            Case("tum s1 640x480 30Hz", "tum", 1, 30, "640x480"),
            Case("euroc s3 640x480 30Hz", "euroc", 3, 30, "640x480")]
    if weights is not None:
        out += [Case("tum s1 320x240 10Hz superpoint", "tum", 1, 10, features="superpoint"),
                Case("demo 2-lap 640x480 superpoint", "demo", None, features="superpoint", size="640x480")]
    clean = "demo 2-lap 320x240 clean"
    out.append(Case(clean, "demo", None))
    for name, args in STRETCHES.items():
        out.append(Case(f"demo 2-lap 320x240 {name}", "demo", None, log_args=args, stretch_of=clean))
    # bad stretches where the built-in VO is the odometry: it breaks, segments and joins show
    out += [Case("tum s1 320x240 10Hz dark", "tum", 1, 10, log_args=["--dark", "20:3"]),
            Case("euroc s1 320x240 10Hz drop-frames", "euroc", 1, 10, log_args=["--drop-frames", "20:3"])]
    out.append(Case("tum all dark", "tum", 1, 10, log_args=["--dark", "0:1000", "--frames", "60"], unusable=True))
    return out


def quick_cases() -> list[Case]:
    """Three short cases for CI: the low-resolution VO layouts and a dark stretch on the demo's first lap."""
    return [Case("quick tum s1 320x240 10Hz 30 s", "tum", 1, 10, log_args=["--frames", "300"]),
            Case("quick euroc s1 320x240 10Hz 30 s", "euroc", 1, 10, log_args=["--frames", "300"]),
            Case("quick demo 1.1 laps 320x240 dark", "demo", None, log_args=["--frames", "470", "--dark", "20:3"])]


def _cli(*args) -> list[str]:
    return [sys.executable, "-m", "slam_lcd", *map(str, args)]


def _slug(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")


def make_log(work: Path, c: Case) -> Path:
    log = work / f"{_slug(c.name)}.bag"
    args = ["--layout", c.layout, "--size", c.size]
    if c.session is not None:
        args += ["--session", c.session]
    if c.rate is not None:
        args += ["--rate", c.rate]
    args += c.log_args
    stamp = log.with_suffix(".args.json")
    if not (log.exists() and stamp.exists() and json.loads(stamp.read_text()) == list(map(str, args))):
        subprocess.run(_cli("make-demo-log", log, *args), check=True, capture_output=True)
        stamp.write_text(json.dumps(list(map(str, args))))
    return log


def run_case(work: Path, c: Case, weights: Path | None) -> dict:
    log = make_log(work, c)
    out = work / f"{_slug(c.name)}_out"
    cmd = _cli("run", log, "-o", out, "--features", c.features)
    if PRESETS[c.layout]:
        cmd += ["--config", PRESETS[c.layout]]
    if c.layout == "euroc":
        cmd += ["--calib", log.parent / f"camchain-{log.stem}.yaml"]
    if c.features == "superpoint" and weights is not None:
        cmd += ["--weights", weights]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    row = {"case": c.name, "exit": p.returncode, "wall_s": wall,
           "losses": sum("lost tracking" in line for line in p.stderr.splitlines()),
           "error": p.stderr.strip().splitlines()[-1] if p.returncode else ""}
    rep = out / "report.json"
    if p.returncode == 0 and rep.exists():
        r = json.loads(rep.read_text())
        seg = r.get("segments") or {}
        comps = seg.get("components", [])
        row.update(keyframes=r["keyframes"], segments=seg.get("count", 1), components=len(comps),
                   joined=sum(len(x["segments"]) for x in comps if len(x["segments"]) > 1),
                   loops=r["loops"]["accepted"], false=r["loops"]["false_accepted"],
                   ate_before=r["headline"]["ate_before_m"], ate_after=r["headline"]["ate_after_m"])
    return row


def _fmt(v, spec=""):
    return "–" if v is None else format(v, spec)


def table(rows: list[dict]) -> str:
    lines = ["| case | exit | losses | segments (joined) / components | loops acc. / false | ATE before → after (m) "
             "| wall (s) |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        seg = (f"{r['segments']} ({r['joined']}) / {r['components']}" if "segments" in r else "–")
        loops = f"{r['loops']} / {_fmt(r['false'])}" if "loops" in r else "–"
        ate = (f"{_fmt(r.get('ate_before'), '.3f')} → {_fmt(r.get('ate_after'), '.3f')}" if "loops" in r
               else r["error"][:60])
        lines.append(f"| {r['case']} | {r['exit']} | {r['losses']} | {seg} | {loops} | {ate} | {r['wall_s']:.0f} |")
    return "\n".join(lines)


def checks(rows: list[dict], all_cases: list[Case], losses: bool = True) -> list[tuple[str, bool]]:
    """The acceptance lines (``losses``: also the tracking-loss bound, which holds for whole sessions)."""
    by = {r["case"]: r for r in rows}
    spec = {c.name: c for c in all_cases}
    out = []
    for r in rows:
        c = spec[r["case"]]
        want = 2 if c.unusable else 0
        out.append((f"{r['case']}: exit {r['exit']} (want {want})", r["exit"] == want))
        if "false" in r:
            out.append((f"{r['case']}: {r['false']} false loops", (r["false"] or 0) == 0))
        low_res = c.size == "320x240" and (c.layout == "tum" or (c.layout == "euroc" and c.rate in (5, 10)))
        if low_res and r.get("ate_after") is not None and not c.unusable:
            out.append((f"{r['case']}: ATE after {r['ate_after']:.3f} <= before {r['ate_before']:.3f}",
                        round(r["ate_after"], 3) <= round(r["ate_before"], 3)))  # to the mm the table prints
        if losses and c.layout in ("tum", "euroc") and c.rate in (10, 30) and not c.unusable:
            out.append((f"{r['case']}: {r['losses']} tracking losses (<= 3)", r["losses"] <= 3))
        if c.stretch_of and c.stretch_of in by and r.get("ate_after") is not None:
            clean = by[c.stretch_of].get("ate_after")
            if clean is not None:
                out.append((f"{r['case']}: ATE after {r['ate_after']:.3f} <= 2 x clean {clean:.3f}",
                            r["ate_after"] <= 2 * clean))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="three short cases (CI)")
    ap.add_argument("--only", default=None, help="cases whose name contains this text")
    ap.add_argument("--work", type=Path, default=None, help="keep logs and outputs here (default: a temporary folder)")
    ap.add_argument("--weights", type=Path, default=None, help="SuperPoint weights (the SuperPoint cases need them)")
    ap.add_argument("--markdown", type=Path, default=None, help="also write the table to this file")
    a = ap.parse_args(argv)
    all_cases = quick_cases() if a.quick else cases(a.weights)
    chosen = [c for c in all_cases if a.only is None or a.only in c.name]
    if a.weights is None:
        print("SuperPoint cases left out: no --weights")
    with tempfile.TemporaryDirectory() as tmp:
        work = a.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        rows = []
        for c in chosen:
            rows.append(run_case(work, c, a.weights))
            r = rows[-1]
            print(f"{c.name}: exit {r['exit']}, {r['losses']} losses, ATE {_fmt(r.get('ate_before'), '.3f')} -> "
                  f"{_fmt(r.get('ate_after'), '.3f')}, {r['wall_s']:.0f} s", flush=True)
    text = table(rows)
    print(f"\n{machine_line()}; {len(rows)} cases\n\n{text}\n")
    if a.markdown:
        a.markdown.write_text(text + "\n")
    results = checks(rows, all_cases, losses=not a.quick)
    for what, ok in results:
        print(("ok    " if ok else "MISS  ") + what)
    misses = sum(not ok for _, ok in results)
    print(f"{len(results) - misses} passed, {misses} failed")
    return 1 if misses else 0


if __name__ == "__main__":
    sys.exit(main())
