"""The online database as plain arrays for a map, and back.

:func:`snapshot` turns an online :class:`~slam_lcd.vocab.database.BowDatabase` into arrays (no
pickle): its words and every keyframe's bag of words; :func:`restore_words`,
:func:`restore_bows` and :func:`restore_into` read them back. The dependency runs one way: this
module reads and fills a database, the database never imports it.
"""
from __future__ import annotations

from itertools import pairwise

import numpy as np

from ..errors import InputError
from .bow import BowVector
from .config import VocabConfig
from .database import BowDatabase
from .word_index import WordIndex
from .words import IncrementalWords


def snapshot(db: BowDatabase, centres: str = "int8") -> dict[str, np.ndarray] | None:
    """The online database's state as plain arrays (no pickle): words and every keyframe's bag of words.

    ``centres``: ``int8`` (one scale per word: 260 B a word) or ``float16`` (512 B). The word
    index's graph (faiss) is kept as its serialised bytes, so a restored database searches the same
    graph instead of re-inserting every word. None for a database over a trained vocabulary (its
    bags of words are recomputed cheaply by the tree) or an empty one.
    """
    if not db.online or db.words is None or not len(db):
        return None
    w = db.words
    c = w.centres
    if centres == "int8":
        peak = np.abs(c).max(axis=1) if len(c) else np.zeros(0, np.float32)
        scale = np.where(peak > 0, 127.0 / np.maximum(peak, 1e-12), 1.0).astype(np.float32)
        q = np.clip(np.rint(c * scale[:, None]), -127, 127).astype(np.int8)
        f16 = np.zeros((0, c.shape[1]), np.float16)
    elif centres == "float16":
        q, scale, f16 = np.zeros((0, c.shape[1]), np.int8), np.zeros(0, np.float32), c.astype(np.float16)
    else:
        raise InputError(f"vocabulary snapshot: centres {centres!r} is not int8 or float16")
    lens = np.array([len(b) for b in db._bow_words], np.int64)
    idx = w.index
    graph = np.zeros(0, np.uint8)
    proj: np.ndarray = np.zeros((0, 0), np.float32)
    state = np.zeros(3, np.int64)
    ends = np.zeros(0, np.int64)
    if idx is not None and idx.active:
        import faiss

        graph = faiss.serialize_index(idx.graph)
        assert idx.proj is not None  # an active index has its projection (WordIndex._build)
        proj = idx.proj
        state = np.array([idx.n_indexed, idx.built_at, idx.n_builds], np.int64)
        ends = np.array(list(idx._image_ends), np.int64)
    counts = np.concatenate(db._bow_counts) if lens.sum() else np.zeros(0)
    return {"kf_ids": np.array(db.kf_ids, np.int64), "desc_kind": np.array(db._desc_kind or "float"),
            "dim": np.array(w.dim, np.int64), "n_images": np.array(w.n_images, np.int64),
            "centres_q": q, "centres_scale": scale, "centres_f16": f16,
            "lengths": w._lengths[: w.n_words].astype(np.float32), "counts": w.counts.astype(np.int32),
            "images": w.image_counts.astype(np.int32),
            "bow_offsets": np.concatenate([[0], np.cumsum(lens)]).astype(np.int64),
            "bow_words": (np.concatenate(db._bow_words) if lens.sum() else np.zeros(0)).astype(np.int32),
            "bow_counts": (counts.astype(np.uint16) if counts.size and counts.max() <= 65535
                           else counts.astype(np.float64)),
            "proj": proj, "graph": graph, "index_state": state, "image_ends": ends}


def restore_words(state: dict[str, np.ndarray], conf: VocabConfig | None = None) -> tuple[IncrementalWords, str]:
    """(the online words, descriptor kind) of a :func:`snapshot`; raises ``ValueError`` on arrays that do not fit."""
    conf = conf or VocabConfig()
    dim, kind = int(state["dim"]), str(state["desc_kind"])
    q, f16 = state["centres_q"], state["centres_f16"]
    n = len(q) if len(q) else len(f16)
    if not (q.shape in ((n, dim), (0, dim)) and f16.shape in ((n, dim), (0, dim)) and len(state["lengths"]) == n
            and len(state["counts"]) == n and len(state["images"]) == n):
        raise ValueError("the word arrays do not fit together")
    w = IncrementalWords(dim, conf.match_ratio, conf.match_max_distance, kind, radius=conf.online_word_radius,
                         index=WordIndex.from_config(dim, conf))
    w._grow(n)
    for a in range(0, n, 65536):  # straight into the words' array, a block at a time (no full-size temporaries)
        b = min(n, a + 65536)
        if len(q):
            np.divide(q[a:b], state["centres_scale"][a:b, None], out=w._centres[a:b], casting="unsafe")
        else:
            w._centres[a:b] = f16[a:b]
    w._lengths[:n] = state["lengths"]
    w._counts[:n] = state["counts"]
    w._images[:n] = state["images"]
    w.n_words, w.n_images = n, int(state["n_images"])
    w.version += 1
    if len(state["graph"]):
        import faiss

        idx = w.index
        assert idx is not None  # the words were made with WordIndex.from_config above
        idx.proj = np.ascontiguousarray(state["proj"], np.float32)
        idx.graph = faiss.deserialize_index(np.ascontiguousarray(state["graph"], np.uint8))
        idx.n_indexed, idx.built_at, idx.n_builds = (int(v) for v in state["index_state"])
        if idx.graph.ntotal != idx.n_indexed or idx.proj.shape != (dim, idx.pca_dims) or idx.n_indexed > n:
            raise ValueError("the word index does not fit the words (another vocab configuration?)")
        idx._image_ends.extend(int(v) for v in state["image_ends"])
    return w, kind


def restore_bows(state: dict[str, np.ndarray]) -> list[BowVector]:
    """Every keyframe's bag of words of a :func:`snapshot`, in the snapshot's keyframe order."""
    off, words, counts = state["bow_offsets"], state["bow_words"], state["bow_counts"]
    if off.shape != (len(state["kf_ids"]) + 1,) or int(off[-1]) != len(words) or len(counts) != len(words):
        raise ValueError("the bags of words do not fit together")
    return [BowVector(words[a:b].astype(np.int64), counts[a:b].astype(np.float64))
            for a, b in pairwise(off.tolist())]


def restore_into(db: BowDatabase, state: dict[str, np.ndarray]) -> list[BowVector]:
    """Give an empty online ``db`` the snapshot's words; returns the bags of words to insert with
    :meth:`BowDatabase.add_bow` (in the snapshot's order, sessions marked by the caller)."""
    if not db.online or len(db) or db.words is not None:
        raise InputError("a vocabulary snapshot restores into an empty online database only")
    words, _ = restore_words(state, db.conf)
    bows = restore_bows(state)
    db.words = words  # the descriptor kind and size are taken from the next descriptors (_check)
    return bows


def keep_only(state: dict[str, np.ndarray], kf_ids: np.ndarray) -> dict[str, np.ndarray]:
    """The snapshot for the keyframes ``kf_ids`` only (a map that dropped the others' descriptors).

    Their bags of words are kept as they are; the words no kept bag of words uses are dropped and
    the others renumbered, each word's image count recomputed; the word index (a faiss graph over
    every word) is left out, to be rebuilt by the database when its words call for one. Why prune
    rather than keep: the online vocabulary grows with every keyframe a run inserts (about 78 words
    a keyframe on the demo), and a map that keeps places must not keep the words of the views it
    dropped.
    """
    ids = state["kf_ids"]
    keep = np.isin(ids, np.asarray(kf_ids, np.int64))
    off = state["bow_offsets"]
    spans = [(int(a), int(b)) for a, b, k in zip(off[:-1], off[1:], keep, strict=True) if k]
    rows = np.concatenate([np.arange(a, b) for a, b in spans]) if spans else np.zeros(0, np.int64)
    words = state["bow_words"][rows]
    used = np.unique(words)
    renumber = np.full(len(state["lengths"]), -1, np.int64)
    renumber[used] = np.arange(len(used))
    new_words = renumber[words].astype(np.int32)
    q, scale, f16 = state["centres_q"], state["centres_scale"], state["centres_f16"]
    return dict(state, kf_ids=ids[keep], n_images=np.array(int(keep.sum()), np.int64),
                centres_q=q[used] if len(q) else q, centres_scale=scale[used] if len(scale) else scale,
                centres_f16=f16[used] if len(f16) else f16, lengths=state["lengths"][used],
                counts=state["counts"][used],
                images=np.bincount(new_words, minlength=len(used)).astype(np.int32),
                bow_offsets=np.concatenate([[0], np.cumsum([b - a for a, b in spans])]).astype(np.int64),
                bow_words=new_words, bow_counts=state["bow_counts"][rows],
                proj=np.zeros((0, 0), np.float32), graph=np.zeros(0, np.uint8),
                index_state=np.zeros(3, np.int64), image_ends=np.zeros(0, np.int64))
