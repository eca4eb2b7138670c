"""Section ``lifelong`` of tools/bench_map.py: twenty days of one demo world, kept as places and variants.

Twenty sessions of world 0 at 320x240, camera at 5 Hz (``--size``, ``--rate``), in four appearance
states (:mod:`slam_lcd.sim.appearance`): ``day`` under several lighting epochs and exposures,
``night``, ``moved`` (posters replaced) and ``renovated`` (the east half, once: the last session).
Routes (laps of block A, clockwise laps of block B, figure eights), start points and seeds differ
from session to session; each is a session log (odometry in its own frame). The sessions are
appended one at a time to two maps in the same run: the default (``map.lifelong``, places and
appearance variants) and ``map.lifelong=false`` (every keyframe kept). Held-out logs, one per
state, are localised against both maps; the renovated one also against the lifelong map as it was
before the renovated session (the state unseen).

Printed, with the targets beside them: kept and total keyframes, the joint graph's variables and
factors, and bytes on disk after sessions 3 and 20 (ratio 20/3); append wall time per keyframe of
sessions 3 and 20 (median of ``--cost-repeats`` appends, each to a copy of the map it met; features
cached for all, so the cost is the map's); ``Map.open`` + loop detector ready after 3 and 20 (median
of ``--load-repeats`` fresh processes); every session's ATE in the map frame against its odometry's
and against its ATE in the unreduced map, false loops between sessions; the held-out logs' share
localised, median error, keyframes more than 1 m off.

    python tools/bench_map.py lifelong --work W --weights W.pth
"""
from __future__ import annotations

import json
import logging
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

AT = (3, 20)  # the map is measured after these sessions


@dataclass(frozen=True)
class Day:
    """One recording: appearance state, route, start point (m along it), laps, seed, lighting epoch offset, exposure."""

    name: str
    appearance: str
    kind: str
    start_at: float
    laps: float
    seed: int
    lighting: float = 0.0
    exposure: float = 1.0


SESSIONS = [
    Day("s1", "day", "figure8", 2.0, 1.0, 201),
    Day("s2", "night", "figure8", 44.0, 1.0, 202, exposure=1.1),
    Day("s3", "day", "laps", 10.0, 1.3, 203, lighting=3.0, exposure=0.75),
    Day("s4", "day", "laps-b", 20.0, 1.2, 204, lighting=1.0),
    Day("s5", "night", "laps", 30.0, 1.2, 205),
    Day("s6", "moved", "figure8", 60.0, 1.0, 206),
    Day("s7", "day", "figure8", 20.0, 1.0, 207, lighting=5.0, exposure=1.1),
    Day("s8", "night", "laps-b", 5.0, 1.2, 208, exposure=1.2),
    Day("s9", "moved", "laps", 36.0, 1.2, 209, lighting=2.0),
    Day("s10", "day", "laps", 15.0, 1.2, 210, lighting=7.0, exposure=0.85),
    Day("s11", "night", "figure8", 70.0, 1.0, 211, exposure=0.9),
    Day("s12", "moved", "laps-b", 33.0, 1.2, 212, lighting=4.0),
    Day("s13", "day", "figure8", 30.0, 1.0, 213, lighting=9.0),
    Day("s14", "night", "laps", 0.0, 1.2, 214),
    Day("s15", "day", "laps-b", 10.0, 1.2, 215, lighting=2.0, exposure=1.2),
    Day("s16", "moved", "figure8", 50.0, 1.0, 216, lighting=6.0),
    Day("s17", "night", "laps-b", 25.0, 1.2, 217, exposure=1.1),
    Day("s18", "day", "laps", 25.0, 1.2, 218, lighting=11.0, exposure=0.9),
    Day("s19", "day", "figure8", 65.0, 1.0, 219, lighting=4.0),
    Day("s20", "renovated", "figure8", 10.0, 1.0, 220),
]
HELD_OUT = [
    Day("h-day", "day", "laps", 24.0, 1.0, 301, lighting=6.0, exposure=0.95),
    Day("h-night", "night", "laps-b", 12.0, 1.0, 302),
    Day("h-moved", "moved", "laps", 33.0, 1.0, 303, lighting=1.0),
    Day("h-renovated", "renovated", "laps-b", 30.0, 1.0, 304),
]
UNSEEN = "h-renovated"  # also localised against the lifelong map before the session that saw its state


def render_logs(work: Path, days: list[Day], size: tuple[int, int], rate: float) -> dict[str, Path]:
    """Each day as a session log (once: kept in ``work`` for later runs)."""
    from slam_lcd.sim import make_demo_log

    logs = {}
    for i, d in enumerate(days):
        path = work / f"{d.name}-{size[0]}x{size[1]}-{rate:g}hz.mcap"
        if not path.exists():
            make_demo_log(path, "mcap", width=size[0], height=size[1], camera_rate=rate, session=1 + i % 8,
                          world_seed=0, kind=d.kind, start_at=d.start_at, laps=d.laps, seed=d.seed,
                          lighting=d.lighting, exposure=d.exposure, appearance=d.appearance)
        logs[d.name] = path
    return logs


def run_one(log: Path, out: Path, cfg, extractor, m=None, name=None, mode="append") -> tuple[object, float]:
    """One run of ``log`` (appended to or localised in ``m``), and its wall time."""
    from slam_lcd.run import MapUse, Models, OutputOptions, run_log

    t0 = time.perf_counter()
    use = MapUse(m, mode=mode, session_name=name) if m is not None else None
    res = run_log(log, out, cfg, models=Models(extractor=extractor), map_use=use,
                  output=OutputOptions(progress=False, write_mcap=False))
    return res, time.perf_counter() - t0


def append(root: Path, log: Path, out: Path, cfg, extractor, meta, name: str) -> tuple[int, float]:
    """Append ``log`` to the map at ``root`` (made if absent): its keyframes and the wall time of the append."""
    from slam_lcd.map.session_map import Map

    t0 = time.perf_counter()
    with Map.open(root, features=meta, conf=cfg.map, write=True, create=True) as m:
        res, _ = run_one(log, out, cfg, extractor, m, name)
    return res.n_keyframes, time.perf_counter() - t0


def contents(root: Path) -> dict:
    """Kept and total keyframes, places, the joint graph's variables and factors, and bytes on disk of the map at
    ``root``, from its arrays."""
    from slam_lcd.map.lifelong import counts
    from slam_lcd.map.session_map import Map

    m = Map.open(root)
    c = counts(m.graph, m.sessions)
    size = sum(p.stat().st_size for p in root.rglob("*") if p.is_file() and p.name != ".lock")
    return {"kept": c["kept_keyframes"], "total": c["keyframes"], "places": c["places"], "bytes": int(size),
            "variables": c["graph_variables"], "factors": c["graph_factors"]}


def ready_time(root: Path, repeats: int) -> float:
    """``Map.open`` + loop detector ready: median over ``repeats`` fresh processes (``bench_map._measure_load``)."""
    runs = []
    for _ in range(repeats):
        code = (f"import json, sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import bench_map; "
                f"print(json.dumps(bench_map._measure_load({str(root)!r}, True)))")
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
        runs.append(json.loads(out.stdout.strip().splitlines()[-1])["ready_s"])
    return float(np.median(runs))


def sessions_table(root: Path, true_max: float) -> tuple[list[dict], int, int]:
    """Per session: keyframes, ATE in the map frame and of its odometry, joined; false and true loops
    between sessions."""
    from slam_lcd.map.session_map import Map
    from slam_lcd.map.summary import map_summary

    s = map_summary(Map.open(root))
    acc = [r for r in s["inter_session_loops"] if r["accepted"]]
    false = sum(1 for r in acc if r["gt_distance_m"] is None or r["gt_distance_m"] > true_max)
    return s["sessions"], false, len(acc) - false


def localise(log: Path, root: Path, out: Path, cfg, extractor, meta) -> dict:
    """``log`` localised against the map at ``root`` (read only): share, median error, keyframes over 1 m."""
    from slam_lcd.map.session_map import Map

    m = Map.open(root, features=meta, conf=cfg.map)
    res, wall = run_one(log, out, cfg, extractor, m, mode="localize")
    rep = res.localization
    e = rep["errors"] or {}
    return {"share": float(rep["share_localised"]), "n": int(rep["keyframes"]), "localised": int(rep["localised"]),
            "median": e.get("median_m"), "over_1m": e.get("over_1m"), "wall": wall}


def cost_of(k: int, runs: Path, label: str, logs, cfg, extractor, meta, first: tuple[int, float],
            repeats: int) -> float:
    """Append wall time per keyframe of session ``k``: median over the timed append and ``repeats - 1``
    more, each to a copy of the map as session ``k`` met it."""
    d = SESSIONS[k - 1]
    n, walls = first[0], [first[1]]
    for _ in range(repeats - 1):
        dst = runs / f"{label}-cost"
        shutil.rmtree(dst, ignore_errors=True)
        if (runs / f"{label}-before{k}").exists():
            shutil.copytree(runs / f"{label}-before{k}", dst)
        walls.append(append(dst, logs[d.name], runs / "cost-out", cfg, extractor, meta, d.name)[1])
    return float(np.median(walls)) / max(1, n)


def build(label: str, cfg, runs: Path, logs, extractor, meta, args) -> dict:
    """Append the twenty sessions to the map ``label``; keep copies after 3, before 3, 20 and after 19."""
    root = runs / label
    shutil.rmtree(root, ignore_errors=True)
    timed = {}
    for i, d in enumerate(SESSIONS, start=1):
        if i in AT and root.exists():
            shutil.copytree(root, runs / f"{label}-before{i}")
        timed[i] = append(root, logs[d.name], runs / f"{label}-out" / d.name, cfg, extractor, meta, d.name)
        if i in AT or i == len(SESSIONS) - 1:
            shutil.copytree(root, runs / f"{label}-after{i}")
        print(f"  {label}: {d.name} ({d.appearance}, {d.kind}) appended: {timed[i][0]} keyframes, "
              f"{timed[i][1]:.1f} s", flush=True)
    out = {"contents": {k: contents(runs / f"{label}-after{k}") for k in AT}}
    out["cost"] = {k: cost_of(k, runs, label, logs, cfg, extractor, meta, timed[k], args.cost_repeats) for k in AT}
    out["ready"] = {k: ready_time(runs / f"{label}-after{k}", args.load_repeats) for k in AT}
    out["sessions"], out["false"], out["true"] = sessions_table(root, cfg.run.loop_true_max_distance)
    return out


def _ratio_line(what: str, a: float, b: float, goal: float, unit: str = "") -> str:
    r = b / a if a else float("nan")
    verdict = "met" if r <= goal else f"MISSED by {100 * (r / goal - 1):.0f} %"
    return (f"  {what}: after {AT[0]} {a:{unit}}, after {AT[1]} {b:{unit}}, ratio {r:.2f} "
            f"(goal <= {goal:g}: {verdict})")


def report_map(label: str, r: dict) -> None:
    a, b = AT
    ca, cb = r["contents"][a], r["contents"][b]
    print(f"\nmap {label}: places {ca['places']} -> {cb['places']}; total keyframes {ca['total']} -> {cb['total']} "
          f"(ratio {cb['total'] / ca['total']:.2f})")
    print(_ratio_line("stored (kept) keyframes", ca["kept"], cb["kept"], 1.5, "d"))
    print(_ratio_line("bytes on disk (MB)", ca["bytes"] / 1e6, cb["bytes"] / 1e6, 1.5, ".1f"))
    print(_ratio_line("joint graph variables", ca["variables"], cb["variables"], 1.5, "d"))
    print(_ratio_line("joint graph factors", ca["factors"], cb["factors"], 1.5, "d"))
    print(_ratio_line("append cost (ms per keyframe)", 1e3 * r["cost"][a], 1e3 * r["cost"][b], 1.3, ".1f"))
    print(_ratio_line("Map.open + detector ready (s)", r["ready"][a], r["ready"][b], 1.5, ".2f"))
    worst = 0.0
    print("  ATE per session, odometry -> map frame (goal: map <= 10 % of odometry):")
    for s, d in zip(r["sessions"], SESSIONS, strict=True):
        ratio = s.get("ratio") or float("nan")
        worst = max(worst, ratio) if np.isfinite(ratio) else float("inf")
        print(f"    {s['name']:4s} {d.appearance:9s} {d.kind:8s} {s['keyframes']:4d} kf  "
              f"{s.get('ate_odometry') or float('nan'):.3f} -> {s.get('ate_map') or float('nan'):.4f} m "
              f"({100 * ratio:.1f} %){'' if s['joined'] else '  NOT JOINED'}")
    over = [s["name"] for s in r["sessions"] if not (s.get("ratio") is not None and s["ratio"] <= 0.10)]
    print(f"  worst ratio {100 * worst:.1f} % ({'met' if not over else 'MISSED by ' + ', '.join(over)}); "
          f"loops between sessions accepted: {r['true']} true, {r['false']} false (goal 0 false: "
          f"{'met' if r['false'] == 0 else 'MISSED'})")


def report_ate_against(lifelong: dict, unreduced: dict) -> None:
    """Each session's ATE in the lifelong map's frame against its ATE in the unreduced map (goal <= 1.2x)."""
    pairs = [(s["name"], (s.get("ate_map") or float("nan")) / (u.get("ate_map") or float("nan")))
             for s, u in zip(lifelong["sessions"], unreduced["sessions"], strict=True)]
    name, worst = max(pairs, key=lambda p: p[1] if np.isfinite(p[1]) else float("inf"))
    over = [n for n, r in pairs if not r <= 1.2]
    print(f"\nATE in the map frame, lifelong against unreduced (goal <= 1.2x each session): median "
          f"{float(np.median([r for _, r in pairs])):.3f}x, worst {name} {worst:.3f}x "
          f"({'met' if not over else 'MISSED by ' + ', '.join(over)})")


def report_localisation(loc: dict) -> None:
    print("\nheld-out logs localised (goal: >= 95 % per state, median error <= 1.1x the unreduced map's, 0 over 1 m)")
    for d in HELD_OUT:
        a, b = loc[("lifelong", d.name)], loc[("unreduced", d.name)]
        ratio = (a["median"] / b["median"]) if a["median"] and b["median"] else float("nan")
        ok = a["share"] >= 0.95 and b["share"] >= 0.95 and ratio <= 1.1 and a["over_1m"] == 0 and b["over_1m"] == 0
        print(f"  {d.name:12s} ({d.appearance}, {d.kind}): lifelong {100 * a['share']:.1f} % of {a['n']}, "
              f"median {_m(a['median'])}, {a['over_1m']} over 1 m; unreduced {100 * b['share']:.1f} % of {b['n']}, "
              f"median {_m(b['median'])}, {b['over_1m']} over 1 m; median ratio {ratio:.2f} "
              f"({'met' if ok else 'MISSED'})")
    u = loc[("unseen", UNSEEN)]
    print(f"  {UNSEEN} against the lifelong map before its state was seen (after {len(SESSIONS) - 1} sessions): "
          f"{100 * u['share']:.1f} %, median {_m(u['median'])}, {u['over_1m']} over 1 m "
          f"(goal < 80 %: {'met' if u['share'] < 0.8 else 'MISSED'}); after it was seen once: "
          f"{100 * loc[('lifelong', UNSEEN)]['share']:.1f} %")


def _m(x) -> str:
    return f"{x:.4f} m" if x is not None else "n/a"


def section_lifelong(args) -> None:
    from slam_lcd.config import load_config
    from slam_lcd.features import load_extractor
    from slam_lcd.map.session_map import extractor_meta
    from slam_lcd.runtime.machine import machine_line

    t_start = time.perf_counter()
    judged = logging.getLogger("slam_lcd.map.lifelong")  # each append's appearance verdict, printed
    judged.setLevel(logging.INFO)
    judged.addHandler(logging.StreamHandler(sys.stdout))
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    size = tuple(int(v) for v in args.size.split("x"))
    sets = [f"features.weights={args.weights}"] if args.weights else []
    sets += [f"features.cache_dir={work / 'cache'}", "run.plots=false", "run.loop_pictures=false", *args.set]
    cfgs = {"lifelong": load_config("default", sets),
            "unreduced": load_config("default", [*sets, "map.lifelong=false"])}
    extractor = load_extractor(cfgs["lifelong"].features)
    meta = extractor_meta(extractor, cfgs["lifelong"].map.descriptor_form)
    print(machine_line())
    print(f"features: {cfgs['lifelong'].features.kind} at {size[0]}x{size[1]}, camera at {args.rate:g} Hz; "
          f"{len(SESSIONS)} sessions of world 0, logs and feature cache in {work}", flush=True)
    logs = render_logs(work, SESSIONS + HELD_OUT, size, args.rate)
    print(f"  logs ready ({time.perf_counter() - t_start:.0f} s)", flush=True)
    runs = work / "lifelong"
    shutil.rmtree(runs, ignore_errors=True)
    runs.mkdir()
    for d in SESSIONS + HELD_OUT:  # plain runs fill the feature cache: every timed append reads cached features
        run_one(logs[d.name], runs / "warm", cfgs["lifelong"], extractor)
    print(f"  feature cache filled ({time.perf_counter() - t_start:.0f} s)", flush=True)
    res = {label: build(label, cfg, runs, logs, extractor, meta, args) for label, cfg in cfgs.items()}
    loc = {}
    for label, cfg in cfgs.items():
        for d in HELD_OUT:
            loc[(label, d.name)] = localise(logs[d.name], runs / label, runs / "loc-out", cfg, extractor, meta)
    loc[("unseen", UNSEEN)] = localise(logs[UNSEEN], runs / f"lifelong-after{len(SESSIONS) - 1}", runs / "loc-out",
                                       cfgs["lifelong"], extractor, meta)
    for label, r in res.items():
        report_map(label, r)
    report_ate_against(res["lifelong"], res["unreduced"])
    report_localisation(loc)
    print(f"\n(benchmark wall time {time.perf_counter() - t_start:.0f} s)")


def add_parser(sub) -> None:
    lf = sub.add_parser("lifelong", help="twenty sessions in four appearance states: lifelong vs unreduced map")
    lf.add_argument("--work", required=True)
    lf.add_argument("--weights", default=None)
    lf.add_argument("--size", default="320x240")
    lf.add_argument("--rate", type=float, default=5.0, help="camera rate (Hz) of the rendered logs")
    lf.add_argument("--set", action="append", default=[])
    lf.add_argument("--cost-repeats", type=int, default=3, help="appends of sessions 3 and 20 timed (median)")
    lf.add_argument("--load-repeats", type=int, default=3, help="fresh processes per Map.open + ready time")
    lf.set_defaults(func=section_lifelong)
