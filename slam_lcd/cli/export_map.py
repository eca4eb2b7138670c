"""`slam-lcd export-map RUN_DIR OUT.ply|OUT.pcd`: rebuild a finished run's map cloud with other settings.

The run's own settings (``map_cloud`` in its resolved config) are the defaults; the flags
change the voxel size, the depth range and the pixel step. Reads the run's log again
(:mod:`slam_lcd.outputs.cloud_export`); a folder that is not a run or a run whose log is gone is one
line and exit status 2, with nothing written.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

from ..cloud import MapCloudConfig
from ..config import Config, apply_override, validate_config
from ..errors import InputError


def register(sub) -> None:
    p = sub.add_parser("export-map", help="rebuild a finished run's map point cloud (PLY / PCD) from its log",
                       description="Rebuild the map point cloud of a finished `slam-lcd run` (keyframe poses + the "
                                   "log's depth or stereo images) with another voxel size or depth range, as PLY or "
                                   "PCD (binary; x y z float32 and RGB).")
    p.add_argument("run_dir", metavar="RUN_DIR", help="output folder of `slam-lcd run`")
    p.add_argument("out", metavar="OUT", help="cloud file to write: .ply or .pcd")
    p.add_argument("--voxel", type=float, default=None, metavar="M",
                   help="voxel edge in metres (default: the run's map_cloud.voxel_m)")
    p.add_argument("--min-depth", type=float, default=None, metavar="M",
                   help="nearest sensor depth used (default: the run's map_cloud.min_depth_m)")
    p.add_argument("--max-depth", type=float, default=None, metavar="M",
                   help="farthest sensor depth used (default: the run's map_cloud.max_depth_m)")
    p.add_argument("--pixel-step", type=int, default=None, metavar="N",
                   help="use every N-th pixel in both directions (default: the run's map_cloud.pixel_step)")
    p.add_argument("--odometry", action="store_true",
                   help="merge with the odometry poses instead of the corrected ones (default: corrected)")
    p.add_argument("--log", default=None, metavar="PATH",
                   help="the run's log, if it moved (default: the path report.json names)")
    p.set_defaults(func=run)


def _settings(run_dir: Path, args):
    """The run's ``map_cloud`` section with the flags applied, range-checked like any config."""
    cfg = Config()
    try:
        section = json.loads((run_dir / "report.json").read_text(encoding="utf-8")).get("config", {}).get(
            "map_cloud", {}) or {}
    except (OSError, ValueError, AttributeError):
        section = {}  # export_map says what is wrong with the folder
    names = {f.name for f in dataclasses.fields(MapCloudConfig)}
    cfg.map_cloud = MapCloudConfig(**{k: v for k, v in section.items() if k in names})
    for key, value in (("voxel_m", args.voxel), ("min_depth_m", args.min_depth), ("max_depth_m", args.max_depth),
                       ("pixel_step", args.pixel_step)):
        if value is not None:
            cfg = apply_override(cfg, f"map_cloud.{key}={value}")
    try:
        return validate_config(cfg).map_cloud
    except InputError as e:
        raise InputError(e.problem.replace("map_cloud.", "--").replace("_m ", " ")) from None


def run(args) -> int:
    from ..outputs.cloud_export import export_map

    run_dir = Path(args.run_dir)
    conf = _settings(run_dir, args)
    res = export_map(run_dir, Path(args.out), conf, odometry=args.odometry, log_path=args.log)
    skipped = "; ".join(f"{n} skipped: {r}" for r, n in res["skipped"].items())
    print(f"wrote {args.out}: {res['points']} points from {res['keyframes_used']} of {res['keyframes']} keyframes "
          f"({res['poses']} poses, voxel {conf.voxel_m:g} m, depth {conf.min_depth_m:g}-{conf.max_depth_m:g} m)"
          + (f"; {skipped}" if skipped else ""))
    return 0
