#!/usr/bin/env python
"""What an append costs in the joint graph as the map grows: per-append seconds, recorded verdicts on and off.

Synthetic sessions of one route (``--keyframes`` each, odometry noised by the covariance it
gives), each with ``--loops`` true loops to the session before it and 5 % false ones, appended one
by one as a map appends them (:func:`slam_lcd.map.joint_graph.solve` with the verdicts and loop
states of the earlier appends carried on, each session placed where the previous solve put it).

Printed per append: the seconds of the solve with the recorded verdicts (what ``Map.add_session``
does), and of the same solve asked to judge every pair again (``judged`` empty: the cost a map
without records pays), the pairs judged and kept, and the ratio of the last append to the second
(the goal: <= 1.2 with recorded verdicts). Medians of ``--repeat`` runs of each append.

    python tools/bench_joint.py [--sessions 6] [--loops 400] [--keyframes 450] [--repeat 3]
"""
from __future__ import annotations

import argparse
import copy
import statistics
import time

import numpy as np
from bench_pcm import session as noisy_session  # tools/ is the script's folder

from slam_lcd.geometry import inv, make_T, se3_exp, so3_exp
from slam_lcd.map.joint_graph import JointLoop, SessionPoses, solve
from slam_lcd.map.pair_verdicts import record
from slam_lcd.runtime.machine import machine_line

STEP_COV = np.diag([0.002 ** 2] * 3 + [0.01 ** 2] * 3)  # per 0.5 m keyframe step
LOOP_INFO = np.linalg.inv(np.diag([0.01 ** 2] * 3 + [0.03 ** 2] * 3))


def route(n: int, seed: int) -> np.ndarray:
    """Body poses 0.5 m apart, a right-angle turn every 40 keyframes and a slight wander."""
    rng = np.random.default_rng(seed)
    T = [np.eye(4)]
    for i in range(1, n):
        yaw = np.pi / 2 if i % 40 == 0 else rng.normal(0, 0.01)
        T.append(T[-1] @ make_T(so3_exp(np.array([0, 0, yaw])), np.array([0.5, 0, 0])))
    return np.array(T)


def session(name: str, gt: np.ndarray, first: int, rng) -> SessionPoses:
    """Odometry noised by the covariance it reports (:func:`bench_pcm.session`), its own estimate recorded: the
    placed sessions' ``T_init`` become map poses, and the verdicts read ``T_own``."""
    s = noisy_session(name, gt, first, rng, STEP_COV)
    s.T_own = s.T_odom.copy()
    return s


def world(n_sessions: int, keyframes: int, n_loops: int, seed: int):
    rng = np.random.default_rng(seed)
    gt0 = route(keyframes, seed)
    gts, sessions, loops = [], [], []
    L = np.linalg.cholesky(np.linalg.inv(LOOP_INFO))
    for k in range(n_sessions):
        gt = gt0 @ make_T(np.eye(3), np.array([0.0, 0.3 * (k % 3), 0.0]))
        gts.append(gt)
        sessions.append(session(f"s{k}", gt, 100000 * k, rng))
        if k == 0:
            continue
        idx = np.linspace(0, keyframes - 1, n_loops).astype(int)
        pair = [JointLoop(100000 * k + int(j), 100000 * (k - 1) + int(j),
                          inv(gts[k - 1][j]) @ gt[j] @ se3_exp(L @ rng.normal(size=6)), LOOP_INFO, True) for j in idx]
        for i, j in rng.integers(0, keyframes, (n_loops // 20, 2)):
            pair.append(JointLoop(100000 * k + int(j), 100000 * (k - 1) + int(i), se3_exp(rng.normal(0, 1.0, 6)),
                                  LOOP_INFO, True))
        loops.append(pair)
    return sessions, loops


def appends(sessions, loops, repeat: int, keep_records: bool) -> list[dict]:
    """Each append's median seconds, with the records of the earlier appends (or judging all again)."""
    judged: dict = {}
    state: dict = {}
    res, out = None, []
    for k in range(2, len(sessions) + 1):
        subset = []
        for s0 in sessions[:k]:
            s = copy.copy(s0)
            if res is not None and s.name in res.component:
                s.prev_component = res.component[s.name]
                s.T_init = np.array([res.poses[int(i)] for i in s.ids])
            subset.append(s)
        times = []
        for _ in range(repeat):
            now = []
            for group in loops[:k - 1]:
                for lp in group:
                    lp = copy.copy(lp)
                    if (lp.query, lp.match) in state:
                        lp.accepted, lp.reason = state[(lp.query, lp.match)]
                    now.append(lp)
            t0 = time.perf_counter()
            r = solve(subset, now, judged=judged if keep_records else {})
            times.append(time.perf_counter() - t0)
        res = r
        judged = {tuple(d.sessions): record(d, r.rule) for d in r.pairs}
        state = {(lp.query, lp.match): (lp.accepted and not lp.reason.startswith("gnc"), lp.reason) for lp in now}
        false_kept = sum(1 for lp in now if lp.accepted and lp.query % 100000 != lp.match % 100000)
        out.append({"append": k, "s": statistics.median(times), "judged": sum(d.status != "kept" for d in r.pairs),
                    "joined": sum(d.decision == "joined" for d in r.pairs), "false_kept": false_kept})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sessions", type=int, default=6)
    ap.add_argument("--loops", type=int, default=400, help="true loops between each session and the one before")
    ap.add_argument("--keyframes", type=int, default=450, help="keyframes per session")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    print(machine_line())
    sessions, loops = world(args.sessions, args.keyframes, args.loops, args.seed)
    kept = appends(sessions, loops, args.repeat, True)
    again = appends(sessions, loops, args.repeat, False)
    print(f"{args.sessions} sessions of {args.keyframes} keyframes, {args.loops} true loops (+5 % false) per pair")
    print("append  recorded verdicts (s)  pairs judged  |  judging every pair again (s)  pairs judged  | "
          "joined  false kept")
    for a, b in zip(kept, again, strict=True):
        print(f"{a['append']:6d}  {a['s']:21.2f}  {a['judged']:12d}  |  {b['s']:28.2f}  {b['judged']:12d}  | "
              f"{a['joined']:6d}  {a['false_kept']:10d}")
    ratio = kept[-1]["s"] / kept[0]["s"]
    print(f"append {kept[-1]['append']} / append 2 with recorded verdicts: {ratio:.2f}x (goal <= 1.2): "
          f"{'PASS' if ratio <= 1.2 else 'FAIL'}")
    print(f"append {again[-1]['append']} / append 2 judging every pair again: {again[-1]['s'] / again[0]['s']:.2f}x")


if __name__ == "__main__":
    main()
