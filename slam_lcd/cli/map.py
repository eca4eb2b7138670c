"""`slam-lcd map info DIR`, `map export DIR --to FMT OUT`, `map compact DIR`: look into, export and reduce a map."""
from __future__ import annotations

import json
from pathlib import Path

from ..errors import InputError
from ..files.atomic import atomic_path, atomic_write, check_apart, check_writable_target
from .run import config_from_args
from .util import write_guard

FORMATS = ("tum", "kitti", "euroc", "mcap")


def register(sub) -> None:
    p = sub.add_parser("map", help="inspect, export or compact a multi-session map (info, export, compact)",
                       description="Inspect a map folder written by `slam-lcd run --map`, or export every "
                                   "session's trajectory in the map frame.")
    msub = p.add_subparsers(dest="map_command", metavar="SUBCOMMAND")
    msub.required = True
    i = msub.add_parser("info", help="sessions, keyframes, loops within and between sessions, components, size")
    i.add_argument("map_dir", metavar="DIR", help="map folder")
    i.add_argument("--json", action="store_true", help="print the summary as JSON (default: text)")
    i.add_argument("--plot", default=None, metavar="PNG",
                   help="also draw the map's growth over its sessions (keyframes, kept keyframes, MB) into PNG "
                        "(default: none)")
    i.set_defaults(func=info)
    c = msub.add_parser("compact", help="keep places and appearance variants, not every keyframe (map.lifelong)",
                        description="Reduce a map built without map.lifelong as if each session had been appended "
                                    "with it: keyframes that a kept keyframe of their place matches well keep only "
                                    "their pose. A map that keeps places already keeps its places, appearances "
                                    "and last uses, and loses only what the rules drop now (e.g. a smaller "
                                    "map.max_variants). One atomic commit, like an append.")
    c.add_argument("map_dir", metavar="DIR", help="map folder (changed in place, atomically)")
    c.add_argument("--config", default=None, metavar="NAME|FILE", help="preset or YAML file for the map section "
                                                                         "(default: default)")
    c.add_argument("--set", dest="overrides", action="append", default=[], metavar="map.KEY=VALUE",
                   help="override a map key, e.g. --set map.max_variants=2 (default: none)")
    c.set_defaults(func=compact)
    e = msub.add_parser("export", help="every session's keyframe trajectory in the map frame")
    e.add_argument("map_dir", metavar="DIR", help="map folder")
    e.add_argument("--to", choices=FORMATS, default="tum",
                   help="tum / kitti / euroc: one file per session in the folder OUT; mcap: one MCAP file OUT with a "
                        "PoseStamped topic per session in the map frame (default: tum)")
    e.add_argument("out", metavar="OUT", help="output folder (tum, kitti, euroc) or .mcap file")
    e.set_defaults(func=export)


def _open(path):
    from ..map.session_map import Map

    return Map.open(path)


def _size(root: Path) -> int:
    return sum(p.stat().st_size for p in root.rglob("*") if p.is_file())


def info(args) -> int:
    from ..map.summary import map_summary, summary_lines

    m = _open(args.map_dir)
    s = map_summary(m)
    s["bytes"] = _size(Path(args.map_dir))
    s["bytes_per_keyframe"] = s["bytes"] / max(1, s["n_keyframes"])
    s["schema"], s["features"] = 1, m.manifest.features.get("kind")
    if args.plot:
        _write_plot(Path(args.plot), s, Path(args.map_dir))
    if args.json:
        print(json.dumps(s, indent=2))
        return 0
    for line in summary_lines(s):
        print(line)
    print(f"loops within sessions: {s['loops_within_sessions']}; between sessions by pair: "
          + (", ".join(f"{k}: {v}" for k, v in s["inter_session_accepted_by_pair"].items()) or "none"))
    print("components: " + "; ".join("[" + ", ".join(c) + "]" for c in s["components"]))
    print(f"features: {s['features']}; size on disk: {s['bytes'] / 1e6:.1f} MB "
          f"({s['bytes_per_keyframe'] / 1e3:.0f} kB per keyframe)")
    for r in s["sessions"]:
        print(f"  {r['name']}: {r['kept_keyframes']} of {r['keyframes']} keyframes kept, {r['bytes'] / 1e6:.2f} MB")
    return 0


def _write_plot(out: Path, summary: dict, map_dir: Path) -> None:
    from ..outputs.map_outputs import growth_png

    check_apart("DIR", map_dir, {"--plot": out})
    check_writable_target(out)
    png = growth_png(summary)
    if png is None:
        raise InputError("the map does not record its growth (made by an older slam-lcd): no plot", map_dir)
    with atomic_write(out, "wb") as fh:
        fh.write(png)


def compact(args) -> int:
    """``map compact DIR``: the map reduced in memory, then one commit (the writer lock held throughout)."""
    from ..map.session_map import Map

    cfg = config_from_args(args)
    with Map.open(args.map_dir, conf=cfg.map, write=True) as m:
        figures = m.compact(cfg.lcd)
        m.save()
    b, a = figures["before"], figures["after"]
    print(f"map {args.map_dir}: {a['keyframes']} keyframes, kept {b['kept_keyframes']} -> {a['kept_keyframes']} "
          f"({a['places']} places, {a['variants']} more variants)")
    return 0


def export(args) -> int:
    out = Path(args.out)
    check_apart("DIR", args.map_dir, {"OUT": out})  # before the map is read: nothing of it is written
    m = _open(args.map_dir)
    check_writable_target(out, folder=args.to != "mcap")
    names = m.session_names
    with write_guard(out):  # an OS error while writing names OUT, never a temporary name
        return _export(args, m, out, names)


def _export(args, m, out: Path, names: list[str]) -> int:
    from ..io.trajectory_files import write_trajectory
    from ..map.store import MANIFEST
    from ..outputs.map_outputs import session_file_stem

    if args.to == "mcap":
        from ..io.message_builders import pose_stamped_msg
        from ..io.writers import open_writer

        with open_writer(out, "mcap") as w:
            for i, name in enumerate(names):
                traj = m.session_trajectory(i)
                comp = m.manifest.sessions[i]["component"]
                frame = "map" if comp == m.manifest.sessions[0]["component"] else f"map_{comp}"
                for st, T in zip(traj.stamps, traj.poses, strict=True):
                    w.write(f"/map/{_topic(name)}/pose", pose_stamped_msg(T, int(st), frame), int(st))
        print(f"{out}: {len(names)} sessions as /map/<session>/pose")
        return 0
    suffix = {"tum": ".tum", "kitti": ".txt", "euroc": ".csv"}[args.to]
    with atomic_path(out, directory=True) as tmp:
        tmp.mkdir(parents=True)
        for i, name in enumerate(names):
            write_trajectory(tmp / f"{session_file_stem(name)}{suffix}", m.session_trajectory(i), args.to)
    print(f"{out}/: {len(names)} session trajectories ({args.to}) from {Path(args.map_dir) / MANIFEST}")
    return 0


def _topic(name: str) -> str:
    """A session name inside a ROS topic name (letters, digits and _ only)."""
    return "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in name) or "session"
