#!/usr/bin/env python
"""Multi-session map benchmarks: the demo world's sessions joined into one map, localisation, load cost.

Section ``sessions`` (the demo world's session presets, ``make-demo-log --session K``, rendered
into ``--work`` once): sessions 1-3 (same world, other starts and routes, session 3 under
changed lighting) appended one by one with ``run --map``, then the same three in one call;
session 4 (another world) appended to a copy; session 5 localised against the 3-session map.
Printed: loops between every pair of sessions (true / false by ground truth: keyframes of one
world within ``run.loop_true_max_distance``; any loop into another world is false), components,
each session's ATE in the common frame (one SE(3) alignment of the whole map to ground truth)
against its own odometry ATE, the localised share and errors, whether the map's bytes changed,
and the wall time per keyframe of each append against a plain ``run`` of the same log, measured
in the same run (features cached for both: the comparison is of what the map adds).

Section ``load``: a map of ``--keyframes`` keyframes made by repeating the sessions' real
keyframes (new ids; the files a map of that size would hold), then ``Map.open`` (read + sha256 +
arrays) and ``Map.open`` + ``load_into`` (the loop detector ready to query: BoW database rebuilt
from the stored descriptors), median of ``--repeat`` runs each in a fresh process, resident
memory, bytes per keyframe on disk.

Section ``lifelong`` (:mod:`bench_map_lifelong`): twenty sessions in four appearance states appended
to a lifelong map and to an unreduced one; growth, append and load cost, ATE, localisation.

    python tools/bench_map.py sessions --work W --weights W.pth
    python tools/bench_map.py load --work W [--keyframes 5000]
    python tools/bench_map.py lifelong --work W --weights W.pth
"""
from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from slam_lcd.runtime.machine import machine_line

WORLD_OF = {1: 0, 2: 0, 3: 0, 4: 1000, 5: 0}


def ensure_sessions(work: Path, frames: int | None) -> dict[int, Path]:
    from slam_lcd.sim import make_demo_log

    logs = {}
    for k in (1, 2, 3, 4, 5):
        path = work / (f"s{k}.mcap" if frames is None else f"s{k}-f{frames}.mcap")
        if not path.exists():
            make_demo_log(path, "mcap", frames=frames, session=k)
        logs[k] = path
    return logs


def map_files_digest(root: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(root.rglob("*")):
        if p.is_file() and p.name != ".lock":
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def judge(m, true_max: float) -> dict:
    """Loops between sessions by pair, true / false from the keyframes' ground truth (and world)."""
    from slam_lcd.map.summary import map_summary

    s = map_summary(m)
    world = {meta["name"]: WORLD_OF.get(int(meta["name"].lstrip("s").split("-")[0] or 0), 0)
             for meta in m.manifest.sessions}
    pairs: dict[str, dict] = {}
    for r in s["inter_session_loops"]:
        if not r["accepted"]:
            continue
        key = " - ".join(sorted((r["query_session"], r["match_session"])))
        same = world[r["query_session"]] == world[r["match_session"]]
        true = same and r["gt_distance_m"] is not None and r["gt_distance_m"] <= true_max
        d = pairs.setdefault(key, {"true": 0, "false": 0})
        d["true" if true else "false"] += 1
    return {"summary": s, "pairs": pairs}


def run_session(log, out, cfg, extractor, m=None, name=None, mode="append"):
    from slam_lcd.run import MapUse, Models, OutputOptions, run_log

    t0 = time.perf_counter()
    use = MapUse(m, mode=mode, session_name=name) if m is not None else None
    res = run_log(log, out, cfg, models=Models(extractor=extractor), map_use=use,
                  output=OutputOptions(progress=False))
    return res, time.perf_counter() - t0


def section_sessions(args) -> None:
    from slam_lcd.config import load_config
    from slam_lcd.features import load_extractor
    from slam_lcd.map.session_map import Map, extractor_meta

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    logs = ensure_sessions(work, args.frames)
    sets = [f"features.weights={args.weights}"] if args.weights else []
    if args.features:
        sets.append(f"features.kind={args.features}")
    cfg = load_config("default", sets + list(args.set))
    extractor = load_extractor(cfg.features)
    meta = extractor_meta(extractor, cfg.map.descriptor_form)
    print(machine_line())
    print(f"features: {cfg.features.kind}; logs in {work}")
    runs = work / "runs"
    shutil.rmtree(runs, ignore_errors=True)
    # plain runs (they also fill the feature cache, so every timed run below reads cached features)
    plain = {}
    for k in (1, 2, 3):
        run_session(logs[k], runs / f"warm{k}", cfg, extractor)
        res, wall = run_session(logs[k], runs / f"plain{k}", cfg, extractor)
        plain[k] = (res, wall)
    # appended one by one (each its own Map.open, as three `run --map` commands)
    root = runs / "map_one_by_one"
    appended = {}
    for k in (1, 2, 3):
        if root.exists():  # the map as the append of session k found it (the cost pairs below start from it)
            shutil.copytree(root, runs / f"map_before{k}")
        with Map.open(root, features=meta, conf=cfg.map, write=True, create=True) as m:
            res, wall = run_session(logs[k], runs / f"append{k}", cfg, extractor, m, f"s{k}")
            appended[k] = (res, wall)
    # the same three in one call
    root_one = runs / "map_one_call"
    with Map.open(root_one, features=meta, conf=cfg.map, write=True, create=True) as m:
        for k in (1, 2, 3):
            run_session(logs[k], runs / f"onecall{k}", cfg, extractor, m, f"s{k}")
    for label, r in (("one by one", root), ("one call", root_one)):
        m = Map.open(r)
        j = judge(m, cfg.run.loop_true_max_distance)
        s = j["summary"]
        print(f"\n3 sessions appended {label}: {len(s['components'])} component(s) {s['components']}; "
              f"visual links {s['visual_links']}")
        for pair, d in sorted(j["pairs"].items()):
            print(f"  loops {pair}: {d['true']} true, {d['false']} false")
        for row in s["sessions"]:
            print(f"  {row['name']}: {row['keyframes']} keyframes, "
                  f"ATE odometry {row.get('ate_odometry', float('nan')):.3f} m"
                  f" -> map {row.get('ate_map', float('nan')):.4f} m "
                  f"(ratio {100 * (row.get('ratio') or float('nan')):.1f} %)")
    # cost: interleaved pairs (plain run, then the same log appended to a copy of the map it met),
    # repeated, medians: a busy neighbour then slows both sides of a pair alike
    times = {k: {"plain": [plain[k][1]], "append": [appended[k][1]]} for k in (1, 2, 3)}
    for _ in range(args.cost_repeats - 1):
        for k in (1, 2, 3):
            times[k]["plain"].append(run_session(logs[k], runs / "cost_plain", cfg, extractor)[1])
            dst = runs / "cost_map"
            shutil.rmtree(dst, ignore_errors=True)
            if k > 1:
                shutil.copytree(runs / f"map_before{k}", dst)
            with Map.open(dst, features=meta, conf=cfg.map, write=True, create=True) as m:
                times[k]["append"].append(run_session(logs[k], runs / "cost_append", cfg, extractor, m, f"s{k}")[1])
    print(f"\nappend cost (features cached): wall per keyframe (medians), append / plain run of the same log "
          f"(median of the ratios of {args.cost_repeats} interleaved pairs)")
    for k in (1, 2, 3):
        n = max(1, plain[k][0].n_keyframes)
        pk, ak = np.median(times[k]["plain"]) / n, np.median(times[k]["append"]) / n
        ratios = [a / p for a, p in zip(times[k]["append"], times[k]["plain"], strict=True)]
        print(f"  s{k}: plain {1000 * pk:.1f} ms/kf, append {1000 * ak:.1f} ms/kf, ratio {np.median(ratios):.2f} "
              f"(pairs {', '.join(f'{x:.2f}' for x in ratios)}; map before: {k - 1} sessions)")
    # session 4 (another world) into a copy
    root4 = runs / "map_plus_other_world"
    shutil.copytree(root, root4)
    with Map.open(root4, features=meta, conf=cfg.map, write=True) as m:
        run_session(logs[4], runs / "append4", cfg, extractor, m, "s4")
    j = judge(Map.open(root4), cfg.run.loop_true_max_distance)
    s4 = next(r for r in j["summary"]["sessions"] if r["name"] == "s4")
    false4 = sum(d["false"] for p, d in j["pairs"].items() if "s4" in p)
    offered4 = sum(1 for r in j["summary"]["inter_session_loops"] if "s4" in (r["query_session"], r["match_session"]))
    print(f"\nsession 4 (other world): joined {s4['joined']}, component {s4['component']}, loops to it accepted "
          f"{s4['inter_session_loops']} ({false4} false), offered {offered4}; note: {s4.get('note', '')}")
    # session 5 localised against the 3-session map
    before = map_files_digest(root)
    m = Map.open(root, features=meta, conf=cfg.map)
    res, wall = run_session(logs[5], runs / "localize5", cfg, extractor, m, mode="localize")
    rep = res.localization
    e = rep["errors"] or {}
    print(f"\nlocalise session 5: {rep['localised']} of {rep['keyframes']} keyframes "
          f"({100 * rep['share_localised']:.1f} %)"
          f", median error {e.get('median_m', float('nan')):.4f} m, max {e.get('max_m', float('nan')):.4f} m, "
          f"{e.get('over_1m')} over 1 m; map bytes unchanged: {map_files_digest(root) == before}; {wall:.1f} s")
    size = sum(p.stat().st_size for p in root.rglob('*') if p.is_file())
    n = Map.open(root).n_keyframes
    print(f"map on disk: {size / 1e6:.1f} MB, {n} keyframes, {size / n / 1e3:.0f} kB per keyframe")


def _source_vocab(src: Path) -> dict:
    """The source map's vocabulary snapshot: its own, or made by replaying it once (not timed)."""
    from slam_lcd.lcd import LoopDetector
    from slam_lcd.map.session_map import Map
    from slam_lcd.vocab.snapshot import snapshot

    m = Map.open(src)
    det = LoopDetector()
    m.load_into(det)
    return snapshot(det.db, "int8")


def _replicated_vocab(v: dict, src_ids: np.ndarray, pieces: list[tuple[int, np.ndarray]]) -> dict:
    """A snapshot for the repeated map: the source's words once per repetition (word ids offset), each
    keyframe's bag of words from its source keyframe; the word index's graph built over all of them."""
    import faiss

    from slam_lcd.vocab import VocabConfig
    from slam_lcd.vocab.word_index import WordIndex

    W = len(v["lengths"])
    at = {int(k): i for i, k in enumerate(v["kf_ids"])}
    off = v["bow_offsets"]
    reps = max(r for r, _ in pieces) + 1
    words, counts, lens = [], [], []
    for rep, src_kf in pieces:
        for k in src_kf:
            i = at[int(k)]
            words.append(v["bow_words"][off[i]:off[i + 1]] + rep * W)
            counts.append(v["bow_counts"][off[i]:off[i + 1]])
            lens.append(off[i + 1] - off[i])
    out = dict(v)
    for k in ("centres_q", "centres_scale", "lengths", "counts", "images"):
        out[k] = np.concatenate([v[k]] * reps)
    out["bow_words"], out["bow_counts"] = np.concatenate(words), np.concatenate(counts)
    out["bow_offsets"] = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
    out["n_images"] = np.array(int(v["n_images"]) * reps)
    centres = out["centres_q"].astype(np.float32) / out["centres_scale"][:, None]
    idx = WordIndex.from_config(centres.shape[1], VocabConfig())
    idx._image_ends.extend([len(centres)] * (idx.fresh_images + 1))
    t = time.perf_counter()
    idx._build(centres)
    print(f"  (word index built over {len(centres)} words for the snapshot: {time.perf_counter() - t:.0f} s, "
          f"not timed)")
    out["graph"] = faiss.serialize_index(idx.graph)
    out["proj"] = idx.proj
    out["index_state"] = np.array([idx.n_indexed, idx.built_at, idx.n_builds], np.int64)
    out["image_ends"] = np.array(list(idx._image_ends), np.int64)
    return out


def _replicated(src: Path, dst: Path, keyframes: int, vocab: bool = False) -> None:
    from slam_lcd.map import store
    from slam_lcd.map.store import MapGraph, MapManifest, SessionKeyframes

    man = store.read_manifest(src)
    sess = [store.read_session(src, man, i) for i in range(len(man.sessions))]
    shutil.rmtree(dst, ignore_errors=True)
    dst.mkdir(parents=True)
    new, table, next_id, total, rep = [], [], 0, 0, 0
    pieces = []  # (repetition, source keyframe ids) per repeated session
    while total < keyframes:
        for meta, s in zip(man.sessions, sess, strict=True):
            n = min(len(s), keyframes - total)
            if n <= 0:
                break
            K = int(s.offsets[n])
            ids = np.arange(next_id, next_id + n, dtype=np.int64)
            cut = SessionKeyframes(ids, s.stamps[:n], s.T_odom[:n], s.cov[:n], s.T_gt[:n], s.offsets[:n + 1],
                                   s.keypoints[:K], s.descriptors[:K], s.scales[:K] if len(s.scales) else s.scales,
                                   s.points3d[:K], s.points_source[:n])
            name = f"{meta['name']}-r{rep}"
            m = dict(meta, name=name, keyframes=n, kf_id_start=int(ids[0]), kf_id_end=int(ids[-1]) + 1,
                     component=0)
            m.pop("file", None)
            new.append((m, cut))
            pieces.append((rep, s.ids[:n]))
            table.append(m)
            next_id += n
            total += n
        rep += 1
    ids = np.concatenate([s.ids for _, s in new])
    graph = MapGraph(ids, np.concatenate([s.T_odom for _, s in new]), np.zeros(0, np.int64), np.zeros(0, np.int64),
                     np.zeros((0, 4, 4)), np.zeros((0, 6, 6)), np.zeros(0, bool), np.zeros(0, "<U8"))
    snap = None
    if vocab:
        v = _source_vocab(src)
        snap = _replicated_vocab(v, None, pieces)
        snap["kf_ids"] = ids
    store.commit(dst, MapManifest(features=man.features), new, graph, table, snap)


def _rss_mb() -> float:
    """Resident memory now (VmRSS), MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _measure_load(root: str, ready: bool) -> dict:
    from slam_lcd.lcd import LoopDetector
    from slam_lcd.map.session_map import Map

    rss0 = _rss_mb()  # after the imports: what the map itself adds
    t0 = time.perf_counter()
    m = Map.open(root)
    t1 = time.perf_counter()
    out = {"open_s": t1 - t0, "keyframes": m.n_keyframes}
    if ready:
        det = LoopDetector()
        m.load_into(det)
        out["ready_s"] = time.perf_counter() - t0
    out["rss_growth_mb"] = _rss_mb() - rss0
    return out


def store_vocab_bytes(root: Path) -> int:
    man = json.loads((root / "map.json").read_text())
    return int(man["files"][man["vocab_file"]]["bytes"]) if man.get("vocab_file") else 0


def section_load(args) -> None:
    work = Path(args.work)
    src = Path(args.source) if args.source else work / "runs" / "map_one_by_one"
    if not (src / "map.json").exists():
        sys.exit(f"{src}: no map to repeat; run the sessions section first or give --source")
    big = work / f"map_{args.keyframes}"
    _replicated(src, big, args.keyframes, vocab=args.snapshot)
    size = sum(p.stat().st_size for p in big.rglob("*") if p.is_file())
    vfile = store_vocab_bytes(big)
    print(machine_line())
    print(f"map of {args.keyframes} keyframes (the sessions of {src} repeated): {size / 1e6:.0f} MB on disk, "
          f"{size / args.keyframes / 1e3:.0f} kB per keyframe"
          + (f" (vocabulary snapshot {vfile / args.keyframes / 1e3:.1f} kB per keyframe)" if vfile else ""))
    for ready in (False, True):
        runs = []
        for _ in range(args.repeat):
            code = (f"import json, sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); import bench_map; "
                    f"print(json.dumps(bench_map._measure_load({str(big)!r}, {ready})))")
            out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
            runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
        key = "ready_s" if ready else "open_s"
        t = np.median([r[key] for r in runs])
        mem = np.median([r["rss_growth_mb"] for r in runs])
        what = "Map.open + load_into (detector ready to query)" if ready else "Map.open (read, sha256, arrays)"
        print(f"  {what}: median {t:.2f} s over {args.repeat} fresh processes "
              f"({', '.join(f'{r[key]:.2f}' for r in runs)}), resident memory +{mem:.0f} MB "
              f"({mem * 1e3 / args.keyframes:.0f} kB per keyframe)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="section", required=True)
    s = sub.add_parser("sessions")
    s.add_argument("--work", required=True)
    s.add_argument("--weights", default=None)
    s.add_argument("--features", choices=["superpoint", "orb"], default=None)
    s.add_argument("--frames", type=int, default=None, help="frames per session (default: the presets' laps)")
    s.add_argument("--set", action="append", default=[])
    s.add_argument("--cost-repeats", type=int, default=3, help="interleaved plain/append pairs per session")
    s.set_defaults(func=section_sessions)
    lo = sub.add_parser("load")
    lo.add_argument("--work", required=True)
    lo.add_argument("--source", default=None, help="a map to repeat (default: WORK/runs/map_one_by_one)")
    lo.add_argument("--keyframes", type=int, default=5000)
    lo.add_argument("--repeat", type=int, default=3)
    lo.add_argument("--snapshot", action="store_true",
                    help="give the repeated map a vocabulary snapshot (the source's words repeated; made untimed)")
    lo.set_defaults(func=section_load)
    import bench_map_lifelong

    bench_map_lifelong.add_parser(sub)
    args = ap.parse_args()
    args.func(args)


if __name__ == "__main__":
    main()
