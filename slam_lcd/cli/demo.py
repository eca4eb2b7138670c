"""`slam-lcd demo`: render the built-in demo world (cached), run the whole pipeline on it, print a summary.

Offline first run: when no SuperPoint weights can be found or downloaded
(:class:`~slam_lcd.features.weights.WeightsUnavailableError`), the demo still runs the whole
job with the ORB baseline and says so, in one line at the start and in the summary. Only the
demo does this, and only when the user did not ask for SuperPoint by name (``--features
superpoint`` or ``--set features.kind=superpoint``): ``slam-lcd run`` never changes a user's
features silently. The ORB demo meets the same bar as the SuperPoint one (ATE after <= 25% of
odometry, no false loop; docs/features.md has the figures), so the default configuration is
used with ``features.kind=orb`` and nothing else changed.
"""
from __future__ import annotations

import sys
from pathlib import Path

from ..files.atomic import check_no_clash
from ..runtime.interrupts import exit_status
from .run import add_config_args, config_from_args, config_inputs
from .util import parse_size


def register(sub) -> None:
    p = sub.add_parser("demo", help="run the whole pipeline on the built-in demo world",
                       description="Builds a demo log of a rendered world with loops, drifting odometry and ground "
                                   "truth (cached), runs slam-lcd on it with SuperPoint (ORB when no weights are "
                                   "available offline) and prints keyframes, loops and ATE before -> after.")
    p.add_argument("-o", "--out", default="slam-lcd-demo", help="output folder (default: ./slam-lcd-demo)")
    p.add_argument("--frames", type=int, default=None,
                   help="camera frames to render (default: the demo's 2 laps, about 850 frames; "
                        "470 is a little more than one lap, the least that closes loops)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the demo world (default 0)")
    p.add_argument("--size", default="640x480", type=parse_size,
                   help="image size WxH (default 640x480; 320x240 runs about 2x faster)")
    p.add_argument("--rebuild", action="store_true",
                   help="render the demo log again even if cached (default: reuse the cached log in "
                        "$SLAM_LCD_CACHE_DIR/demo or ~/.cache/slam-lcd/demo)")
    p.add_argument("--sessions", type=int, default=1, choices=[1, 2, 3],
                   help="1: one log of two laps. 2 or 3: the demo world's sessions (other starts and routes, one "
                        "under changed lighting, each odometry in its own frame) joined into one map in OUT/map, "
                        "with each session's ATE before -> after in the map frame (default 1)")
    add_config_args(p)
    p.set_defaults(func=run)


def _arrow() -> str:
    """'→' where stdout can encode it, else '->' (a cp1252 console or pipe must not crash the demo)."""
    try:
        "→".encode(sys.stdout.encoding or "ascii")
        return "→"
    except (UnicodeEncodeError, LookupError):
        return "->"


def orb_fallback_notice(target: Path) -> str:
    from ..features.weights import WEIGHTS_NAME

    return (f"SuperPoint weights not available offline {_arrow()} ORB features; put {WEIGHTS_NAME} at {target} "
            f"or pass --weights for the paper's features")


def _superpoint_named(args) -> bool:
    """Did the user ask for SuperPoint by name (then no fallback: a named choice is never changed)?"""
    if getattr(args, "features", None) == "superpoint":
        return True
    for assignment in args.overrides:
        key, _, value = assignment.partition("=")
        if key.strip() == "features.kind" and value.strip() == "superpoint":
            return True
    return False


def load_demo_extractor(args):
    """``(config, extractor, notice)``: SuperPoint when weights are there, else ORB with a notice."""
    from ..features import load_extractor
    from ..features.weights import WEIGHTS_NAME, WeightsUnavailableError, cache_dir

    cfg = config_from_args(args)
    try:
        return cfg, load_extractor(cfg.features), None
    except WeightsUnavailableError:
        if cfg.features.kind != "superpoint" or _superpoint_named(args):
            raise
        notice = orb_fallback_notice(cache_dir(cfg.features.cache_dir) / WEIGHTS_NAME)
        cfg = config_from_args(args, extra=["features.kind=orb"])
        return cfg, load_extractor(cfg.features), notice


def run(args) -> int:
    from ..run.options import Models, OutputOptions
    from ..run.runner import run_log
    from ..sim.demo_cache import demo_log_path, ensure_demo_log

    width, height = args.size
    # the demo log (written into the cache) and --out are two outputs: never one path
    check_no_clash({"the demo log": demo_log_path(args.frames, args.seed, width, height), "--out": args.out},
                   config_inputs(args), merged=[args.out])
    # resolve the weights first: the notice (or a named file's error) comes before any work
    cfg, extractor, notice = load_demo_extractor(args)
    if notice:
        print(notice, flush=True)
    if args.sessions > 1:
        return _run_sessions(args, cfg, extractor, notice)
    log_path = ensure_demo_log(frames=args.frames, seed=args.seed, rebuild=args.rebuild,
                               progress=not args.no_progress, width=width, height=height)
    print(f"demo log: {log_path}", flush=True)
    from ..sim import demo_surfaces

    res = run_log(log_path, Path(args.out), cfg, models=Models(extractor=extractor),
                  output=OutputOptions(progress=not args.no_progress, input_paths=config_inputs(args),
                                       command_line=getattr(args, "command_line", None),
                                       overrides=list(args.overrides), surfaces=demo_surfaces(args.seed)))
    print("slam-lcd demo summary")
    print(f"  features: {cfg.features.kind}" + (f" ({notice})" if notice else ""))
    for line in res.summary_lines():
        print(f"  {line}")
    print(f"outputs in {res.out_dir}/ (corrected.tum, loops.csv, report.md, trajectory.png, ...)")

    return exit_status() if res.interrupted else 0  # 130 Ctrl-C, 143 SIGTERM, 129 SIGHUP


def _run_sessions(args, cfg, extractor, notice) -> int:
    """``demo --sessions N``: the first N session logs of the demo world, appended one by one to OUT/map."""
    from ..map.session_map import Map, extractor_meta
    from ..map.summary import summary_lines
    from ..run.options import MapUse, Models, OutputOptions
    from ..run.runner import run_log
    from ..sim.demo_cache import ensure_demo_log

    width, height = args.size
    out = Path(args.out)
    logs = [ensure_demo_log(frames=args.frames, rebuild=args.rebuild, progress=not args.no_progress, width=width,
                            height=height, session=k) for k in range(1, args.sessions + 1)]
    for k, path in enumerate(logs, 1):
        print(f"demo session {k}: {path}", flush=True)
    m = Map.open(out / "map", features=extractor_meta(extractor, cfg.map.descriptor_form), conf=cfg.map, write=True,
                 create=True)
    try:
        if m.sessions:
            print(f"{out / 'map'} already holds {len(m.sessions)} sessions: the demo sessions it lacks are appended")
        res = None
        for k, path in enumerate(logs, 1):
            held = m.already_holds(path)
            if held is not None:  # one rule for every way into a map (Map.session_of_log)
                print(held)
                continue
            res = run_log(path, out / f"session{k}", cfg, models=Models(extractor=extractor),
                          map_use=MapUse(m, session_name=f"session{k}"),
                          output=OutputOptions(progress=not args.no_progress, input_paths=config_inputs(args),
                                               command_line=getattr(args, "command_line", None),
                                               overrides=list(args.overrides)))
            if res.interrupted:
                return exit_status()
    finally:
        m.close()
    print("slam-lcd demo summary (multi-session)")
    print(f"  features: {cfg.features.kind}" + (f" ({notice})" if notice else ""))
    if res is None:
        print(f"  map {out / 'map'}: nothing appended (it holds every demo session already)")
    else:
        assert res.map is not None  # run_log with a map to append to fills it (an interrupted run returned above)
        for line in summary_lines(res.map):
            print(f"  {line.strip()}")
    print(f"outputs in {out}/ (map/, session1/ ... : each run's files, map/ in each: every session in the map frame)")
    return 0
