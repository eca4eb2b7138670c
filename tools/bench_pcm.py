#!/usr/bin/env python3
"""Time the judgement of one pair of sessions: pairwise consistency (PCM) and the largest consistent sets.

Two synthetic sessions drive one planar random-walk route side by side (keyframes 0.5 m apart),
each with odometry noised by exactly the covariance it reports; ``N`` true loops join keyframe
``i`` of one to keyframe ``i`` of the other (noise 1 cm / 0.6 deg, honest information), and
``--false`` of them (a share) are replaced by look-alikes that put the second session's keyframe
at a place at least 10 m along the route from where it is (half the route at most). Timed
separately, median of ``--repeat``: ``pair_statistics`` (the chi-square of every two loops), the
first ``maximum_clique`` (the largest consistent set), the rival one (the largest among the rest)
and ``judge_pair`` (all of it, with the map's default configuration). Printed per ``N``: the
times, the search nodes and whether each search was exact, the sizes of the sets and the number of
inconsistent true pairs. The last line checks the goal: a pair of 1000 loops judged in 3 s or
less.

    python tools/bench_pcm.py [--loops 100 400 1000] [--false 0.1] [--repeat 3] [--seed 0]
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from slam_lcd.geometry import inv, make_T, se3_exp, so3_exp
from slam_lcd.map.cliques import maximum_clique
from slam_lcd.map.config import MapConfig
from slam_lcd.map.joins import judge_pair
from slam_lcd.map.joint_types import JointLoop, SessionPoses
from slam_lcd.map.pcm import SessionChains, pair_statistics, pcm_threshold

STEP = 0.5  # m between keyframes
STEP_COV = np.diag([0.005 ** 2 * STEP] * 3 + [0.05 ** 2 * STEP] * 3)  # each session's odometry, honest
LOOP_COV = np.diag([1e-4] * 6)  # 1 cm / 0.6 deg
GOAL_N, GOAL_S = 1000, 3.0


def route(n: int, rng) -> np.ndarray:
    """n ground-truth poses 0.5 m apart: a planar random walk in heading."""
    T = [np.eye(4)]
    for _ in range(1, n):
        T.append(T[-1] @ make_T(so3_exp(np.array([0, 0, rng.normal(0, 0.05)])), np.array([STEP, 0, 0])))
    return np.array(T)


def session(name: str, gt: np.ndarray, first_id: int, rng, step_cov: np.ndarray = STEP_COV) -> SessionPoses:
    """Odometry noised by exactly the covariance the session reports for each step (``step_cov``)."""
    L = np.linalg.cholesky(step_cov)
    odo = [np.eye(4)]
    for i in range(1, len(gt)):
        odo.append(odo[-1] @ inv(gt[i - 1]) @ gt[i] @ se3_exp(L @ rng.normal(size=6)))
    o = np.array(odo)
    return SessionPoses(name, np.arange(first_id, first_id + len(gt)), o, np.repeat(step_cov[None], len(gt), 0),
                        o.copy())


def scene(n_loops: int, false_share: float, seed: int) -> tuple[SessionChains, list[JointLoop], np.ndarray]:
    """Two sessions and ``n_loops`` loops between them; also which loops are true."""
    rng = np.random.default_rng(seed)
    n = n_loops + 1
    gt_a = route(n, rng)
    gt_b = gt_a @ make_T(so3_exp(np.array([0, 0, 0.2])), np.array([0.3, 1.0, 0]))  # driven beside it
    a, b = session("a", gt_a, 0, rng), session("b", gt_b, 100000, rng)
    L = np.linalg.cholesky(LOOP_COV)
    info = np.linalg.inv(LOOP_COV)
    false = rng.random(n_loops) < false_share
    loops = []
    for i in range(n_loops):
        j = i
        if false[i]:  # b's keyframe j claimed to be where b's keyframe i is
            far = np.flatnonzero(np.abs(np.arange(n) - i) >= min(20, (n - 1) // 2))
            j = int(rng.choice(far))
        Z = inv(gt_a[i]) @ gt_b[i] @ se3_exp(L @ rng.normal(size=6))
        loops.append(JointLoop(int(b.ids[j]), int(a.ids[i]), Z, info, True))
    return SessionChains([a, b], MapConfig()), loops, ~false


def timed(fn, repeat: int):
    out, times = None, []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def bench(n_loops: int, false_share: float, repeat: int, seed: int) -> float:
    chains, loops, true = scene(n_loops, false_share, seed)
    conf = MapConfig()
    thr = pcm_threshold(conf)
    X, t_stat = timed(lambda: pair_statistics(loops, chains), repeat)
    adj = X <= thr
    first, t_first = timed(lambda: maximum_clique(adj, conf.pcm_clique_budget), repeat)
    rest = np.ones(n_loops, bool)
    rest[first.members] = False
    rival, t_rival = timed(lambda: maximum_clique(adj, conf.pcm_clique_budget, allowed=rest), repeat)
    (d, _), t_judge = timed(lambda: judge_pair((0, 1), loops, chains, conf), repeat)
    tt = np.outer(true, true)
    np.fill_diagonal(tt, False)
    bad_true = int((~adj[tt]).sum()) // 2
    in_first = int(true[first.members].sum())
    print(f"N {n_loops:5d} ({int((~true).sum())} false): pair_statistics {t_stat:7.3f} s | "
          f"clique {t_first:7.3f} s ({first.nodes} nodes, {'exact' if first.exact else 'over budget'}; "
          f"{len(first.members)} loops, {in_first} true) | "
          f"rival {t_rival:7.3f} s ({rival.nodes} nodes, {'exact' if rival.exact else 'over budget'}; "
          f"{len(rival.members)} loops) | judge_pair {t_judge:7.3f} s ({d.decision}) | "
          f"inconsistent true pairs {bad_true} of {int(true.sum()) * (int(true.sum()) - 1) // 2}", flush=True)
    return t_judge


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loops", type=int, nargs="+", default=[100, 400, 1000], help="loops between the sessions")
    ap.add_argument("--false", type=float, default=0.0, help="share of the loops replaced by look-alikes")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)
    print(f"median of {args.repeat}; false share {args.false:g}", flush=True)
    judged = {n: bench(n, args.false, args.repeat, args.seed) for n in args.loops}
    if GOAL_N in judged:
        t = judged[GOAL_N]
        print(f"{GOAL_N} loops judged in {t:.2f} s (goal <= {GOAL_S:g} s): {'PASS' if t <= GOAL_S else 'FAIL'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
