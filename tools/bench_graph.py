#!/usr/bin/env python3
"""Time graph verification: the all-pairs reference vs the grid-bucketed version, on real match sets.

Match sets come from the demo world (rendered here at 1280x960, SuperPoint or ORB features):
one-to-one matches of revisit pairs (true loops, 900-1300 matches) and of pairs of places half
a lap apart matched without ratio or distance bound (wrong matches, what pruning has to take
apart; only ~250 are mutual), each cut to exactly 100, 300 or 1000 matches with the
detector's own budget rule. For every set both versions run
in the same process; the script prints per size the median time of each, their ratio, and
checks that the verdicts are identical (the reference is tests/support/lcd_graph_reference.py).

    python tools/bench_graph.py [--features superpoint|orb] [--weights W] [--sizes 100 300 1000] [--repeat 3]
"""
from __future__ import annotations

import argparse
import functools
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from slam_lcd import sim  # noqa: E402
from slam_lcd.features import FeaturesConfig, load_extractor  # noqa: E402
from slam_lcd.features.matching import mutual_nn_match_bf  # noqa: E402
from slam_lcd.lcd import LcdConfig, verify_graph  # noqa: E402
from slam_lcd.lcd.budget import select_matches  # noqa: E402

from support import lcd_graph_reference as ref  # noqa: E402


def demo_features(kind: str, weights: str | None, n_pairs: int, width: int, height: int):
    """Features of revisit pairs (query, match) and of the same queries' far-away keyframes."""
    world = sim.build_world(0)
    traj = sim.make_trajectory("laps", laps=1.3, rate_hz=1.0)
    cam = sim.demo_camera(width, height)
    T_bc = sim.T_body_camera()
    pairs = sim.gt_loop_pairs(traj, T_body_camera=T_bc)
    # the revisits seen from the closest viewpoints (most overlap: the largest true match sets)
    cams = traj.poses @ T_bc
    gap = np.linalg.norm(cams[pairs[:, 0], :3, 3] - cams[pairs[:, 1], :3, 3], axis=1)
    pick, used = [], set()
    for q, m in pairs[np.argsort(gap, kind="stable")]:
        if len(pick) < n_pairs and not {int(q), int(m)} & used:
            pick.append((int(q), int(m)))
            used |= {int(q), int(m)}
    conf = FeaturesConfig(kind=kind, feature_cache=False, max_keypoints=3000, orb_n_features=4000)
    ex = load_extractor(conf, weights=weights, device="cpu")
    cache: dict[int, object] = {}

    def feats(k: int):
        if k not in cache:
            img, _ = sim.render(world, cam, traj.poses[k] @ T_bc)
            cache[k] = ex.extract(img)
        return cache[k]

    n = len(traj)
    true_pairs = [(feats(q), feats(m)) for q, m in pick]
    false_pairs = [(feats(int(q)), feats(int((q + n // 2) % n))) for q, _ in pick]  # half a lap away
    return true_pairs, false_pairs


def match_sets(true_pairs, false_pairs, sizes, kind: str):
    conf = LcdConfig()
    max_d = conf.match_max_distance_orb if kind == "orb" else conf.match_max_distance_sp
    sets = {s: [] for s in sizes}
    counts = {"true": [], "false": []}
    for label, pairs, ratio, bound in (("true", true_pairs, conf.match_ratio, max_d),
                                       ("false", false_pairs, None, None)):
        for fq, fm in pairs:
            m, d = mutual_nn_match_bf(fq.descriptors, fm.descriptors, ratio=ratio, max_distance=bound,
                                      return_distances=True)
            counts[label].append(len(m))
            for s in sizes:
                if len(m) >= s:
                    keep = select_matches(m, d, fq.keypoints, s, fq.image_size, conf.verify_spread_cells)
                    sets[s].append((label, fq.keypoints, fm.keypoints, m[keep]))
    return sets, counts


def timed(fn, repeat: int):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--features", choices=["superpoint", "orb"], default="superpoint")
    ap.add_argument("--weights", default=None, help="SuperPoint weights (default: $SLAM_LCD_SUPERPOINT_WEIGHTS)")
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 300, 1000])
    ap.add_argument("--pairs", type=int, default=4, help="revisit pairs rendered (and as many far pairs)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--resolution", default="1280x960", help="rendered image size (1000 true matches need 1280x960)")
    args = ap.parse_args(argv)
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named

    t0 = time.perf_counter()
    width, height = (int(v) for v in args.resolution.lower().split("x"))
    true_pairs, false_pairs = demo_features(args.features, args.weights, args.pairs, width, height)
    sets, counts = match_sets(true_pairs, false_pairs, args.sizes, args.features)
    print(f"[bench_graph] {args.features} features of {2 * args.pairs} demo pairs ({args.resolution}) in "
          f"{time.perf_counter() - t0:.1f} s; one-to-one matches of the revisits {counts['true']}, of places half a "
          f"lap apart {counts['false']}; T/F: sets cut from those; median of {args.repeat} runs per set, both "
          f"versions in this process")
    exact = LcdConfig(graph_early_exit=False)
    fast = LcdConfig()
    print(f"{'matches':>7} {'sets':>9} {'reference':>10} {'grid':>9} {'ratio':>6} {'grid+exit':>9} {'ratio':>6} "
          f"{'rounds':>6}  verdicts")
    for s in args.sizes:
        if not sets[s]:
            print(f"{s:>7}  no match set this large (more --pairs, or ORB)")
            continue
        t_ref, t_new, t_exit, rounds, same = [], [], [], [], True
        for _label, kq, km, m in sets[s]:
            a, v = timed(functools.partial(ref.verify_graph, kq, km, m, exact), args.repeat)
            b, w = timed(functools.partial(verify_graph, kq, km, m, exact), args.repeat)
            c, x = timed(functools.partial(verify_graph, kq, km, m, fast), args.repeat)
            same &= (v.accepted, v.reason, v.score, v.n_nodes, v.iterations) == \
                (w.accepted, w.reason, w.score, w.n_nodes, w.iterations) and np.array_equal(v.kept, w.kept)
            same &= x.accepted == v.accepted
            t_ref.append(a), t_new.append(b), t_exit.append(c), rounds.append(v.iterations)
        n_true = sum(1 for x in sets[s] if x[0] == "true")
        mr, mn, me = np.median(t_ref), np.median(t_new), np.median(t_exit)
        print(f"{s:>7} {n_true:>3}T/{len(sets[s]) - n_true:>2}F {mr * 1e3:>8.1f}ms {mn * 1e3:>7.1f}ms {mr / mn:>5.1f}x "
              f"{me * 1e3:>7.1f}ms {mr / me:>5.1f}x {np.median(rounds):>6.0f}  {'identical' if same else 'DIFFERENT'}")
        if not same:
            return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
