#!/usr/bin/env python
"""Benchmark of slam_lcd.backend on the KITTI-00 scenario (and optionally sphere2500).

Prints the median iSAM2 update time per keyframe over all 4541 keyframes, the time per
loop, the batch GNC (TLS) time and a plain batch Levenberg-Marquardt solve of the same
graph in the same run (the baseline), with ratios and the ATE of each.

    python tools/bench_backend.py [--false-fraction 0.2] [--stride 1] [--sphere]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from slam_lcd.backend.config import BackendConfig
from slam_lcd.backend.pose_graph import values_to_array

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tests"))  # the KITTI scenario and the batch solvers are test harnesses (tests/support)
from support.scenario import ScenarioConfig, ate_rmse, make_scenario, run_scenario  # noqa: E402
from support.solve import solve_gnc, solve_lm  # noqa: E402


def shared_data() -> Path:
    env = os.environ.get("SLAM_LCD_SHARED")
    root = Path(env) if env else REPO.parent / "shared"
    if not (root / "data").is_dir():
        sys.exit(f"bench_backend: real data folder not found at {root} (set SLAM_LCD_SHARED)")
    return root / "data"


def bench_kitti(data: Path, false_fraction: float, stride: int, seed: int) -> None:
    d = data / "trajectories"
    sc = make_scenario(d / "KITTI_00_gt.txt", ScenarioConfig(stride=stride, false_fraction=false_fraction, seed=seed),
                       d / "KITTI_00_gt_times.txt")
    print(f"KITTI-00 scenario: {len(sc.stamps)} keyframes, {sc.n_true} true + {sc.n_false} false loops (seed {seed})")
    g, res = run_scenario(sc, BackendConfig())
    ut = np.array(g.update_times) * 1e3
    lt = np.array(g.loop_times) * 1e3
    print(f"  online (iSAM2 + gate, then final GNC): {res.line('robust')}")
    print(f"  iSAM2 update per keyframe: median {np.median(ut):.3f} ms, mean {ut.mean():.3f} ms, "
          f"p95 {np.percentile(ut, 95):.3f} ms, total {ut.sum() / 1e3:.2f} s")
    print(f"  add_loop (gate + iSAM2 update): median {np.median(lt):.2f} ms, max {lt.max():.1f} ms "
          f"over {len(lt)} loops")
    gt_ = g.gnc_times
    print(f"  GNC re-checks (every {g.conf.gnc_every_n_loops} loops + finalize): {len(gt_)} runs, "
          f"total {sum(gt_):.2f} s, final {gt_[-1] if gt_ else 0:.2f} s")

    # Same graph, three batch solves from the odometry initial estimate.
    odo = g.odometry_values()
    n_base = len(sc.stamps)  # prior + (n-1) odometry factors
    graph_all, _ = g.batch_graph("all")
    gnc_vals, w, t_gnc = solve_gnc(graph_all, odo, list(range(n_base)))
    lm_vals, t_lm = solve_lm(graph_all, odo)
    inl_graph, _ = g.batch_graph("accepted")
    lm_inl, t_lm_inl = solve_lm(inl_graph, odo)
    n = len(sc.stamps)
    w_loops = w[n_base:] >= 0.5
    print(f"  batch on the same graph ({graph_all.size()} factors, all loops):")
    print(f"    GNC (TLS):       {t_gnc:7.2f} s  ATE {ate_rmse(sc.gt, values_to_array(gnc_vals, n)):.2f} m, "
          f"false rejected {int((~w_loops & ~sc.is_true).sum())}/{sc.n_false}, "
          f"true kept {int((w_loops & sc.is_true).sum())}/{sc.n_true}")
    print(f"    plain LM:        {t_lm:7.2f} s  ATE {ate_rmse(sc.gt, values_to_array(lm_vals, n)):.2f} m "
          f"(no outlier handling)")
    print(f"    LM, inliers only:{t_lm_inl:7.2f} s  ATE {ate_rmse(sc.gt, values_to_array(lm_inl, n)):.2f} m")
    print(f"    ratio GNC / plain LM: {t_gnc / t_lm:.1f}x; "
          f"all {n} iSAM2 keyframe updates / plain LM: {ut.sum() / 1e3 / t_lm:.2f}x")


def bench_sphere(data: Path) -> None:
    from slam_lcd.backend.g2o import chain_initial_estimate, read_g2o

    from support.solve import batch_graph, from_values, isam2_edge_by_edge, to_values, translation_rmse

    d = data / "posegraphs"
    _, edges = read_g2o(d / "sphere2500.txt", edge3_matrix="sqrt_information")
    _, gte = read_g2o(d / "sphere2500_groundtruth.txt", edge3_matrix="sqrt_information")
    gt = chain_initial_estimate(gte)
    init = chain_initial_estimate(edges)
    vals, t_lm = solve_lm(batch_graph(edges, 0, np.eye(4)), to_values(init))
    print(f"sphere2500: initial translation RMSE {translation_rmse(init, gt):.2f} m")
    print(f"  batch LM:  {t_lm:6.2f} s, RMSE {translation_rmse(from_values(vals), gt):.3f} m")
    t0 = time.perf_counter()
    est, times = isam2_edge_by_edge(edges, BackendConfig())
    tt = time.perf_counter() - t0
    print(f"  iSAM2 pose by pose: {tt:6.2f} s total, median update {1e3 * np.median(times):.2f} ms, "
          f"RMSE {translation_rmse(est, gt):.3f} m")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--false-fraction", type=float, default=0.2, help="share of false loops among all loops")
    ap.add_argument("--stride", type=int, default=1, help="keyframe every n-th ground-truth pose (1: all 4541)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sphere", action="store_true", help="also run sphere2500 (batch LM and iSAM2 pose by pose; slow)")
    args = ap.parse_args(argv)
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    data = shared_data()
    bench_kitti(data, args.false_fraction, args.stride, args.seed)
    if args.sphere:
        bench_sphere(data)
    return 0


if __name__ == "__main__":
    sys.exit(main())
