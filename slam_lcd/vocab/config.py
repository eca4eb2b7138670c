"""Configuration section `vocab` (owned by :mod:`slam_lcd.vocab`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..value_range import ranged


@dataclass
class VocabConfig:
    # --- incremental word learning (paper §III-C) ---
    # Lowe ratio for matching an image to the previous one (None: mutual NN only)
    match_ratio: float | None = ranged(0.9, "(0, 1]")
    # max descriptor distance of a match on unit vectors (None: 0.8 for float descriptors,
    # 1.0 for binary ones, which is Hamming 64 of 256 bits)
    match_max_distance: float | None = ranged(None, "(0, 2]")
    # --- tree over the words ---
    # 'dp': Dirichlet-process mixture level by level up to a root; 'hkmeans': DBoW2-style k^L
    tree: Literal["dp", "hkmeans"] = "dp"
    # DP tree: dimensions kept by PCA before the mixture is fitted (0: no PCA)
    dp_pca_dims: int = ranged(24, "[0, inf)")
    # DP tree: nodes of one level are cut into spatial blocks of at most this many before fitting
    dp_block_size: int = ranged(256, "[2, inf)")
    # DP tree: truncation of the stick-breaking prior (max components per block)
    dp_truncation: int = ranged(64, "[1, inf)")
    # DP tree: concentration of the Dirichlet process (smaller: fewer parents)
    dp_concentration: float = ranged(1.0, "(0, inf)")
    # DP tree: variational EM iterations per block
    dp_max_iter: int = ranged(30, "[1, inf)")
    # DP tree: hard-EM steps per level moving each child to its nearest parent (0: pure DP grouping)
    dp_refine_iters: int = ranged(10, "[0, inf)")
    # both trees: a parent with more children than this is split by k-means (bounds descent cost)
    max_branching: int = ranged(24, "[2, inf)")
    # hkmeans baseline: branching factor k and depth L
    hk_branching: int = ranged(10, "[2, inf)")
    hk_depth: int = ranged(4, "[1, inf)")
    # seed for every random choice of training
    seed: int = ranged(0, "[0, inf)")
    # --- BoW database ---
    # idf weights: from the vocabulary's training images, or from the database so far
    idf_source: Literal["vocabulary", "database"] = "vocabulary"
    # (how many candidates a query returns and which recent keyframes it skips are the loop
    # detector's: lcd.top_k, lcd.exclude_recent_n / _s; BowDatabase.query takes them as arguments)
    # divide scores by the score against the previous keyframe (DBoW2's alpha normalisation)
    normalise_by_previous: bool = False
    # with normalise_by_previous: skip the query when the previous-keyframe score is below this
    min_previous_score: float = ranged(0.005, "[0, 1]")
    # --- online mode (no pre-trained vocabulary) ---
    # an unmatched feature closer than this to an existing word joins it instead of founding a new word
    online_word_radius: float = ranged(0.7, "(0, 2]")  # on unit vectors
    # --- online nearest-word search (docs/vocab_online.md "The nearest word at scale") ---
    # below this many words the nearest word is found exhaustively (one matrix product); from
    # here on a graph index (faiss HNSW) over projected centres proposes candidates that are
    # re-ranked exactly (a huge value keeps exhaustive search; the corridor's ~4k words stay exact)
    ann_min_words: int = ranged(5000, "[1, inf)")
    # dimensions of the projection (top eigenvectors of the centres' second moment) the graph holds
    ann_pca_dims: int = ranged(64, "[1, 4096]")
    # links per word in the graph (HNSW M)
    ann_hnsw_m: int = ranged(16, "[2, 256]")
    # beam width of a graph search (more: higher recall, slower)
    ann_ef_search: int = ranged(16, "[1, inf)")
    # beam width while a word is inserted into the graph (faiss default 40; more: better links, slower)
    ann_ef_construction: int = ranged(40, "[1, inf)")
    # words per descriptor taken from the graph and re-ranked exactly against the current centres
    ann_candidates: int = ranged(12, "[1, inf)")
    # words founded in the last this-many images are searched exhaustively (their centres still move most)
    ann_fresh_images: int = ranged(2, "[0, inf)")
    # a feature matched to the previous image is decided among its match's best words (and the
    # match's word) instead of searching the graph, for up to this many images in a row (0: always search)
    ann_hint_images: int = ranged(16, "[0, inf)")
    # ... and only when the match is closer than this (a far match says little about the feature's neighbourhood)
    ann_hint_max_distance: float = ranged(0.5, "(0, 2]")
    # ... and a feature that matches none of the previous image's features but one of the image before's
    # that the previous image missed (a landmark lost for one image) is decided the same way
    ann_hint_gap: bool = True
    # ... and a feature still to search whose best word among those of the keyframes around the previous
    # keyframe's best query result lies within online_word_radius takes it (a revisit: landmarks entering the view);
    # float descriptors (SuperPoint) only: ORB words are less distinct, the corridor's ORB run took a
    # false loop with it; a pool that decides under 20 % of the rows it scores (a new route) pauses for
    # the next three images
    ann_pool: bool = True
    # re-fit the projection and rebuild the graph when the vocabulary has grown by this factor (0: never)
    ann_rebuild_growth: float = ranged(0.0, "0 or [1, inf)")
    # how the graph stores the projected words: "sq8" (8-bit codes per dimension) or "flat" (float32)
    ann_storage: Literal["sq8", "flat"] = "sq8"
    # insert an image's settled words into the graph on a worker thread while the caller goes on
    # (its query, the next image's match); every use of the graph waits for it: the same graph and words
    ann_background_insert: bool = True
