"""`slam-lcd localize LOG --map DIR --out OUT`: localise a log against a saved map without changing it.

Exit status: 0 when at least one keyframe is localised; 1 when none is (the outputs are still
written: ``localization.csv`` gives each keyframe's reason, the report says 0 %); 2 bad input
(the map, the log, the paths); 130 / 143 / 129 after Ctrl-C / SIGTERM / SIGHUP.
"""
from __future__ import annotations

from pathlib import Path

from ..runtime.interrupts import exit_status
from .run import add_config_args, add_source_args, config_from_args, config_inputs, run_input_paths, sources_of


def register(sub) -> None:
    p = sub.add_parser("localize", help="localise a log against a saved map (the map is only read)",
                       description="Stream a log through keyframe selection and SuperPoint, match each keyframe "
                                   "against the map's keyframes (Bag of SuperPoints, graph verification, metric "
                                   "pose), keep the matches its odometry confirms, and write its trajectory in the "
                                   "map frame. The map folder is never written to.")
    p.add_argument("log", help="ROS1 .bag, rosbag2 folder or .mcap file")
    p.add_argument("--map", required=True, metavar="DIR", help="the map folder (from `slam-lcd run --map`; required)")
    p.add_argument("-o", "--out", required=True,
                   help="output folder (required; created if missing): localized.tum, keyframes_localized.tum, "
                        "localization.csv, report.json/.md/.html and the run's usual files")
    add_source_args(p)
    p.add_argument("--no-mcap", action="store_true", help="do not write corrected.mcap (default: write it)")
    add_config_args(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..features import load_extractor
    from ..map.session_map import Map, extractor_meta
    from ..map.summary import localisation_lines
    from ..run.checks import check_run_paths
    from ..run.options import MapUse, Models, OutputOptions
    from ..run.runner import run_log

    cfg = config_from_args(args)
    inputs = config_inputs(args)
    check_run_paths(args.log, args.out, cfg, args.gt, run_input_paths(args), map_dir=args.map)  # before any work
    m = Map.open(args.map, conf=cfg.map)  # a missing, foreign or damaged map: refused before the model loads
    with m:
        extractor = load_extractor(cfg.features)
        m.check_features(extractor_meta(extractor, cfg.map.descriptor_form))
        res = run_log(args.log, Path(args.out), cfg, sources=sources_of(args), models=Models(extractor=extractor),
                      map_use=MapUse(m, mode="localize"),
                      output=OutputOptions(progress=not args.no_progress, write_mcap=not args.no_mcap,
                                           input_paths=inputs, command_line=getattr(args, "command_line", None),
                                           overrides=list(args.overrides)))
    if res.localization is not None:
        for line in localisation_lines(res.localization):
            print(line)
    print(f"outputs in {res.out_dir}/ ({', '.join(res.outputs)})"
          + (" -- a partial set, see PARTIAL.txt" if res.interrupted else ""))
    if res.interrupted:
        return exit_status()  # 130 Ctrl-C, 143 SIGTERM, 129 SIGHUP
    return 0 if res.localization is not None and res.localization["localised"] else 1
