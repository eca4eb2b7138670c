#!/usr/bin/env python
"""Maps on every odometry and in every order: demo sessions joined under each odometry covariance, and
sessions 1-3 appended in all six orders.

Section ``covariance``: demo sessions 1 and 2 (``--size``, ``--features``; default 320x240 ORB)
appended into a fresh map once per value of ``frontend.odom_covariance`` (absolute, relative,
model). Printed per value: the loops offered between the sessions that are true by ground truth,
how many the joint graph accepted (the goal: >= 90 %) and how many false ones (goal 0); the
components; each session's own loops accepted in its plain run and in the map.

Section ``orders``: sessions 1-3 appended into one map (every loop between them exists then),
then the map's sessions and loops replayed through the joint graph in all six orders
(:func:`slam_lcd.map.replay.append_in_order`). A run finds loops only to the sessions the map
holds when it runs, so end to end the loops offered differ by order; the replay asks whether the
same sessions and loops give the same map. Printed per order: components, loops kept between
sessions (false by ground truth), the ATE of the whole map (one SE(3) alignment), and whether
the kept loops are those of the first order.

    python tools/bench_map_odometry.py covariance --work W
    python tools/bench_map_odometry.py orders --work W
"""
from __future__ import annotations

import argparse
import itertools
import shutil
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_map import judge, run_session

from slam_lcd.runtime.machine import machine_line


def ensure(work: Path, size: str, sessions) -> dict[int, Path]:
    from slam_lcd.cli.util import parse_size
    from slam_lcd.sim import make_demo_log

    w, h = parse_size(size)
    out = {}
    for k in sessions:
        path = work / f"s{k}-{w}x{h}.mcap"
        if not path.exists():
            make_demo_log(path, "mcap", session=k, width=w, height=h)
        out[k] = path
    return out


def _config(args, extra=()):
    from slam_lcd.config import load_config

    sets = [f"features.kind={args.features}"] + ([f"features.weights={args.weights}"] if args.weights else [])
    return load_config("default", sets + list(args.set) + list(extra))


def _offered_true(summary, true_max: float) -> int:
    return sum(1 for r in summary["inter_session_loops"]
               if r["gt_distance_m"] is not None and r["gt_distance_m"] <= true_max)


def own_loops(m) -> dict[str, int]:
    """Each session's own accepted loops in the map (visual links not counted)."""
    from slam_lcd.map.joint_types import is_link
    from slam_lcd.map.session_graph import existing_loops

    where = {int(k): meta["name"] for meta, s in zip(m.manifest.sessions, m.sessions, strict=True) for k in s.ids}
    out = {meta["name"]: 0 for meta in m.manifest.sessions}
    for lp in existing_loops(m.sessions, m.graph):
        if lp.accepted and not lp.inter and not is_link(lp):
            out[where[int(lp.query)]] += 1
    return out


def _append_all(order, logs, cfg, runs: Path, tag: str):
    from slam_lcd.features import load_extractor
    from slam_lcd.map.session_map import Map, extractor_meta

    extractor = load_extractor(cfg.features)
    meta = extractor_meta(extractor, cfg.map.descriptor_form)
    root = runs / f"map_{tag}"
    shutil.rmtree(root, ignore_errors=True)
    for k in order:
        with Map.open(root, features=meta, conf=cfg.map, write=True, create=True) as m:
            run_session(logs[k], runs / f"{tag}_s{k}", cfg, extractor, m, f"s{k}")
    return Map.open(root)


def section_covariance(args) -> None:
    from slam_lcd.features import load_extractor

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    logs = ensure(work, args.size, (1, 2))
    runs = work / "runs_cov"
    print(machine_line())
    print(f"demo sessions 1 and 2, {args.size}, {args.features}")
    for value in args.values:
        cfg = _config(args, [f"frontend.odom_covariance={value}"])
        extractor = load_extractor(cfg.features)
        plain = {k: run_session(logs[k], runs / f"plain_{value}_s{k}", cfg, extractor)[0] for k in (1, 2)}
        m = _append_all((1, 2), logs, cfg, runs, value)
        j = judge(m, cfg.run.loop_true_max_distance)
        s = j["summary"]
        d = j["pairs"].get("s1 - s2", {"true": 0, "false": 0})
        offered = _offered_true(s, cfg.run.loop_true_max_distance)
        within = own_loops(m)
        share = d["true"] / offered if offered else float("nan")
        print(f"{value:9s}: between s1 and s2 {d['true']} of {offered} true loops accepted ({100 * share:.0f} %; "
              f"goal >= 90 %), {d['false']} false; components {s['components']}; own loops plain run / map: "
              + ", ".join(f"s{k} {plain[k].loops_accepted} / {within.get(f's{k}')}" for k in (1, 2))
              + f"  {'PASS' if share >= 0.9 and d['false'] == 0 and len(s['components']) == 1 else 'FAIL'}")


def section_orders(args) -> None:
    """Sessions 1-3 appended into one map (in the order 1, 2, 3: every loop between them exists then), then
    the map's sessions and loops replayed through the joint graph in all six orders."""
    from slam_lcd.eval.align import umeyama
    from slam_lcd.map.replay import append_in_order, fresh
    from slam_lcd.map.session_graph import existing_loops, session_poses

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    logs = ensure(work, args.size, (1, 2, 3))
    cfg = _config(args)
    print(machine_line())
    print(f"demo sessions 1-3, {args.size}, {args.features}: their sessions and loops in all six orders")
    m = _append_all((1, 2, 3), logs, cfg, work / "runs_orders", "123")
    loops = [fresh(lp) for lp in existing_loops(m.sessions, m.graph)]
    poses = session_poses(m.manifest.sessions, m.sessions, {}, loops, cfg.map)
    sessions = {p.name: p for p in poses}
    gt = {int(k): T for s in m.sessions for k, T in zip(s.ids, s.T_gt, strict=True)}
    name_of = {int(k): p.name for p in poses for k in p.ids}
    true_max = cfg.run.loop_true_max_distance
    first = None
    for order in itertools.permutations(sorted(sessions)):
        results, state = append_in_order(sessions, loops, order, cfg.map)
        res = results[-1]
        kept = {k for k, (acc, _) in state.items() if acc and name_of[k[0]] != name_of[k[1]]}
        false = sum(1 for q, mt in kept if np.linalg.norm(gt[q][:3, 3] - gt[mt][:3, 3]) > true_max)
        ids = np.array(sorted(res.poses))
        est = np.array([res.poses[int(k)][:3, 3] for k in ids])
        ref = np.array([gt[int(k)][:3, 3] for k in ids])
        R, t, _ = umeyama(est, ref, with_scale=False)
        ate = float(np.sqrt(np.mean(np.sum((est @ R.T + t - ref) ** 2, axis=1))))
        comps = sorted(sorted(n for n, c_ in res.component.items() if c_ == c0) for c0 in set(res.component.values()))
        verdict = "the same as" if kept == first else "DIFFER from"
        same = "" if first is None else f"; kept loops {verdict} the first order's"
        first = kept if first is None else first
        print(f"order {' '.join(order)}: components {comps}; {len(kept)} loops between sessions kept ({false} false); "
              f"ATE of the map {ate:.4f} m{same}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="section", required=True)
    for name in ("covariance", "orders"):
        p = sub.add_parser(name)
        p.add_argument("--work", required=True)
        p.add_argument("--size", default="320x240")
        p.add_argument("--features", choices=["orb", "superpoint"], default="orb")
        p.add_argument("--weights", default=None)
        p.add_argument("--set", action="append", default=[])
    sub.choices["covariance"].add_argument("--values", nargs="+", default=["absolute", "relative", "model"],
                                           choices=["absolute", "relative", "model"])
    args = ap.parse_args()
    {"covariance": section_covariance, "orders": section_orders}[args.section](args)


if __name__ == "__main__":
    main()
