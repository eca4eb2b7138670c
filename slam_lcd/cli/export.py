"""`slam-lcd export TRAJ --to tum|kitti|euroc|mcap|rosbag1|rosbag2 OUT`: convert a trajectory.

TRAJ is a TUM / KITTI / EuRoC file or ``LOG:TOPIC``. Text outputs keep full precision
(stamps as exact decimal seconds or integer ns); log outputs (an MCAP file, a ROS1 ``.bag``,
a rosbag2 folder, as evo's ``--save_as_bag`` / ``--save_as_bag2``) carry a PoseStamped per
stamp, ``/tf`` and a ``nav_msgs/Path`` (see :func:`slam_lcd.io.writers.write_trajectory_log`).
The output is written atomically and never onto the input.
"""
from __future__ import annotations

from ..errors import InputError
from ..io.trajectory_formats import FORMATS
from .run import add_alias
from .util import check_outputs, write_guard

LOG_TARGETS = ("mcap", "rosbag1", "rosbag2")
TARGETS = (*FORMATS, *LOG_TARGETS)
DEFAULT_TOPIC = "/slam_lcd/trajectory"


def register(sub) -> None:
    p = sub.add_parser(
        "export",
        help="convert a trajectory (file or LOG:TOPIC) to TUM / KITTI / EuRoC / MCAP / ROS1 bag / rosbag2",
        description="Convert a trajectory (TUM / KITTI / EuRoC file or LOG:TOPIC) to another format.",
    )
    p.add_argument("traj", metavar="TRAJ", help="input trajectory: file (format detected) or LOG:TOPIC")
    p.add_argument("--to", dest="to", required=True, choices=TARGETS, help="output format (required)")
    p.add_argument("out", metavar="OUT", nargs="?", default=None, help="output path (or give it with -o/--out)")
    p.add_argument("-o", "--out", dest="out_opt", default=None, metavar="OUT",
                   help="output path, as OUT (default: none; OUT or --out is required)")
    p.add_argument("--format", dest="in_format", choices=FORMATS, default=None,
                   help="input format (default: detected from the file's contents and suffix)")
    p.add_argument("--times", default=None, metavar="FILE",
                   help="KITTI times file of the input (default: none; KITTI poses get stamps 0, 1, 2 ... s)")
    p.add_argument("--times-out", default=None, metavar="FILE",
                   help="with --to kitti: also write the stamps (s) here (default: stamps are not written)")
    p.add_argument("--out-topic", dest="topic", default=DEFAULT_TOPIC,
                   help="with --to mcap, rosbag1 or rosbag2: pose topic written (default %(default)s)")
    add_alias(p, "--topic", "topic")  # old spelling of --out-topic
    p.add_argument("--frame-id", default=None,
                   help="with --to mcap, rosbag1 or rosbag2: parent frame (default: the input's, else 'map')")
    p.add_argument("--child-frame-id", default=None,
                   help="with --to mcap, rosbag1 or rosbag2: child frame (default: the input's, else 'base_link')")
    p.late_positional = "out"  # OUT may follow the options (see cli.util.one_line_errors)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..io.trajectory_files import write_trajectory
    from ..sensors.trajectories import load_trajectory_source

    if args.out and args.out_opt and args.out != args.out_opt:
        raise InputError(f"two output paths given ({args.out} and --out {args.out_opt}); give one")
    args.out = args.out or args.out_opt
    if not args.out:
        raise InputError("no output path: give OUT (or -o/--out OUT)")
    if args.times_out is not None and args.to != "kitti":
        raise InputError("--times-out only applies to --to kitti (the other formats keep their stamps)")
    # no output on or inside an input (the log of LOG:TOPIC, its rosbag2 folder), none on another
    check_outputs({"OUT": args.out, "--times-out": args.times_out}, {"TRAJ": args.traj, "--times": args.times},
                  folders=("OUT",) if args.to == "rosbag2" else ())
    for opt in ("topic", "frame_id", "child_frame_id"):
        if args.to not in LOG_TARGETS and getattr(args, opt) not in (None, DEFAULT_TOPIC):
            flag = "--out-topic" if opt == "topic" else f"--{opt.replace('_', '-')}"
            raise InputError(f"{flag} only applies to --to mcap, rosbag1 or rosbag2")
    traj = load_trajectory_source(args.traj, args.in_format, args.times)
    if args.to in LOG_TARGETS:
        from ..io.writers import write_trajectory_log

        frame = args.frame_id or (traj.frame_id if traj.frame_id != "world" else "map")
        child = args.child_frame_id or (traj.child_frame_id if traj.child_frame_id != "body" else "base_link")
        if not args.topic.startswith("/"):
            raise InputError(f"--out-topic must start with '/', got {args.topic!r}")
        with write_guard(args.out):
            counts = write_trajectory_log(args.out, traj, args.to, topic=args.topic, frame_id=frame,
                                          child_frame_id=child)
        print(f"wrote {args.out} ({len(traj)} poses; " + ", ".join(f"{k}: {v}" for k, v in counts.items()) + ")")
        return 0
    with write_guard(args.out):
        write_trajectory(args.out, traj, args.to, times_path=args.times_out)
    print(f"wrote {args.out} ({args.to}, {len(traj)} poses)")
    if args.to == "kitti" and args.times_out is None:
        print("note: KITTI files carry no stamps; pass --times-out FILE to keep them")
    elif args.to == "kitti":
        print(f"wrote {args.times_out} (stamps in seconds)")
    return 0
