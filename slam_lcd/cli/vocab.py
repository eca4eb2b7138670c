"""`slam-lcd vocab`: train or inspect a Bag of SuperPoints vocabulary.

``slam-lcd vocab train SOURCE --out VOCAB.npz [--features superpoint|orb] [--weights W] [--tree dp|hkmeans]``
where SOURCE is an image folder (files in natural name order) or a log with ``--topic``;
``slam-lcd vocab info VOCAB.npz`` prints words, depth and branching per level.
"""
from __future__ import annotations

import logging
import re
import time
from pathlib import Path

from ..errors import FileMissingError, InputError

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".pgm", ".ppm", ".tif", ".tiff"}


def register(sub) -> None:
    p = sub.add_parser("vocab", help="train or inspect a Bag of SuperPoints vocabulary")
    vsub = p.add_subparsers(dest="vocab_command", metavar="ACTION")
    t = vsub.add_parser("train", help="train a vocabulary from an image folder or a log's image topic")
    t.add_argument("source", help="image folder, or a ROS1/ROS2 bag or MCAP file (with --topic)")
    t.add_argument("--out", required=True, help="output vocabulary (.npz)")
    t.add_argument("--topic", help="image topic when SOURCE is a log")
    t.add_argument("--features", choices=["superpoint", "orb"], default=None, help="descriptor kind (default: config)")
    t.add_argument("--weights", help="SuperPoint weights file")
    t.add_argument("--tree", choices=["dp", "hkmeans"], default=None, help="word tree (default: config vocab.tree)")
    t.add_argument("--every", type=int, default=1, help="use every n-th image (default 1)")
    t.add_argument("--max-images", type=int, default=None, help="stop after this many images")
    t.add_argument("--config", help="preset name or YAML file")
    t.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE", help="config override")
    t.set_defaults(func=run_train)
    i = vsub.add_parser("info", help="print words, depth and branching of a vocabulary")
    i.add_argument("vocab", help="vocabulary file (.npz)")
    i.set_defaults(func=run_info)
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])


def _natural_key(path: Path):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path.name)]


def iter_source_images(source: Path, topic: str | None, every: int = 1, max_images: int | None = None,
                       skipped: list | None = None):
    """Grey uint8 images of an image folder (natural order) or of one image topic of a log.

    Damaged or unreadable images are skipped when ``skipped`` (a list) is given: their
    errors are appended to it (the caller warns once); otherwise they raise.
    """
    import cv2

    from ..errors import DamagedImageError, SlamLcdError, in_context, stamp_text
    from ..image_files import read_image

    every = max(1, every)
    count = 0
    if source.is_dir() and not (source / "metadata.yaml").exists():
        files = sorted((f for f in source.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES), key=_natural_key)
        if not files:
            raise InputError("no images (.png/.jpg/...) in this folder", source)
        for f in files[::every]:
            try:
                img = read_image(f, cv2.IMREAD_GRAYSCALE)
            except InputError as e:
                if skipped is None:
                    raise
                skipped.append(e)
                continue
            yield img
            count += 1
            if max_images is not None and count >= max_images:
                return
        return
    if not source.exists():
        raise FileMissingError("training source not found", source)
    if not topic:
        raise InputError("SOURCE is a log: give the image topic with --topic", source)
    from ..io import open_log
    from ..io.decode import decode_compressed_image, decode_image, image_to_gray

    with open_log(source) as reader:
        (name,) = reader.resolve_topics([topic])
        msgtype = reader.topics[name].msgtype
        if msgtype not in ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"):
            raise InputError(f"--topic {name} carries {msgtype}, not a camera image", source)
        for n, m in enumerate(reader.messages([name])):
            if n % every:
                continue
            try:
                img = decode_compressed_image(m.msg) if "Compressed" in m.msgtype else decode_image(m.msg)
                gray = image_to_gray(img)
            except SlamLcdError as e:
                err = in_context(e, f"topic {m.topic}, stamp {stamp_text(m.stamp)}", source)
                if skipped is None or not isinstance(e, DamagedImageError):
                    raise err from None
                skipped.append(err)
                continue
            yield gray
            count += 1
            if max_images is not None and count >= max_images:
                return


def run_train(args) -> int:
    from ..atomic import check_no_clash, check_writable_target
    from ..config import load_config, validate_config
    from ..features import load_extractor
    from ..vocab import train_hkmeans, train_vocabulary
    from .util import write_guard

    if args.every < 1:
        raise InputError(f"--every must be >= 1, got {args.every}")
    if args.max_images is not None and args.max_images < 1:
        raise InputError(f"--max-images must be >= 1, got {args.max_images}")
    source, out = Path(args.source), Path(args.out)
    check_writable_target(out)
    check_no_clash([out], {"SOURCE": source, "--config": args.config if args.config and Path(args.config).exists() else None,
                           "--weights": args.weights})
    cfg = load_config(args.config, args.set)
    if args.features:
        cfg.features.kind = args.features
    if args.weights:
        cfg.features.weights = args.weights
    validate_config(cfg)
    tree = args.tree or cfg.vocab.tree
    extractor = load_extractor(cfg.features)
    t0 = time.perf_counter()
    sets = []
    skipped: list = []
    for img in iter_source_images(source, args.topic, args.every, args.max_images, skipped=skipped):
        sets.append(extractor.extract(img).descriptors)
    if skipped:
        log.warning("%d damaged or unreadable image(s) skipped; the first: %s", len(skipped), skipped[0])
    if not sets:
        raise InputError("no readable image to train on", source)
    n_desc = sum(len(d) for d in sets)
    log.info("extracted %d descriptors from %d images in %.1f s", n_desc, len(sets), time.perf_counter() - t0)
    t1 = time.perf_counter()
    if tree == "dp":
        vocab = train_vocabulary(sets, cfg.vocab, features=cfg.features.kind)
    else:
        vocab = train_hkmeans(sets, cfg.vocab.hk_branching, cfg.vocab.hk_depth, cfg.vocab.seed, features=cfg.features.kind)
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
