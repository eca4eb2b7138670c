"""`slam-lcd view RUN_DIR | MAP_DIR [--save OUT.rrd] [--web] [--port N]`: a Rerun recording of what a folder holds.

Nothing is run again: the recording is made from the folder's files (slam_lcd.viewer). Without
``--save`` or ``--web`` the native viewer opens (it needs a display). Needs the ``viewer`` extra
(``pip install 'slam-lcd[viewer]'``); without it, one line saying so and exit status 2, after the
folder and the flags are checked (a wrong folder is named as such first).
"""
from __future__ import annotations

import logging

from ..errors import InputError

log = logging.getLogger(__name__)


def register(sub) -> None:
    p = sub.add_parser("view", help="show a run or map folder in the Rerun viewer (or save a .rrd recording)",
                       description="Make a Rerun recording from a run output folder (trajectories, keyframe "
                                   "frusta, loops by verdict, map cloud, ATE over time) or a map folder (every "
                                   "session in the map frame, loops between sessions), then open the native viewer, "
                                   "serve the web viewer (--web) or only write the file (--save). Needs "
                                   "`pip install 'slam-lcd[viewer]'`.")
    p.add_argument("folder", metavar="RUN_DIR|MAP_DIR", help="output folder of `slam-lcd run`, or a map folder")
    p.add_argument("--save", default=None, metavar="OUT.rrd",
                   help="write the recording to this .rrd file (default: none; alone, no viewer is opened)")
    p.add_argument("--web", action="store_true",
                   help="serve the bundled web viewer on localhost until Ctrl-C, for a remote or headless machine "
                        "(default: the native viewer, which needs a display)")
    p.add_argument("--port", type=int, default=None, metavar="N",
                   help="port of the web viewer with --web (default: 9090)")
    p.add_argument("--log", default=None, metavar="PATH",
                   help="with a run folder: the log the run read, where it is now, for the keyframe images (and a "
                        "ground truth read from the log) (default: the path report.json names)")
    p.add_argument("--localization", default=None, metavar="DIR",
                   help="with a map folder: also show this `slam-lcd localize` output folder in the map frame "
                        "(default: none)")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..viewer import require_rerun, targets
    from ..viewer.view import plan

    if args.port is not None and not args.web:
        raise InputError("--port is the web viewer's: give it with --web")
    if args.port is not None and not 0 < args.port < 65536:
        raise InputError(f"--port {args.port} is not a port number (1-65535)")
    p = plan(args.folder, args.localization, args.log)
    if args.save is not None:
        targets.check_rrd_target(args.save, p.inputs)
    elif not args.web:
        targets.check_display()  # refused with one line, before anything is logged
    require_rerun()  # the input is good: only now is the missing extra the thing to report
    layout = p.layout()
    for line in p.warnings:
        log.warning("%s", line)
    print(p.summary)
    if args.save is not None:
        out = targets.save(args.save, p.build, layout, p.name)
        print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB)")
    if args.web:
        rec, url = targets.serve_web(p.build, layout, p.name, args.port)
        print(f"web viewer: {url}  (Ctrl-C stops it)", flush=True)
        targets.wait_for_interrupt()
        targets.close(rec)
    elif args.save is None:
        targets.spawn(p.build, layout, p.name)
    return 0
