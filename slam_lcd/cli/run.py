"""`slam-lcd run LOG --out DIR`: loop-correct the trajectory of a recorded log."""
from __future__ import annotations

import argparse
from pathlib import Path

from ..config import load_config, preset_names
from ..errors import InputError
from ..files.atomic import check_no_clash
from ..runtime.interrupts import exit_status


def add_config_args(p, *, device: bool = True) -> None:
    """The configuration flags every command that builds a pipeline stage shares (one name per concept)."""
    p.add_argument("--config", default=None, metavar="NAME|FILE",
                   help=f"preset name ({', '.join(preset_names())}) or YAML file (default: default)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one configuration key (repeatable), e.g. --set backend.loop_kernel=huber "
                        "(default: none)")
    p.add_argument("--features", choices=["superpoint", "orb"], default=None,
                   help="feature extractor (default: the config's features.kind, superpoint)")
    p.add_argument("--weights", default=None, metavar="PATH",
                   help="SuperPoint weights file, superpoint_v1.pth layout (default: $SLAM_LCD_SUPERPOINT_WEIGHTS, "
                        "then superpoint_v1.pth in the cache, then a download; see `slam-lcd weights`)")
    if device:
        p.add_argument("--device", default=None, choices=["auto", "cpu", "cuda"],
                       help="torch device for SuperPoint (default: the config's features.device, auto = CUDA "
                            "when available, else CPU)")
    p.add_argument("--no-feature-cache", action="store_true",
                   help="do not read or write the on-disk feature cache (default: features are cached in "
                        "$SLAM_LCD_CACHE_DIR or ~/.cache/slam-lcd)")


def config_inputs(args) -> dict:
    """Input files named by the config flags (outputs must never land on them)."""
    from pathlib import Path as _P

    inputs = {}
    if getattr(args, "config", None) and _P(args.config).exists():
        inputs["--config"] = args.config
    return inputs


def config_from_args(args, extra: list[str] | tuple[str, ...] = ()):
    """The run configuration: preset/file, then ``--set``, then the shortcut flags (they win)."""
    overrides = list(getattr(args, "overrides", []) or [])
    if getattr(args, "features", None):
        overrides.append(f"features.kind={args.features}")
    if getattr(args, "weights", None):
        overrides.append(f"features.weights={args.weights}")
    if getattr(args, "device", None):
        overrides.append(f"features.device={args.device}")
    if getattr(args, "no_feature_cache", False):
        overrides.append("features.feature_cache=false")
    return load_config(args.config or "default", [*overrides, *extra])


def add_alias(p, alias: str, dest: str, **kwargs) -> None:
    """An old spelling kept working but not shown in --help."""
    p.add_argument(alias, dest=dest, default=argparse.SUPPRESS, help=argparse.SUPPRESS, **kwargs)


def add_source_args(p) -> None:
    """The flags that choose a log's topics, ground truth and calibration (`run`, `localize`)."""
    p.add_argument("--image-topic", default=None,
                   help="camera image topic (default: auto-detected, the only sensor_msgs/Image or CompressedImage "
                        "topic without 'depth' or 'right' in its name)")
    p.add_argument("--odom-topic", default=None,
                   help="odometry topic (default: auto-detected, the only nav_msgs/Odometry topic; with none, the "
                        "built-in visual odometry runs: RGB-D on the depth topic, else stereo on --right-topic)")
    p.add_argument("--depth-topic", default=None,
                   help="depth image topic (default: auto-detected, an image topic with 'depth' in its name in "
                        "the camera's namespace; none: loops are scaled by triangulation)")
    p.add_argument("--right-topic", default=None,
                   help="rectified right camera image topic, for the built-in stereo visual odometry of a log "
                        "without odometry or depth (default: auto-detected, the calibration's second camera, the "
                        "image topic with 'left' spelled 'right', or the only image topic named *right*)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--gt-topic", default=None,
                   help="ground truth in the log: a PoseStamped, PoseWithCovarianceStamped, Odometry, "
                        "TransformStamped or PointStamped (position only: ATE on translation) topic, or a TF chain "
                        "TOPIC:PARENT:CHILD such as /tf:world:kinect (default: auto-detected, the only pose topic "
                        "named *ground_truth* or *groundtruth*; none: no ATE)")
    g.add_argument("--gt", default=None, metavar="FILE",
                   help="ground-truth trajectory file, TUM / KITTI / EuRoC (default: none; the log's "
                        "ground-truth topic if any)")
    p.add_argument("--calib", action="append", default=None, metavar="FILE",
                   help="camera calibration: a Kalibr camchain.yaml, or EuRoC camN/sensor.yaml files (repeat: cam0 "
                        "first); wins over the log's CameraInfo and /tf_static mounting (default: none, the log's "
                        "CameraInfo)")


def register(sub) -> None:
    p = sub.add_parser("run", help="correct a recorded log's trajectory with loop closures",
                       description="Stream a ROS1 bag, rosbag2 folder or MCAP file through keyframe selection, "
                                   "SuperPoint, Bag of SuperPoints, graph verification and GTSAM iSAM2; write the "
                                   "corrected trajectory, loops, reports and plots into --out.")
    p.add_argument("log", nargs="+", help="ROS1 .bag, rosbag2 folder or .mcap file (several with --map: appended "
                                          "in the order given)")
    p.add_argument("-o", "--out", required=True,
                   help="output folder (required; created if missing; the files slam-lcd writes are replaced; with "
                        "several logs, one subfolder per log named after it)")
    p.add_argument("--map", default=None, metavar="DIR",
                   help="multi-session map folder: the log's loops are also searched in every session the map "
                        "holds, and the log is appended to it as a new session (created if missing; default: none, "
                        "a single-log run)")
    p.add_argument("--session-name", default=None, metavar="NAME",
                   help="name of the new session in the map (default: the log's file name without suffix)")
    add_source_args(p)
    p.add_argument("--no-mcap", action="store_true",
                   help="do not write corrected.mcap (default: write it, run.write_mcap)")
    p.add_argument("--plot_mode", "--plot-mode", dest="plot_mode", default=None,
                   choices=["auto", "xy", "xz", "yz", "xyz"],
                   help="plane (or xyz: 3-D) of trajectory.png (default: the config's run.plot_mode, auto = the "
                        "plane the motion spans)")
    p.add_argument("--copy-images", action="store_true",
                   help="copy the log's image topics into corrected.mcap too (large; default: every topic but "
                        "images, run.copy_images)")
    p.add_argument("--truth-world", type=int, default=None, metavar="SEED",
                   help="the log was rendered from the demo world of this seed (make-demo-log --seed / --world-seed):"
                        " map.ply's points are measured against its true surfaces too (default: none)")
    p.add_argument("--rerun", nargs="?", const="spawn", default=None, metavar="spawn|FILE.rrd",
                   help="log keyframes (image, keypoints, pose) and loops to Rerun while the run goes, then the run "
                        "folder's contents: 'spawn' (the default when no value is given) opens the native viewer, "
                        "FILE.rrd writes a recording (default: none; needs `pip install 'slam-lcd[viewer]'`)")
    add_config_args(p)
    p.set_defaults(func=run)


def run(args) -> int:
    extra = ["run.copy_images=true"] if args.copy_images else []
    if args.plot_mode:
        extra.append(f"run.plot_mode={args.plot_mode}")
    cfg = config_from_args(args, extra=extra)
    logs = [Path(x) for x in args.log]
    if len(logs) > 1 and args.map is None:
        raise InputError(f"{len(logs)} logs given: several logs go into one map (--map DIR); "
                         "to run them separately use `slam-lcd batch`")
    if len(logs) > 1 and args.rerun is not None:
        raise InputError(f"--rerun records one run: give one log ({len(logs)} given)")
    if len(logs) > 1 and args.session_name:
        raise InputError("--session-name names one session: give it with one log")
    if args.map is None:
        return _print_result(_run_one(args, cfg, logs[0], Path(args.out), None))
    from ..features import load_extractor
    from ..map.session_map import Map, extractor_meta
    from ..run.checks import check_run_paths

    names = [x.stem for x in logs]
    if len(set(names)) != len(names):
        raise InputError(f"two logs share a name ({', '.join(names)}): their output folders would clash")
    outs = [Path(args.out)] if len(logs) == 1 else [Path(args.out) / n for n in names]
    for log_path, out in zip(logs, outs, strict=True):  # every path refused before a model loads or a lock waits
        check_run_paths(log_path, out, cfg, args.gt, run_input_paths(args), map_dir=args.map, appended=True)
    extractor = load_extractor(cfg.features)
    m = Map.open(args.map, features=extractor_meta(extractor, cfg.map.descriptor_form), conf=cfg.map, write=True,
                 create=True)
    rc = 0
    try:
        for log_path, out in zip(logs, outs, strict=True):
            held = m.already_holds(log_path, args.image_topic)
            if held is not None:  # one rule for every way into a map (Map.session_of_log)
                print(held)
                continue
            res = _run_one(args, cfg, log_path, out, m, extractor=extractor)
            rc = _print_result(res)
            if res.interrupted:
                break
    finally:
        m.close()
    return rc


def run_input_paths(args) -> dict:
    """The run's inputs named by flags besides the log and --gt (--config, --calib)."""
    inputs = config_inputs(args)
    for i, p in enumerate(getattr(args, "calib", None) or []):
        inputs[f"--calib {i}"] = p
    return inputs


def _run_one(args, cfg, log_path: Path, out: Path, m, extractor=None):
    from ..run.runner import run_log

    inputs = config_inputs(args)
    live = _live(args, log_path, out)
    try:
        res = _run_log(run_log, args, cfg, log_path, out, m, extractor, inputs, live)
    except BaseException:
        if live is not None:
            live.discard()
        raise
    if live is not None:
        saved = live.finish(out, res.ground_truth)
        if saved is not None:
            res.outputs.append(f"{saved} (Rerun recording)")
    return res


def _live(args, log_path: Path, out: Path):
    """The live Rerun recorder of ``--rerun`` (its file checked against every input first), or None."""
    if args.rerun is None:
        return None
    from ..viewer.live import SPAWN, LiveRecorder

    if args.rerun != SPAWN:
        from ..viewer.targets import check_rrd_target

        inputs = {"the log": log_path, "--gt": args.gt, "--map": args.map, **run_input_paths(args)}
        check_rrd_target(args.rerun, inputs)
        check_no_clash({"--rerun": args.rerun, "--out": out}, {}, merged=[out])
    return LiveRecorder(args.rerun, log_path.stem)


def _run_log(run_log, args, cfg, log_path, out, m, extractor, inputs, live):
    from ..run.options import MapUse, Models, OutputOptions

    return run_log(log_path, out, cfg, sources=sources_of(args), models=Models(extractor=extractor),
                   map_use=MapUse(m, session_name=args.session_name) if m is not None else None,
                   output=OutputOptions(progress=not args.no_progress, write_mcap=not args.no_mcap,
                                        input_paths=inputs, command_line=getattr(args, "command_line", None),
                                        overrides=list(args.overrides), surfaces=_truth(args), live=live))


def sources_of(args):
    """The :class:`~slam_lcd.run.options.Sources` of the source flags (``run`` and ``localize`` share them)."""
    from ..run.options import Sources

    return Sources(image_topic=args.image_topic, odom_topic=args.odom_topic, gt_topic=args.gt_topic,
                   depth_topic=args.depth_topic, right_topic=args.right_topic, gt_file=args.gt, calib=args.calib)


def _truth(args):
    """The true surfaces of ``--truth-world`` (the demo world of that seed), or None."""
    if args.truth_world is None:
        return None
    from ..sim import demo_surfaces  # lazy: the demo world (OpenCV, the renderer) only with --truth-world

    return demo_surfaces(args.truth_world)


def _print_result(res) -> int:
    for line in res.summary_lines():
        print(line)
    if res.map is not None:
        from ..map.summary import summary_lines

        for line in summary_lines(res.map):
            print(line)
    print(f"outputs in {res.out_dir}/ ({', '.join(res.outputs)})"
          + (" -- a partial set, see PARTIAL.txt" if res.interrupted else ""))

    return exit_status() if res.interrupted else 0  # 130 Ctrl-C, 143 SIGTERM, 129 SIGHUP
