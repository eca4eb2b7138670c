"""`slam-lcd eval-lcd`: evaluate loop-closure detection against ground truth.

Runs the loop detector over an image folder (or an image topic of a log), scores every BoW
candidate with every verification check, and writes, under ``--out``: ``candidates.csv``
(every candidate with its evidence and ground truth), ``pr.csv`` (precision-recall per
mode), ``pr.png`` (the curves), ``summary.json`` and the resolved ``config.yaml``.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import time
from pathlib import Path

import numpy as np

from ..errors import InputError

log = logging.getLogger(__name__)

MODES = ("none", "ransac", "graph", "graph+ransac")
EVAL_OUTPUTS = ("candidates.csv", "pr.csv", "pr.png", "summary.json", "config.yaml")


def register(sub) -> None:
    p = sub.add_parser(
        "eval-lcd",
        help="evaluate loop-closure detection (precision-recall, recall at 100%% precision) against ground truth",
        description="Run BoW candidate retrieval + verification over SOURCE and compare with ground truth.",
    )
    p.add_argument("source", help="image folder, or a bag/MCAP file with --topic")
    p.add_argument("--gt", required=True,
                   help="loop matrix (RTAB-Map .bmp/.png, .npy, .csv pairs) or, with --gt-max-dist, a GT trajectory")
    p.add_argument("--gt-max-dist", type=float, default=None, help="GT poses: loop if closer than this (m)")
    p.add_argument("--gt-max-angle", type=float, default=30.0, help="GT poses: and rotated less than this (deg)")
    p.add_argument("--topic", help="image topic when SOURCE is a log")
    p.add_argument("--camera-info-topic", help="camera_info topic when SOURCE is a log")
    p.add_argument("--features", choices=["superpoint", "orb"], default=None, help="feature extractor")
    p.add_argument("--verify", choices=[*MODES, "all"], default="all", help="verification chain (default: all four)")
    p.add_argument("--weights", help="SuperPoint weights file")
    p.add_argument("--vocab", help="trained vocabulary (.npz); default: online vocabulary")
    p.add_argument("--top-k", type=int, default=None, help="BoW candidates per query (lcd.top_k)")
    p.add_argument("--exclude-recent", type=int, default=None, help="skip the last N frames (lcd.exclude_recent_n)")
    p.add_argument("--focal-factor", type=float, default=None,
                   help="focal length = factor x width when the images have no intrinsics (lcd.default_focal_factor)")
    p.add_argument("--config", help="preset name or YAML file")
    p.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="override a config value")
    p.add_argument("--out", default="lcd_eval", help="output folder (default: ./lcd_eval)")
    p.add_argument("--no-feature-cache", action="store_true", help="do not read/write the on-disk feature cache")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..config import load_config, validate_config
    from ..lcd import LoopDetector
    from ..lcd.evaluation import format_table, load_loop_matrix, precision_recall
    from ..output_set import OutputSet
    from ..lcd.sources import folder_frames, frame_to_keyframe, log_frames

    cfg = load_config(args.config, args.set)
    if args.features:
        cfg.features = dataclasses.replace(cfg.features, kind=args.features)
    if args.weights:
        cfg.features = dataclasses.replace(cfg.features, weights=args.weights)
    if args.no_feature_cache:
        cfg.features = dataclasses.replace(cfg.features, feature_cache=False)
    lcd = cfg.lcd
    if args.top_k is not None:
        lcd = dataclasses.replace(lcd, top_k=args.top_k)
    if args.exclude_recent is not None:
        lcd = dataclasses.replace(lcd, exclude_recent_n=args.exclude_recent)
    if args.focal_factor is not None:
        lcd = dataclasses.replace(lcd, default_focal_factor=args.focal_factor)
    modes = list(MODES) if args.verify == "all" else [args.verify]
    # evaluation scores images, not a SLAM run: no metric pose, no temporal filter
    lcd = dataclasses.replace(lcd, verify=modes[-1], pose=False, temporal_k=0)
    cfg.lcd = lcd
    validate_config(cfg)

    src = Path(args.source)
    out = Path(args.out)
    # every output is checked against every input before any work; the set is published whole
    outputs = OutputSet(out, EVAL_OUTPUTS)
    outputs.check({"SOURCE": src, "--gt": args.gt, "--vocab": args.vocab, "--weights": args.weights,
                   "--config": args.config if args.config and Path(args.config).exists() else None})
    if src.is_dir() and not (src / "metadata.yaml").exists():
        names, stamps, frames = folder_frames(src, exclude=[args.gt])
    else:
        if not args.topic:
            raise InputError("SOURCE is not an image folder: give the image topic with --topic", src)
        names, stamps, frames = log_frames(src, args.topic, args.camera_info_topic)

    if args.gt_max_dist is not None:
        gt = _gt_from_trajectory(args.gt, stamps, args)
    else:
        gt = load_loop_matrix(args.gt, names)

    from ..features import load_extractor

    extractor = load_extractor(cfg.features, weights=cfg.features.weights)
    vocab = None
    if args.vocab:
        from ..vocab import Vocabulary

        vocab = Vocabulary.load(args.vocab)
    det = LoopDetector(lcd, vocab=vocab, extractor=extractor, vocab_conf=cfg.vocab, run_all_checks=True)
    t0 = time.perf_counter()
    cache = None
    if cfg.features.feature_cache:
        from ..features import FeatureCache

        cache = FeatureCache(extractor)
    topic_name = args.topic or "images"
    for k, fr in enumerate(frames):
        kf = frame_to_keyframe(k, fr, None)
        if cache is not None:
            kf.features = cache.extract(src, topic_name, kf.stamp, kf.image)
        det.add(kf)
        log.info("frame %d/%d %s", k + 1, len(names), fr.name)
    elapsed = time.perf_counter() - t0

    results = [precision_recall(det.records, gt, m, lcd.exclude_recent_n) for m in modes]
    kind = cfg.features.kind
    table = format_table(results, kind)
    print(table)
    try:
        _write_set(outputs, cfg, det, gt, names, results, src, args, kind, elapsed)
    except OSError as e:
        outputs.discard()
        raise InputError(f"cannot write the outputs ({e.strerror or e}); nothing was written there", out) from None
    except BaseException:
        outputs.discard()
        raise
    print(f"wrote {out}/candidates.csv, pr.csv, pr.png, summary.json ({len(det.records)} candidates, {elapsed:.1f} s)")
    return 0


def _write_set(outputs, cfg, det, gt, names, results, src, args, kind, elapsed) -> None:
    from ..atomic import write_text
    from ..config import save_config
    from ..lcd.evaluation import plot_pr, write_candidates_csv, write_pr_csv

    out = outputs.staging
    write_candidates_csv(out / "candidates.csv", det.records, gt, names)
    write_pr_csv(out / "pr.csv", results)
    plot_pr(out / "pr.png", results, f"{src.name} ({kind})")
    summary = {
        "source": str(src), "ground_truth": str(args.gt), "features": kind, "frames": len(names),
        "candidates": len(det.records), "seconds": round(elapsed, 2),
        "results": [r.summary() for r in results],
    }
    write_text(out / "summary.json", json.dumps(summary, indent=2))
    save_config(cfg, out / "config.yaml")
    outputs.publish()


def _gt_from_trajectory(path, stamps, args) -> np.ndarray:
    """Loop matrix from a GT trajectory: poses associated to the frames by nearest stamp (within 50 ms)."""
    from ..io.trajectory_files import read_trajectory
    from ..lcd.evaluation import loops_from_poses

    traj = read_trajectory(path)
    stamps = np.asarray(stamps, dtype=np.int64)
    if len(traj) < 2:
        raise InputError("GT trajectory has fewer than 2 poses", path)
    idx = np.searchsorted(traj.stamps, stamps).clip(1, len(traj) - 1)
    prev = idx - 1
    pick = np.where(np.abs(traj.stamps[prev] - stamps) < np.abs(traj.stamps[idx] - stamps), prev, idx)
    if np.any(np.abs(traj.stamps[pick] - stamps) > 50_000_000):
        raise InputError("some frames have no GT pose within 50 ms (name frames by their timestamp in seconds)", path)
    return loops_from_poses(traj.poses[pick], args.gt_max_dist, args.gt_max_angle)
