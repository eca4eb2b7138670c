#!/usr/bin/env python
"""Loop detection per keyframe, this tree against an earlier one, interleaved keyframe by keyframe.

Why interleaved in one process: on a shared machine the load changes from one run to the
next by more than the difference being measured; two detectors fed the same keyframe one
after the other see the same load. The earlier tree (``--before DIR``: a folder holding its
``slam_lcd`` package, e.g. ``git archive <commit> slam_lcd | tar -x -C DIR``) is imported
under another package name, so both run in this process on the same SuperPoint features.

Keyframes: the demo world rendered along its path (``--laps``, ``--rate`` Hz, ``--size``),
RGB-D, exact ground truth; features from the on-disk feature cache (``slam_lcd.sim.keyframes``),
so a second run extracts nothing. Each detector uses its own tree's default ``lcd`` section
with the last 20 s excluded, as the demo-world loop tests do. The order of the two
detectors alternates every keyframe.

Printed: mean ms per keyframe of ``LoopDetector.add`` and of its parts, the ratio
(this tree / before), loops, revisit keyframes with a loop, false loops (cameras >= 2 m or
>= 45 deg apart), worst pose error.

    python tools/bench_lcd_interleaved.py --before DIR [--laps 2] [--rate 2] [--size 640x480] [--weights W]
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent


def load_tree(folder: Path, name: str):
    """Import ``folder/slam_lcd`` as package ``name`` (relative imports resolve inside it)."""
    init = folder / "slam_lcd" / "__init__.py"
    if not init.is_file():
        raise SystemExit(f"{folder}: no slam_lcd/__init__.py")
    spec = importlib.util.spec_from_file_location(name, init, submodule_search_locations=[str(init.parent)])
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def relative_error(T: np.ndarray, T_gt: np.ndarray) -> tuple[float, float]:
    D = np.linalg.inv(T_gt) @ T
    ang = np.degrees(np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1, 1)))
    return float(np.linalg.norm(D[:3, 3])), float(ang)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--before", required=True, help="folder holding the earlier tree's slam_lcd package")
    p.add_argument("--laps", type=float, default=2.0)
    p.add_argument("--rate", type=float, default=2.0, help="keyframes per second along the path")
    p.add_argument("--size", default="640x480")
    p.add_argument("--weights", default=None)
    p.add_argument("--skip", type=int, default=40, help="keyframes not timed at the start (no candidates yet)")
    args = p.parse_args(argv)
    sys.path.insert(0, str(REPO))
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    import slam_lcd
    from slam_lcd import sim
    from slam_lcd.features import FeaturesConfig, load_extractor
    from slam_lcd.sim.keyframes import demo_keyframes

    before = load_tree(Path(args.before), "slam_lcd_before")
    w, h = (int(v) for v in args.size.lower().split("x"))
    ex = load_extractor(FeaturesConfig(kind="superpoint"), weights=args.weights, device="cpu")
    demo = demo_keyframes(ex, laps=args.laps, rate_hz=args.rate, width=w, height=h)
    kfs = demo.keyframes
    pairs = sim.gt_loop_pairs(demo.gt, T_body_camera=demo.T_body_camera)
    queries = set(np.unique(pairs[:, 0]).tolist())
    cams = demo.gt.poses @ demo.T_body_camera

    runs = {}
    for label, pkg in (("before", before), ("after", slam_lcd)):
        lcd = importlib.import_module(pkg.__name__ + ".lcd")
        types = importlib.import_module(pkg.__name__ + ".types")
        conf = lcd.LcdConfig(exclude_recent_s=20.0, exclude_recent_n=0)
        runs[label] = dict(det=lcd.LoopDetector(conf), Keyframe=types.Keyframe, Features=types.Features,
                           total=[], parts={})
    for k, kf in enumerate(kfs):
        order = ("before", "after") if k % 2 == 0 else ("after", "before")
        for label in order:
            r = runs[label]
            f = kf.features
            feats = r["Features"](f.keypoints, f.scores, f.descriptors, f.image_size, f.kind)
            mine = r["Keyframe"](kf.id, kf.stamp, kf.T_world_body, camera=kf.camera, T_body_camera=kf.T_body_camera,
                                 depth=kf.depth, features=feats)
            t0 = time.perf_counter()
            r["det"].add(mine)
            dt = time.perf_counter() - t0
            if k >= args.skip:
                r["total"].append(dt)
                for part, s in r["det"].last_part_seconds.items():
                    r["parts"].setdefault(part, []).append(s)
    print(f"{len(kfs)} keyframes ({args.laps:g} laps at {args.rate:g} Hz, {args.size}), "
          f"timed from keyframe {args.skip}")
    for label, r in runs.items():
        det = r["det"]
        found, false, errs = set(), 0, []
        for c in det.closures:
            t, a = relative_error(cams[c.match_id], cams[c.query_id])
            false += not (t < 2.0 and a < 45.0)
            errs.append(relative_error(c.T_match_query,
                                       np.linalg.inv(demo.gt.poses[c.match_id]) @ demo.gt.poses[c.query_id]))
            found.add(c.query_id) if c.query_id in queries else None
        e = np.array(errs) if errs else np.zeros((1, 2))
        parts = "  ".join(f"{p} {1000 * np.mean(v):.1f}" for p, v in sorted(r["parts"].items()))
        print(f"{label:6s} {1000 * np.mean(r['total']):7.1f} ms/keyframe | loops {len(det.closures)}, "
              f"revisit keyframes {len(found)}/{len(queries)}, false {false}, "
              f"pose error max {e[:, 0].max() * 100:.2f} cm / {e[:, 1].max():.2f} deg | {parts}")
    ratio = np.mean(runs["after"]["total"]) / np.mean(runs["before"]["total"])
    print(f"ratio after / before: x{ratio:.2f}")


if __name__ == "__main__":
    main()
