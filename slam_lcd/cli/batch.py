"""`slam-lcd batch LOG_OR_GLOB... --out DIR`: one `run` per log, on a local process pool or on Ray.

Exit status: 0 when every log is ok or skipped; 2 when any log failed (its error row says
why; the others ran) or when the batch cannot start (bad flags, no log, unwritable --out);
130 after a Ctrl-C, 143 after SIGTERM, 129 after SIGHUP (finished logs kept, running ones write
partial sets, the workers stopped, the summary written marked partial).
"""
from __future__ import annotations

from pathlib import Path

from ..runtime.interrupts import exit_status
from .run import add_alias, add_config_args, config_from_args, config_inputs


def register(sub) -> None:
    p = sub.add_parser("batch", help="run many logs (one `run` each) and summarise them, locally or on Ray",
                       description="Run `slam-lcd run` on every log into DIR/<log name>/ (the same outputs), on a "
                                   "local process pool or as Ray tasks, and write DIR/summary.csv, summary.md and "
                                   "ate_before_after.png with one row per log. A failing log becomes an error row "
                                   "and the others go on; logs with complete outputs of the same configuration are "
                                   "skipped (--force redoes them). Exit status 0 when all logs are ok or skipped, "
                                   "2 when any failed, 130 after Ctrl-C. See docs/batch.md.")
    p.add_argument("logs", nargs="+", metavar="LOG_OR_GLOB",
                   help="ROS1 .bag, .mcap, rosbag2 folder, a folder holding logs, or a glob pattern (quote it: "
                        "'fleet/**/*.bag')")
    p.add_argument("-o", "--out", required=True,
                   help="output folder (required; created if missing): one folder per log and the summary")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="logs run at once (default: one per CPU core / batch.cpus_per_task, at most one per log; "
                        "1 = one after the other in this process; with --ray: the most logs in flight, default all)")
    p.add_argument("--ray", nargs="?", const="local", default=None, metavar="auto|local|ADDRESS",
                   help="run as Ray tasks (needs `pip install slam-lcd[ray]`): local = start a Ray on this machine "
                        "(the default when --ray is given without a value), auto = join the running cluster, or a "
                        "cluster address (ray://head:10001). Default: no Ray, a local process pool")
    p.add_argument("--force", action="store_true",
                   help="redo logs whose complete outputs exist (default: skip them)")
    p.add_argument("--image-topic", default=None,
                   help="camera image topic of every log (default: auto-detected per log)")
    p.add_argument("--odom-topic", default=None, help="odometry topic of every log (default: auto-detected per log)")
    p.add_argument("--depth-topic", default=None,
                   help="depth image topic of every log (default: auto-detected per log)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--gt-topic", dest="gt_topic", default=None, metavar="TOPIC",
                   help="ground-truth pose topic in every log (default: auto-detected per log, a pose topic named "
                        "*ground_truth*; none: no ATE)")
    add_alias(g, "--gt-from-topic", "gt_topic")  # the spelling
    g.add_argument("--gt-dir", default=None, metavar="DIR",
                   help="folder of ground-truth files, DIR/<log name>.<tum|txt|csv...> (TUM / KITTI / EuRoC); a log "
                        "without one is an error row (default: none)")
    p.add_argument("--vocab", default=None, metavar="FILE",
                   help="trained vocabulary (.npz) used by every log, loaded once per worker (default: the online "
                        "vocabulary of each run)")
    p.add_argument("--no-mcap", action="store_true", help="do not write corrected.mcap (default: write it)")
    p.add_argument("--map", default=None, metavar="DIR",
                   help="also join the logs into one multi-session map: after the parallel runs (which fill the "
                        "feature cache), the logs are appended to DIR one at a time in the order of their output "
                        "names, so the map does not depend on worker timing; each append's outputs go to "
                        "OUT/map_sessions/<name>/ (default: none)")
    add_config_args(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..batch import run_batch

    cfg = config_from_args(args)
    if args.map is not None:  # the map apart from --out and the inputs, before any log runs
        _check_map(args)
    res = run_batch(args.logs, Path(args.out), cfg, workers=args.workers, ray=args.ray, force=args.force,
                    image_topic=args.image_topic, odom_topic=args.odom_topic, depth_topic=args.depth_topic,
                    gt_topic=args.gt_topic, gt_dir=args.gt_dir, vocab=args.vocab, write_mcap=not args.no_mcap,
                    progress=not args.no_progress, input_paths=config_inputs(args))
    for line in res.summary_lines():
        print(line)
    if args.map is not None and not res.interrupted:
        rc = _append_to_map(args, cfg, res)
        if rc:
            return rc
    if res.interrupted:
        return exit_status()  # 130 Ctrl-C, 143 SIGTERM, 129 SIGHUP
    return 2 if res.failed else 0


def _check_map(args) -> None:
    from ..batch.discovery import discover_logs
    from ..run.checks import check_map_paths

    inputs = {f"log {e.name}": e.path for e in discover_logs(args.logs)}
    inputs.update({"--gt-dir": args.gt_dir, "--vocab": args.vocab, **config_inputs(args)})
    check_map_paths(args.map, {"--out": args.out}, inputs, appended=True)


def _append_to_map(args, cfg, res) -> int:
    """``batch --map``: the logs that ran (ok or skipped) appended one by one, by output name."""
    from ..batch.discovery import LogEntry, ground_truth_in
    from ..features import load_extractor
    from ..map.session_map import Map, extractor_meta
    from ..map.summary import summary_lines
    from ..run.options import MapUse, Models, OutputOptions, Sources
    from ..run.runner import run_log

    rows = sorted((r for r in res.rows if r["status"] in ("ok", "skipped")), key=lambda r: r["name"])
    if not rows:
        print(f"map {args.map}: no log ran, nothing appended")
        return 0
    extractor = load_extractor(cfg.features)
    out = Path(args.out) / "map_sessions"
    with Map.open(args.map, features=extractor_meta(extractor, cfg.map.descriptor_form), conf=cfg.map, write=True,
                  create=True) as m:
        last = None
        for r in rows:
            held = m.already_holds(r["log"], args.image_topic)
            if held is not None:  # one rule for every way into a map (Map.session_of_log)
                print(held)
                continue
            gt = ground_truth_in(Path(args.gt_dir), LogEntry(Path(r["log"]), r["name"])) if args.gt_dir else None
            sources = Sources(image_topic=args.image_topic, odom_topic=args.odom_topic, gt_topic=args.gt_topic,
                              depth_topic=args.depth_topic, gt_file=gt)
            last = run_log(r["log"], out / r["name"], cfg, sources=sources, models=Models(extractor=extractor),
                           map_use=MapUse(m, session_name=r["name"]),
                           output=OutputOptions(progress=not args.no_progress, write_mcap=not args.no_mcap,
                                                input_paths=config_inputs(args)))
            print(f"appended {r['name']} to {args.map}" + (" (interrupted: not added)" if last.interrupted else ""))
            if last.interrupted:
                return exit_status()
    if last is None:
        print(f"map {args.map}: nothing appended (it holds every log already)")
    else:
        assert last.map is not None  # run_log with a map to append to fills it (an interrupted run returned above)
        for line in summary_lines(last.map):
            print(line)
    return 0
