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


def iter_source_images(source: Path, topic: str | None, every: int = 1, max_images: int | None = None):
    """Grey uint8 images of an image folder (natural order) or of one image topic of a log."""
    import cv2

    every = max(1, every)
    count = 0
    if source.is_dir() and not (source / "metadata.yaml").exists():
        files = sorted((f for f in source.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES), key=_natural_key)
        if not files:
            raise InputError("no images (.png/.jpg/...) in this folder", source)
        for f in files[::every]:
            img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
            if img is None:
                raise InputError("cannot decode image", f)
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
        for n, m in enumerate(reader.messages([topic])):
            if n % every:
                continue
            img = decode_compressed_image(m.msg) if "Compressed" in m.msgtype else decode_image(m.msg)
            yield image_to_gray(img)
            count += 1
            if max_images is not None and count >= max_images:
                return


def run_train(args) -> int:
    from ..atomic import guard_not_input
    from ..config import load_config
    from ..features import load_extractor
    from ..vocab import train_hkmeans, train_vocabulary

    cfg = load_config(args.config, args.set)
    if args.features:
        cfg.features.kind = args.features
    if args.weights:
        cfg.features.weights = args.weights
    tree = args.tree or cfg.vocab.tree
    source, out = Path(args.source), Path(args.out)
    guard_not_input(out, source)
    extractor = load_extractor(cfg.features)
    t0 = time.perf_counter()
    sets = []
    for img in iter_source_images(source, args.topic, args.every, args.max_images):
        sets.append(extractor.extract(img).descriptors)
    n_desc = sum(len(d) for d in sets)
    log.info("extracted %d descriptors from %d images in %.1f s", n_desc, len(sets), time.perf_counter() - t0)
    t1 = time.perf_counter()
    if tree == "dp":
        vocab = train_vocabulary(sets, cfg.vocab, features=cfg.features.kind)
    else:
        vocab = train_hkmeans(sets, cfg.vocab.hk_branching, cfg.vocab.hk_depth, cfg.vocab.seed, features=cfg.features.kind)
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
