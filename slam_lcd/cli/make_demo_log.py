"""`slam-lcd make-demo-log`: render the built-in demo world into a log file."""
from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from ..sim.sessions import SESSIONS
from ..sim.stretch_spec import BLUR_PX, Stretches, stretch_arg
from .util import check_outputs, parse_size, write_guard


def _preset_text(p) -> str:
    return (f"--trajectory {p.kind} --laps {p.laps:g} --start-at {p.start_at:g} --seed {p.seed} --world-seed "
            f"{p.world_seed} --lighting {p.lighting:g} --exposure {p.exposure:g} ({p.role})")


def register(sub) -> None:
    p = sub.add_parser(
        "make-demo-log",
        help="render the built-in demo world (loops, drifting odometry, ground truth) into a log",
        description="Render the demo world along a looping trajectory and write camera images, depth, "
        "odometry (50 Hz) and ground truth as an MCAP file, rosbag2 folder, ROS1 bag or a plain folder. "
        "Ground-truth loop pairs are written beside the log as <name>_loops.csv.",
    )
    p.add_argument("out", nargs="?", default=None, metavar="OUT",
                   help="output path (.mcap file, rosbag2 folder, .bag file, or folder); or give it with -o/--out")
    p.add_argument("-o", "--out", dest="out_opt", default=None, metavar="OUT",
                   help="output path, as OUT (default: none; OUT or --out is required)")
    p.add_argument("--format", dest="fmt", choices=["mcap", "rosbag2", "rosbag1", "folder"], default=None,
                   help="output format (default: auto-detected from OUT's suffix: .mcap, .bag, otherwise rosbag2)")
    p.add_argument("--frames", type=int, default=None,
                   help="number of camera frames (default: --laps laps, 2 laps = about 850 frames)")
    p.add_argument("--seed", type=int, default=None,
                   help="random seed of path weave, odometry and image noise, and of the world unless --world-seed "
                        "(default 0; with --session the preset's)")
    p.add_argument("--session", type=int, choices=sorted(SESSIONS), default=None, metavar="K",
                   help="one recording of a multi-session set (presets below; explicit flags override them): its "
                        "odometry starts at the identity (its own frame, no world -> odom on /tf_static), its stamps "
                        "start K days later, ground truth is in its world's frame (world, or world_<seed>). "
                        + "; ".join(f"{k}: {_preset_text(v)}" for k, v in SESSIONS.items())
                        + " (default: none, a plain demo log)")
    p.add_argument("--world-seed", type=int, default=None,
                   help="seed of the world's textures and lighting (default: --seed; with --session the preset's); "
                        "1000-1999: another building on the same corridors, 2000 and above: the demo building with "
                        "a look-alike corridor (docs/sim_sessions.md)")
    p.add_argument("--start-at", type=float, default=None, metavar="METRES",
                   help="arc length of the start point along the route's centre line (default: the route's usual "
                        "start, 3 m for laps, 2 m for figure8; with --session the preset's)")
    p.add_argument("--lighting", type=float, default=None, metavar="EPOCH",
                   help="offset added to the lighting epoch of every frame: another lamp / exposure state "
                        "(default 0; with --session the preset's)")
    p.add_argument("--exposure", type=float, default=None, metavar="FACTOR",
                   help="global exposure factor of the renderer (default 1; with --session the preset's)")
    p.add_argument("--appearance", choices=["day", "night", "moved", "renovated"], default=None,
                   help="the world's appearance state: day (as the seed paints it), night (most ambient light gone, "
                        "60 %% of the lamps on as spotlights), moved (posters and boards replaced or moved on about "
                        "60 %% of the walls), renovated (new walls and a wooden floor east of x = 12.5 m); "
                        "geometry and ground truth are the same (default: day; docs/sim_sessions.md)")
    p.add_argument("--stereo", action="store_true", help="also write the rectified right camera (default: off)")
    p.add_argument("--depth", dest="depth", action="store_true", default=True, help="write /camera/depth (default: on)")
    p.add_argument("--no-depth", dest="depth", action="store_false",
                   help="do not write depth images (default: write them)")
    p.add_argument("--compressed", action="store_true",
                   help="write JPEG sensor_msgs/CompressedImage instead of raw images (default: raw)")
    p.add_argument("--color", action="store_true", help="RGB images (rgb8) instead of mono8 (default: mono8)")
    p.add_argument("--trajectory", choices=["laps", "figure8", "laps-wide", "laps-b"], default=None,
                   help="laps of block A, a figure eight, laps-wide: laps of block A with every second lap "
                        "0.45 m to the side and the camera turned 30 deg (wide-baseline revisits), or laps-b: "
                        "clockwise laps of block B "
                        "(default: laps; with --session the preset's)")
    p.add_argument("--laps", type=float, default=None,
                   help="laps to drive when --frames is not given (default 2; with --session the preset's)")
    p.add_argument("--size", default="640x480", type=parse_size, help="image size WxH (default 640x480)")
    p.add_argument("--hfov", type=float, default=70.0,
                   help="horizontal field of view in degrees (default 70: fx = 457 at 640 px)")
    p.add_argument("--rate", type=float, default=None,
                   help="camera rate in Hz (default 10, odometry 50 Hz; "
                        "with --layout the dataset's: EuRoC 20, TUM 30, KITTI 10)")
    p.add_argument("--layout", choices=["demo", "euroc", "tum", "kitti"], default="demo",
                   help="topics, encodings, rates, ground truth and calibration as that dataset's bags: euroc = raw "
                        "distorted /cam0 /cam1 mono8 20 Hz, /leica/position, camchain-<name>.yaml beside the log; "
                        "tum = /camera/rgb/image_color rgb8 + /camera/depth_registered/image_raw 16UC1 mm 30 Hz, "
                        "/tf /world -> /kinect; kitti = /kitti/camera_gray_left|right/image_raw + camera_info 10 Hz, "
                        "/tf world -> base_link; none has odometry (default: demo, the topics of --help's description)")
    p.add_argument("--exact-depth", action="store_true",
                   help="with --layout tum: write the exact rendered depth (millimetre steps only) instead of the "
                        "Kinect v1 depth errors (axial noise 0.0012 + 0.0019 (z - 0.4)^2 m, 1/8-pixel disparity "
                        "steps, 0 outside 0.5-4.5 m) (default: the Kinect errors)")
    p.add_argument("--loops-csv", default=None,
                   help="where to write the ground-truth loop pairs (default: <name>_loops.csv beside OUT; "
                        "loop_pairs.csv inside OUT with --format folder)")
    g = p.add_argument_group(
        "bad stretches", "stretches of the failures real logs have, for testing the pipeline's robustness "
        "(docs/sim_stretches.md). Times are seconds from the log's first camera frame (the clock before any "
        "--stamp-jump); a stretch holds START <= t < START + SECONDS; each option may be repeated")
    g.add_argument("--blur", action="append", type=stretch_arg("--blur"), default=None, metavar="START:SECONDS[:PX]",
                   help="motion blur of the camera images (left and right): a line PX pixels long at 640 px image "
                        "width (scaled with --size) along the image motion, horizontal when the view hardly moves "
                        f"(PX default {BLUR_PX:g}); depth unchanged (default: none)")
    g.add_argument("--dark", action="append", type=stretch_arg("--dark"), default=None, metavar="START:SECONDS",
                   help="lights off: the camera images (left and right) near black, with the sensor noise; depth "
                        "(an active sensor) unchanged (default: none)")
    g.add_argument("--drop-frames", action="append", type=stretch_arg("--drop-frames"), default=None,
                   metavar="START:SECONDS",
                   help="no image, depth, right image or camera_info messages; odometry, TF and ground truth go on "
                        "(default: none)")
    g.add_argument("--freeze", action="append", type=stretch_arg("--freeze"), default=None, metavar="START:SECONDS",
                   help="frozen camera: every frame repeats the image, depth and right image of the stretch's first "
                        "frame, with its own new stamp (default: none)")
    g.add_argument("--stamp-jump", action="append", type=stretch_arg("--stamp-jump"), default=None,
                   metavar="AT:SECONDS",
                   help="the recording's clock jumps forward: every message stamped at or after AT (all topics, "
                        "header stamps and log times, ground truth included) is stamped SECONDS later; the motion "
                        "is continuous (default: none)")
    g.add_argument("--odom-dropout", action="append", type=stretch_arg("--odom-dropout"), default=None,
                   metavar="START:SECONDS",
                   help="no odometry messages; after the gap the odometry goes on from where the drifting odometry "
                        "is (no reset); --layout demo only (default: none)")
    g.add_argument("--odom-zero-covariance", action="store_true",
                   help="odometry messages with all-zero pose and twist covariances, as many ROS drivers publish; "
                        "--layout demo, not --format folder (default: the propagated covariances)")
    p.late_positional = "out"  # OUT may follow the options (see cli.util.one_line_errors)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..io.writers import format_for_path
    from ..sim.demo_log import loops_path_for, make_demo_log
    from ..sim.layouts import camchain_path_for

    w, h = args.size
    if args.out and args.out_opt and args.out != args.out_opt:
        raise InputError(f"two output paths given ({args.out} and --out {args.out_opt}); give one")
    args.out = args.out or args.out_opt
    if not args.out:
        raise InputError("no output path: give OUT (or -o/--out OUT)")
    fmt = args.fmt or format_for_path(Path(args.out))
    # before rendering: two outputs on one path, or an unwritable target (read-only, /proc, a file in
    # the way) fail now. The folder format's own loop_pairs.csv is part of the folder, not a second output.
    outputs = {"OUT": args.out}
    if args.loops_csv is not None or fmt != "folder":
        outputs["--loops-csv"] = args.loops_csv if args.loops_csv is not None else loops_path_for(Path(args.out))
    if args.layout == "euroc":
        outputs["the Kalibr camchain beside OUT"] = camchain_path_for(Path(args.out))
    check_outputs(outputs, {}, folders=("OUT",) if fmt in ("rosbag2", "folder") else ())
    with write_guard(args.out):
        info = make_demo_log(args.out, fmt=fmt, frames=args.frames, seed=args.seed, stereo=args.stereo,
                             depth=args.depth, compressed=args.compressed, color=args.color, kind=args.trajectory,
                             laps=args.laps, width=w, height=h, hfov_deg=args.hfov, camera_rate=args.rate,
                             loops_csv=args.loops_csv, progress=not args.no_progress, layout=args.layout,
                             depth_noise=not args.exact_depth, session=args.session, world_seed=args.world_seed,
                             start_at=args.start_at, lighting=args.lighting, exposure=args.exposure,
                             appearance=args.appearance, stretches=_stretches(args))
    print(info.summary())
    return 0


def _stretches(args) -> Stretches:
    return Stretches(blur=tuple(args.blur or ()), dark=tuple(args.dark or ()),
                     drop_frames=tuple(args.drop_frames or ()), freeze=tuple(args.freeze or ()),
                     stamp_jump=tuple(args.stamp_jump or ()), odom_dropout=tuple(args.odom_dropout or ()),
                     odom_zero_covariance=bool(args.odom_zero_covariance))
