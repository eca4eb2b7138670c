"""The trained vocabulary: a word tree plus per-word statistics, saved as a plain ``.npz``.

``train_vocabulary`` is the paper's method (incremental words, then the DP tree);
``train_hkmeans`` is the DBoW2-style baseline. Both return a :class:`Vocabulary`, which
quantises descriptors by greedy descent of its tree and carries the idf weights learned
from its training images (DBoW2's ``ln(N / n_w)``).
"""
from __future__ import annotations

import json
import zipfile
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..errors import InputError, VocabularyError
from ..files.atomic import atomic_write
from ..files.npz import save_npz
from ..runtime.thread_limits import blas_limit
from .config import VocabConfig
from .descriptors import as_unit_vectors, descriptor_kind
from .dp_tree import build_dp_tree
from .hkmeans import build_hkmeans_tree
from .tree import VocabTree
from .words import IncrementalWords

FORMAT = "slam-lcd-vocabulary"
VERSION = 1


def training_idf(word_images: np.ndarray, n_images: int) -> np.ndarray:
    """DBoW2 idf ``ln(N / n_w)``; words never seen in training get ``ln(N)`` (as if seen once)."""
    if n_images <= 1:
        return np.ones(len(word_images), dtype=np.float64)
    return np.log(n_images / np.maximum(word_images, 1)).astype(np.float64)


class Vocabulary:
    """Words organised in a tree; ``quantize`` maps descriptors to word ids (leaf indices)."""

    def __init__(self, tree: VocabTree, idf: np.ndarray, word_counts: np.ndarray, word_images: np.ndarray,
                 n_images: int, desc_kind: str, desc_dim: int, meta: dict | None = None):
        self.tree = tree
        self.idf = np.asarray(idf, dtype=np.float64)
        self.word_counts = np.asarray(word_counts, dtype=np.int64)
        self.word_images = np.asarray(word_images, dtype=np.int64)
        self.n_images = int(n_images)
        self.desc_kind = desc_kind  # 'float' (SuperPoint) | 'binary' (ORB)
        self.desc_dim = int(desc_dim)  # columns of the raw descriptors (256 floats, 32 bytes)
        self.meta = dict(meta or {})
        n = tree.n_words
        if not (len(self.idf) == len(self.word_counts) == len(self.word_images) == n):
            raise ValueError("per-word arrays must have one entry per leaf of the tree")

    def __len__(self) -> int:
        return self.tree.n_words

    @property
    def depth(self) -> int:
        return self.tree.depth

    def _unit(self, desc: np.ndarray) -> np.ndarray:
        d = np.asarray(desc)
        if d.ndim != 2 or descriptor_kind(d) != self.desc_kind or d.shape[1] != self.desc_dim:
            raise InputError(
                f"descriptors {d.dtype}{tuple(d.shape)} do not fit this vocabulary "
                f"({self.desc_kind}, {self.desc_dim} columns, trained on {self.meta.get('features', '?')})"
            )
        return as_unit_vectors(d)

    def quantize(self, desc: np.ndarray) -> np.ndarray:
        """Word id of each descriptor by greedy tree descent (vectorised over all descriptors)."""
        return self.tree.quantize(self._unit(desc))

    def quantize_exhaustive(self, desc: np.ndarray) -> np.ndarray:
        """Nearest word by brute force (the reference the greedy descent is measured against)."""
        return self.tree.quantize_exhaustive(self._unit(desc))

    def stats(self) -> dict:
        """Words, depth and branching statistics per level (for ``slam-lcd vocab info``)."""
        levels = []
        for lvl, b in enumerate(self.tree.branching()):
            levels.append({"level": lvl, "nodes": int(len(b)), "children_min": int(b.min()),
                           "children_mean": float(b.mean()), "children_max": int(b.max())})
        return {"words": len(self), "depth": self.depth, "levels": levels, "n_images": self.n_images,
                "descriptors": f"{self.desc_kind} x{self.desc_dim}", **self.meta}

    # ----------------------------------------------------------------- files
    def save(self, path: str | Path) -> None:
        """Write an ``.npz`` (no pickled objects) atomically."""
        arrays: dict[str, np.ndarray] = {
            "format": np.array(FORMAT), "version": np.array(VERSION),
            "n_levels": np.array(self.tree.depth), "idf": self.idf, "word_counts": self.word_counts,
            "word_images": self.word_images, "n_images": np.array(self.n_images),
            "desc_kind": np.array(self.desc_kind), "desc_dim": np.array(self.desc_dim),
            "meta": np.array(json.dumps(self.meta)),
        }
        for lvl, (c, p) in enumerate(zip(self.tree.centres, self.tree.parents, strict=True), start=1):
            arrays[f"centres_{lvl}"] = c
            arrays[f"parents_{lvl}"] = p.astype(np.int32)
        with atomic_write(path, "wb") as fh:
            save_npz(fh, arrays)

    @classmethod
    def load(cls, path: str | Path) -> Vocabulary:
        """Read a file written by :meth:`save`; any other or damaged file raises VocabularyError."""
        path = Path(path)
        if not path.is_file():
            raise VocabularyError("vocabulary file not found: train one with `slam-lcd vocab train`, or leave --vocab "
                                  "out for the online vocabulary", path)
        with open(path, "rb") as fh:
            if fh.read(4) != b"PK\x03\x04":
                raise VocabularyError("not a vocabulary: expected a .npz (zip) file", path)
        try:
            with np.load(path, allow_pickle=False) as z:
                if "format" not in z.files or str(z["format"]) != FORMAT:
                    raise VocabularyError("not a slam-lcd vocabulary (no 'format' entry)", path)
                if int(z["version"]) != VERSION:
                    raise VocabularyError(f"vocabulary version {int(z['version'])} is not supported", path)
                n_levels = int(z["n_levels"])
                centres = [z[f"centres_{lvl}"] for lvl in range(1, n_levels + 1)]
                parents = [z[f"parents_{lvl}"].astype(np.int64) for lvl in range(1, n_levels + 1)]
                tree = VocabTree(centres, parents)
                return cls(tree, z["idf"], z["word_counts"], z["word_images"], int(z["n_images"]),
                           str(z["desc_kind"]), int(z["desc_dim"]), json.loads(str(z["meta"])))
        except VocabularyError:
            raise
        except (zipfile.BadZipFile, OSError, EOFError, KeyError, ValueError, TypeError) as e:
            raise VocabularyError(f"unreadable or truncated vocabulary ({e.__class__.__name__}: {e})", path) from None


def _check_sets(descriptor_sets) -> tuple[list[np.ndarray], str, int]:
    sets = [np.asarray(d) for d in descriptor_sets]
    sets = [d for d in sets if d.ndim == 2 and len(d)]
    if not sets:
        raise InputError("no descriptors to train a vocabulary on")
    kinds = {descriptor_kind(d) for d in sets}
    dims = {d.shape[1] for d in sets}
    if len(kinds) != 1 or len(dims) != 1:
        raise InputError(f"training descriptors mix kinds/dimensions: {sorted(kinds)} {sorted(dims)}")
    return sets, kinds.pop(), dims.pop()


def train_vocabulary(descriptor_sets: Iterable[np.ndarray], conf: VocabConfig | None = None,
                     features: str = "") -> Vocabulary:
    """The paper's vocabulary: incremental words over the image sequence, then the DP tree."""
    conf = conf or VocabConfig()
    sets, kind, dim = _check_sets(descriptor_sets)
    units = [as_unit_vectors(d) for d in sets]
    words = IncrementalWords(units[0].shape[1], conf.match_ratio, conf.match_max_distance, kind)
    with blas_limit(1):  # thousands of tiny products: thread start-up costs more than it saves
        for u in units:
            words.add_image(u)
        tree, order = build_dp_tree(words.centres, words.counts.astype(np.float32), conf)
    counts, images = words.counts[order], words.image_counts[order]
    meta = {"tree": "dp", "features": features, "training_images": words.n_images,
            "dp_pca_dims": conf.dp_pca_dims, "dp_block_size": conf.dp_block_size,
            "dp_truncation": conf.dp_truncation, "dp_concentration": conf.dp_concentration,
            "max_branching": conf.max_branching, "match_ratio": conf.match_ratio,
            "match_max_distance": words.max_distance}
    return Vocabulary(tree, training_idf(images, words.n_images), counts, images, words.n_images, kind, dim, meta)


def train_hkmeans(descriptors, k: int = 10, L: int = 4, seed: int = 0, features: str = "") -> Vocabulary:
    """DBoW2-style baseline: hierarchical k-means with branching ``k`` and depth ``L``.

    ``descriptors``: a list of per-image arrays (idf from those images) or one array (uniform idf).
    """
    per_image = isinstance(descriptors, (list, tuple))
    sets, kind, dim = _check_sets(descriptors if per_image else [descriptors])
    x = np.concatenate([as_unit_vectors(d) for d in sets])
    with blas_limit(1):  # thousands of tiny products: thread start-up costs more than it saves
        tree, leaf = build_hkmeans_tree(x, k, L, seed)
    counts = np.bincount(leaf, minlength=tree.n_words)
    image_of = np.repeat(np.arange(len(sets)), [len(d) for d in sets])
    pairs = np.unique(np.stack([leaf, image_of], axis=1), axis=0)
    images = np.bincount(pairs[:, 0], minlength=tree.n_words)
    n_images = len(sets) if per_image else 1
    meta = {"tree": "hkmeans", "features": features, "training_images": n_images, "k": k, "L": L}
    return Vocabulary(tree, training_idf(images, n_images), counts, images, n_images, kind, dim, meta)
