"""`slam-lcd vocab`: train or inspect a Bag of SuperPoints vocabulary.

``slam-lcd vocab train SOURCE --out VOCAB.npz [--features superpoint|orb] [--weights W] [--tree dp|hkmeans]``
where SOURCE is an image folder (files in natural name order) or a log with ``--topic``;
``slam-lcd vocab info VOCAB.npz`` prints words, depth and branching per level.
"""
from __future__ import annotations

import logging
import time
from pathlib import Path

from ..config import validate_config
from ..errors import DamagedImageError, FileMissingError, InputError, SlamLcdError, in_context, stamp_text
from ..files.atomic import check_no_clash, check_writable_target
from .run import add_alias, add_config_args, config_from_args
from .util import write_guard

log = logging.getLogger(__name__)

def register(sub) -> None:
    p = sub.add_parser("vocab", help="train or inspect a Bag of SuperPoints vocabulary")
    vsub = p.add_subparsers(dest="vocab_command", metavar="ACTION")
    t = vsub.add_parser("train", help="train a vocabulary from an image folder or a log's image topic")
    t.add_argument("source", help="image folder (image files in natural name order; files named *GT* / "
                                  "*groundtruth* are left out), or a ROS1/ROS2 bag or MCAP file with --image-topic")
    t.add_argument("-o", "--out", required=True, help="output vocabulary (.npz) (required)")
    t.add_argument("--image-topic", default=None,
                   help="image topic when SOURCE is a log (required then; default: none for a folder)")
    add_alias(t, "--topic", "image_topic")  # old spelling of --image-topic
    t.add_argument("--tree", choices=["dp", "hkmeans"], default=None,
                   help="word tree (default: the config's vocab.tree, dp)")
    t.add_argument("--every", type=int, default=1, help="use every n-th image (default 1)")
    t.add_argument("--max-images", type=int, default=None, help="stop after this many images (default: all)")
    add_config_args(t)
    t.set_defaults(func=run_train)
    i = vsub.add_parser("info", help="print words, depth and branching of a vocabulary")
    i.add_argument("vocab", help="vocabulary file (.npz)")
    i.set_defaults(func=run_info)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


FOLDER_TOPIC = "images"  # feature-cache topic of an image folder (the same as eval-lcd's)


def source_image_count(source: Path, topic: str | None, every: int = 1, max_images: int | None = None) -> int | None:
    """How many images :func:`iter_source_images` yields (for the progress bar); None if unknown."""
    every = max(1, every)
    if source.is_dir() and not (source / "metadata.yaml").exists():
        from ..io.image_folder import list_image_files

        n = len(list_image_files(source)[::every])
    elif source.exists() and topic:
        from ..io import open_log

        with open_log(source) as reader:
            info = reader.topics.get(topic)
            if info is None:
                return None
            n = -(-info.count // every)
    else:
        return None
    return n if max_images is None else min(n, max_images)


def iter_source_images(source: Path, topic: str | None, every: int = 1, max_images: int | None = None,
                       skipped: list | None = None):
    """``(topic, stamp, image)`` of an image folder (natural order, image files only, stamps and
    pixels as eval-lcd reads them) or grey images of one image topic of a log (as ``run``
    reads them). The (source, topic, stamp) triple is the feature-cache key, so a vocabulary
    trained after ``run`` or before ``eval-lcd`` on the same source reuses their features.

    Damaged or unreadable images are skipped when ``skipped`` (a list) is given: their
    errors are appended to it (the caller warns once); otherwise they raise.
    """
    every = max(1, every)
    count = 0
    if source.is_dir() and not (source / "metadata.yaml").exists():
        from ..io.image_folder import folder_frames, read_frame

        names, stamps, _ = folder_frames(source)  # the listing and stamps eval-lcd uses (images read below)
        for n in range(0, len(names), every):
            try:
                img = read_frame(source / names[n])
            except InputError as e:
                if skipped is None:
                    raise
                skipped.append(e)
                continue
            yield FOLDER_TOPIC, stamps[n], img
            count += 1
            if max_images is not None and count >= max_images:
                return
        return
    if not source.exists():
        raise FileMissingError("training source not found", source)
    if not topic:
        raise InputError("SOURCE is a log: give the image topic with --image-topic", source)
    from ..io import open_log
    from ..sensors.messages import decode_gray
    from ..sensors.topics import IMAGE_TYPES

    with open_log(source) as reader:
        (name,) = reader.resolve_topics([topic], flag="--image-topic")
        msgtype = reader.topics[name].msgtype
        if msgtype not in IMAGE_TYPES:
            raise InputError(f"--image-topic {name} carries {msgtype}, not a camera image", source)
        for n, m in enumerate(reader.messages([name])):
            if n % every:
                continue
            try:
                gray = decode_gray(m)
            except SlamLcdError as e:
                err = in_context(e, f"topic {m.topic}, stamp {stamp_text(m.stamp)}", source)
                if skipped is None or not isinstance(e, DamagedImageError):
                    raise err from None
                skipped.append(err)
                continue
            yield name, m.stamp, gray
            count += 1
            if max_images is not None and count >= max_images:
                return


def run_train(args) -> int:
    from ..features import load_extractor
    from ..runtime.progress import progress_bar, stage
    from ..vocab import train_hkmeans, train_vocabulary

    if args.every < 1:
        raise InputError(f"--every must be >= 1, got {args.every}")
    if args.max_images is not None and args.max_images < 1:
        raise InputError(f"--max-images must be >= 1, got {args.max_images}")
    source, out = Path(args.source), Path(args.out)
    config = args.config if args.config and Path(args.config).exists() else None
    check_no_clash({"--out": out}, {"SOURCE": source, "--config": config, "--weights": args.weights})
    check_writable_target(out)
    cfg = validate_config(config_from_args(args))
    tree = args.tree or cfg.vocab.tree
    extractor = load_extractor(cfg.features)
    t0 = time.perf_counter()
    cache = None
    if cfg.features.feature_cache:
        from ..features import FeatureCache

        cache = FeatureCache(extractor)
    sets = []
    skipped: list = []
    total = source_image_count(source, args.image_topic, args.every, args.max_images)
    images = iter_source_images(source, args.image_topic, args.every, args.max_images, skipped=skipped)
    for topic, stamp, img in progress_bar(images, total=total, desc="features", unit="img",
                                          enabled=not args.no_progress):
        feats = cache.extract(source, topic, stamp, img) if cache is not None else extractor.extract(img)
        sets.append(feats.descriptors)
    if skipped:
        log.warning("%d damaged or unreadable image(s) skipped; the first: %s", len(skipped), skipped[0])
    if not sets:
        raise InputError("no readable image to train on", source)
    n_desc = sum(len(d) for d in sets)
    log.info("extracted %d descriptors from %d images in %.1f s", n_desc, len(sets), time.perf_counter() - t0)
    t1 = time.perf_counter()
    with stage(f"training a {tree} tree on {n_desc} descriptors", enabled=not args.no_progress):
        if tree == "dp":
            vocab = train_vocabulary(sets, cfg.vocab, features=cfg.features.kind)
        else:
            vocab = train_hkmeans(sets, cfg.vocab.hk_branching, cfg.vocab.hk_depth, cfg.vocab.seed,
                                  features=cfg.features.kind)
    with write_guard(out):
        vocab.save(out)
    print(f"{out}: {len(vocab)} words, depth {vocab.depth}, tree {tree}, {cfg.features.kind} features "
          f"from {len(sets)} images ({n_desc} descriptors), trained in {time.perf_counter() - t1:.1f} s")
    return 0


def run_info(args) -> int:
    from ..vocab import Vocabulary

    vocab = Vocabulary.load(args.vocab)
    st = vocab.stats()
    print(f"{args.vocab}: {st['words']} words, depth {st['depth']}, tree {st.get('tree', '?')}, "
          f"features {st.get('features') or '?'} ({st['descriptors']}), trained on {st['n_images']} images")
    for lv in st["levels"]:
        print(f"  level {lv['level']}: {lv['nodes']} node(s), children min/mean/max "
              f"{lv['children_min']}/{lv['children_mean']:.1f}/{lv['children_max']}")
    return 0
