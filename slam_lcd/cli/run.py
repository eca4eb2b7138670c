"""`slam-lcd run LOG --out DIR`: loop-correct the trajectory of a recorded log."""
from __future__ import annotations

from pathlib import Path

from ..config import load_config


def add_config_args(p) -> None:
    p.add_argument("--config", default=None, help="preset name (data/configs) or YAML file (default: 'default')")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one configuration key (repeatable), e.g. --set backend.loop_kernel=huber")
    p.add_argument("--weights", default=None, help="SuperPoint weights file (superpoint_v1.pth layout)")
    p.add_argument("--device", default=None, choices=["auto", "cpu", "cuda"], help="torch device for SuperPoint")


def config_inputs(args) -> dict:
    """Input files named by the config flags (outputs must never land on them)."""
    from pathlib import Path as _P

    inputs = {}
    if getattr(args, "config", None) and _P(args.config).exists():
        inputs["--config"] = args.config
    return inputs


def config_from_args(args):
    overrides = list(args.overrides)
    if getattr(args, "weights", None):
        overrides.append(f"features.weights={args.weights}")
    if getattr(args, "device", None):
        overrides.append(f"features.device={args.device}")
    return load_config(args.config or "default", overrides)


def register(sub) -> None:
    p = sub.add_parser("run", help="correct a recorded log's trajectory with loop closures",
                       description="Stream a ROS1 bag, rosbag2 folder or MCAP file through keyframe selection, "
                                   "SuperPoint, Bag of SuperPoints, graph verification and GTSAM iSAM2; write the "
                                   "corrected trajectory, loops, reports and plots into --out.")
    p.add_argument("log", help="ROS1 .bag, rosbag2 folder or .mcap file")
    p.add_argument("--out", "-o", required=True, help="output folder (created; files inside are replaced)")
    p.add_argument("--image-topic", default=None)
    p.add_argument("--odom-topic", default=None)
    p.add_argument("--depth-topic", default=None)
    g = p.add_mutually_exclusive_group()
    g.add_argument("--gt-topic", default=None, help="ground-truth pose topic in the log")
    g.add_argument("--gt", default=None, help="ground-truth trajectory file (TUM / KITTI / EuRoC)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-mcap", action="store_true", help="do not write corrected.mcap")
    add_config_args(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..runner import run_log

    cfg = config_from_args(args)
    res = run_log(args.log, Path(args.out), cfg, image_topic=args.image_topic, odom_topic=args.odom_topic,
                  depth_topic=args.depth_topic, gt_topic=args.gt_topic, gt_file=args.gt,
                  progress=not args.no_progress, write_mcap=not args.no_mcap, input_paths=config_inputs(args))
    for line in res.summary_lines():
        print(line)
    print(f"outputs in {res.out_dir}/ ({', '.join(res.outputs)})"
          + (" -- a partial set, see PARTIAL.txt" if res.interrupted else ""))
    return 130 if res.interrupted else 0
