"""`slam-lcd demo`: render the built-in demo world (cached), run the whole pipeline on it, print a summary."""
from __future__ import annotations

from pathlib import Path

from .run import add_config_args, config_from_args, config_inputs


def register(sub) -> None:
    p = sub.add_parser("demo", help="run the whole pipeline on the built-in demo world",
                       description="Builds a demo log of a rendered world with loops, drifting odometry and ground "
                                   "truth (cached), runs slam-lcd on it with SuperPoint and prints keyframes, loops "
                                   "and ATE before -> after.")
    p.add_argument("--out", "-o", default="slam-lcd-demo", help="output folder (default: ./slam-lcd-demo)")
    p.add_argument("--frames", type=int, default=None, help="frames to render (default: the demo's ~2 laps)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--rebuild", action="store_true", help="render the demo log again even if cached")
    p.add_argument("--no-progress", action="store_true")
    add_config_args(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..demo import ensure_demo_log
    from ..features import load_extractor
    from ..runner import run_log

    cfg = config_from_args(args)
    # resolve the weights first: offline without them this stops here with the resolver's message
    extractor = load_extractor(cfg.features)
    log_path = ensure_demo_log(frames=args.frames, seed=args.seed, rebuild=args.rebuild,
                               progress=not args.no_progress)
    print(f"demo log: {log_path}")
    res = run_log(log_path, Path(args.out), cfg, extractor=extractor, progress=not args.no_progress,
                  input_paths=config_inputs(args))
    print("slam-lcd demo summary")
    for line in res.summary_lines():
        print(f"  {line}")
    print(f"outputs in {res.out_dir}/ (corrected.tum, loops.csv, report.md, trajectory.png, ...)")
    return 130 if res.interrupted else 0
