"""The feature options every subcommand that extracts features offers (``--weights``, ``--device``).

    from slam_lcd.features.cli_args import add_feature_arguments, apply_feature_arguments
    add_feature_arguments(parser)                     # in register()
    cfg.features = apply_feature_arguments(cfg.features, args)   # in func()
"""
from __future__ import annotations

import argparse
import dataclasses

from .config import FeaturesConfig


def add_feature_arguments(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("features")
    g.add_argument("--weights", metavar="PATH", default=None,
                   help="SuperPoint weights (superpoint_v1.pth); default: $SLAM_LCD_SUPERPOINT_WEIGHTS, "
                        "then the cache dir ($SLAM_LCD_CACHE_DIR or ~/.cache/slam-lcd), then download")
    g.add_argument("--device", choices=["auto", "cpu", "cuda"], default=None,
                   help="where SuperPoint runs (default: features.device, 'auto')")
    g.add_argument("--features", choices=["superpoint", "orb"], default=None, dest="features_kind",
                   help="feature extractor (default: features.kind)")


def apply_feature_arguments(conf: FeaturesConfig, args: argparse.Namespace) -> FeaturesConfig:
    """A copy of ``conf`` with the command-line options that were given."""
    changes = {}
    if getattr(args, "weights", None):
        changes["weights"] = args.weights
    if getattr(args, "device", None):
        changes["device"] = args.device
    if getattr(args, "features_kind", None):
        changes["kind"] = args.features_kind
    return dataclasses.replace(conf, **changes)
