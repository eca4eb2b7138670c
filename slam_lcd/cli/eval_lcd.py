"""`slam-lcd eval-lcd`: evaluate loop-closure detection against ground truth.

Runs the loop detector over an image folder (or an image topic of a log), scores every BoW
candidate with every verification check, and writes, under ``--out``: ``candidates.csv``
(every candidate with its evidence and ground truth), ``pr.csv`` (precision-recall per
mode), ``pr.png`` (the curves), ``summary.json`` and the resolved ``config.yaml``.
Besides recall at 100% precision it reports the area under each PR curve, Recall@1/5/10 of
BoW retrieval and, when the ground truth is a trajectory, the revisit places found.
"""
from __future__ import annotations

import dataclasses
import json
import logging
import time
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from ..config import save_config, validate_config
from ..errors import InputError
from ..files.atomic import write_text
from .run import add_alias, add_config_args, config_from_args

if TYPE_CHECKING:
    import numpy as np

    from ..io.image_folder import Frame

log = logging.getLogger(__name__)

MODES = ("none", "ransac", "graph", "graph+ransac")
RECALL_AT = (1, 5, 10)  # Recall@N of retrieval
EVAL_OUTPUTS = ("candidates.csv", "pr.csv", "pr.png", "summary.json", "config.yaml")


def register(sub) -> None:
    p = sub.add_parser(
        "eval-lcd",
        help="evaluate loop-closure detection (precision-recall, recall at 100%% precision) against ground truth",
        description="Run BoW candidate retrieval + verification over SOURCE and compare with ground truth.",
    )
    p.add_argument("source", help="image folder (image files in natural name order), or a bag/MCAP file with "
                                  "--image-topic")
    p.add_argument("--gt", required=True,
                   help="ground truth (required): loop matrix (RTAB-Map .bmp/.png, .npy, .csv pairs) or, with "
                        "--gt-max-dist, a GT trajectory; a file inside the image folder is never read as a frame")
    p.add_argument("--gt-max-dist", type=float, default=None,
                   help="read --gt as poses: a loop if closer than this, m (default: --gt is a loop matrix)")
    p.add_argument("--gt-max-angle", type=float, default=30.0,
                   help="with --gt-max-dist: and rotated less than this, deg (default 30)")
    p.add_argument("--image-topic", default=None,
                   help="image topic when SOURCE is a log (required then; default: none for a folder)")
    add_alias(p, "--topic", "image_topic")  # old spelling of --image-topic
    p.add_argument("--camera-info-topic", default=None,
                   help="camera_info topic when SOURCE is a log (default: none; intrinsics from "
                        "--focal-factor)")
    p.add_argument("--verify", choices=[*MODES, "all"], default="all",
                   help="verification chain (default: all four, one PR curve each)")
    p.add_argument("--vocab", default=None, help="trained vocabulary (.npz) (default: the online vocabulary)")
    p.add_argument("--top-k", type=int, default=None,
                   help="BoW candidates per query (default: the config's lcd.top_k, 5)")
    p.add_argument("--exclude-recent", type=int, default=None,
                   help="skip the last N frames as candidates (default: the config's lcd.exclude_recent_n, 20)")
    p.add_argument("--focal-factor", type=float, default=None,
                   help="focal length = factor x width when the images have no intrinsics "
                        "(default: the config's lcd.default_focal_factor, 0.9)")
    p.add_argument("-o", "--out", default="lcd_eval", help="output folder (default: ./lcd_eval)")
    add_config_args(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from ..eval.loop_detection import (
        format_retrieval,
        format_table,
        load_loop_matrix,
        place_recall,
        precision_recall,
        retrieval_recall,
        revisit_places,
    )
    from ..io.image_folder import folder_frames
    from ..lcd import LoopDetector
    from ..outputs.output_set import OutputSet
    from ..runtime.progress import progress_bar
    from ..sensors.frames import frame_to_keyframe, log_frames

    cfg = config_from_args(args)
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
    frames: Iterable[Frame]  # the folder's frames read lazily, a log's all at once
    if src.is_dir() and not (src / "metadata.yaml").exists():
        names, stamps, frames = folder_frames(src, exclude=[args.gt])
    else:
        if not args.image_topic:
            raise InputError("SOURCE is not an image folder: give the image topic with --image-topic", src)
        names, stamps, frames = log_frames(src, args.image_topic, args.camera_info_topic)

    positions = None
    if args.gt_max_dist is not None:
        gt, positions = _gt_from_trajectory(args.gt, stamps, args)
    else:
        gt = load_loop_matrix(args.gt, names)

    from ..features import load_extractor

    extractor = load_extractor(cfg.features)
    vocab = None
    if args.vocab:
        from ..vocab import Vocabulary

        vocab = Vocabulary.load(args.vocab)
    det = LoopDetector(lcd, vocab=vocab, extractor=extractor, vocab_conf=cfg.vocab, run_all_checks=True,
                       retrieval_depth=max(RECALL_AT))
    t0 = time.perf_counter()
    cache = None
    if cfg.features.feature_cache:
        from ..features import FeatureCache

        cache = FeatureCache(extractor)
    topic_name = args.image_topic or "images"
    bar = progress_bar(total=len(names), desc="loop detection", unit="img", enabled=not args.no_progress)
    try:
        for k, fr in enumerate(frames):
            kf = frame_to_keyframe(k, fr, None)
            if cache is not None:
                kf.features = cache.extract(src, topic_name, kf.stamp, kf.image)
            det.add(kf)
            bar.update(1)
            log.info("frame %d/%d %s", k + 1, len(names), fr.name)
    finally:
        bar.close()
    elapsed = time.perf_counter() - t0

    results = [precision_recall(det.records, gt, m, lcd.exclude_recent_n) for m in modes]
    recall_at = retrieval_recall(det.retrieved, gt, lcd.exclude_recent_n, RECALL_AT)
    places = None
    if positions is not None:
        revisits = revisit_places(positions, gt, lcd.exclude_recent_n, args.gt_max_dist)
        places = {m: place_recall(det.records, gt, m, revisits) for m in modes}
    kind = cfg.features.kind
    print(format_table(results, kind, places))
    print(format_retrieval(recall_at, kind))
    try:
        _write_set(outputs, cfg, det, gt, names, results, src, args, kind, elapsed, recall_at, places)
    except OSError as e:
        outputs.discard()
        raise InputError(f"cannot write the outputs ({e.strerror or e}); nothing was written there", out) from None
    except BaseException:
        outputs.discard()
        raise
    print(f"wrote {out}/candidates.csv, pr.csv, pr.png, summary.json ({len(det.records)} candidates, {elapsed:.1f} s)")
    return 0


def _write_set(outputs, cfg, det, gt, names, results, src, args, kind, elapsed, recall_at, places) -> None:
    from ..eval.loop_detection import plot_pr, write_candidates_csv, write_pr_csv

    out = outputs.staging
    write_candidates_csv(out / "candidates.csv", det.records, gt, names)
    write_pr_csv(out / "pr.csv", results)
    plot_pr(out / "pr.png", results, f"{src.name} ({kind})")
    summary = {
        "source": str(src), "ground_truth": str(args.gt), "features": kind, "frames": len(names),
        "candidates": len(det.records), "seconds": round(elapsed, 2),
        "results": [r.summary() for r in results],
        "retrieval_recall_at": {str(n): round(v, 4) for n, v in recall_at.items()},
    }
    if places is not None:
        summary["revisit_places"] = {m: {"found": f, "places": n} for m, (f, n) in places.items()}
    write_text(out / "summary.json", json.dumps(summary, indent=2))
    save_config(cfg, out / "config.yaml")
    outputs.publish()


def _gt_from_trajectory(path, stamps, args) -> tuple[np.ndarray, np.ndarray]:
    """Loop matrix and frame positions from a GT trajectory.

    Poses are associated to the frames by nearest stamp (within 50 ms).
    """
    import numpy as np  # here: the parser loads this module for every command, numpy only for this

    from ..eval.loop_detection import loops_from_poses
    from ..io.trajectory_files import read_trajectory

    traj = read_trajectory(path)
    stamps = np.asarray(stamps, dtype=np.int64)
    if len(traj) < 2:
        raise InputError("GT trajectory has fewer than 2 poses", path)
    idx = np.searchsorted(traj.stamps, stamps).clip(1, len(traj) - 1)
    prev = idx - 1
    pick = np.where(np.abs(traj.stamps[prev] - stamps) < np.abs(traj.stamps[idx] - stamps), prev, idx)
    if np.any(np.abs(traj.stamps[pick] - stamps) > 50_000_000):
        raise InputError("some frames have no GT pose within 50 ms (name frames by their timestamp in seconds)", path)
    poses = traj.poses[pick]
    return loops_from_poses(poses, args.gt_max_dist, args.gt_max_angle), poses[:, :3, 3]
