"""Incremental word learning (paper §III-C): words are feature tracks between consecutive images.

The first image's descriptors found the initial words. Every next image is matched to the
previous one (mutual nearest neighbours, ratio and distance tests): a matched feature joins
the word of the feature it matched, whose centre moves (running mean of the members,
re-normalised); an unmatched feature founds a new word. The number of words therefore
follows the scene, not a k chosen in advance.
"""
from __future__ import annotations

import numpy as np

from ..features.matching import mutual_nn_match
from .descriptors import default_match_distance, group_sums, normalise_rows


class IncrementalWords:
    """Growing set of words over a sequence of images (training and online mode share it).

    ``radius``: in online mode, an unmatched feature whose nearest existing word is closer
    than this joins that word instead of founding a new one (so a revisited place reuses its
    old words); ``None`` is the paper's training rule (unmatched always founds a word).
    """

    def __init__(self, dim: int, ratio: float | None = 0.9, max_distance: float | None = None,
                 kind: str = "float", radius: float | None = None):
        self.dim = dim
        self.ratio = ratio
        self.max_distance = default_match_distance(kind) if max_distance is None else max_distance
        self.radius = radius
        self._sums = np.zeros((1024, dim), dtype=np.float64)
        self._centres = np.zeros((1024, dim), dtype=np.float32)
        self._counts = np.zeros(1024, dtype=np.int64)  # features per word
        self._images = np.zeros(1024, dtype=np.int64)  # images in which the word occurs
        self.n_words = 0
        self.n_images = 0
        self._prev_desc: np.ndarray | None = None
        self._prev_words: np.ndarray | None = None

    # ------------------------------------------------------------------ state
    @property
    def centres(self) -> np.ndarray:
        return self._centres[: self.n_words]

    @property
    def counts(self) -> np.ndarray:
        return self._counts[: self.n_words]

    @property
    def image_counts(self) -> np.ndarray:
        return self._images[: self.n_words]

    def _grow(self, need: int) -> None:
        cap = len(self._counts)
        if need <= cap:
            return
        new = max(need, 2 * cap)
        for name in ("_sums", "_centres", "_counts", "_images"):
            old = getattr(self, name)
            arr = np.zeros((new,) + old.shape[1:], dtype=old.dtype)
            arr[:cap] = old
            setattr(self, name, arr)

    # ----------------------------------------------------------------- update
    def add_image(self, desc: np.ndarray) -> np.ndarray:
        """Assign each unit-vector descriptor of the next image to a word (creating words); returns word ids."""
        desc = np.ascontiguousarray(desc, dtype=np.float32)
        n = len(desc)
        words = np.full(n, -1, dtype=np.int64)
        if n and self._prev_desc is not None and len(self._prev_desc):
            m = mutual_nn_match(desc, self._prev_desc, ratio=self.ratio, max_distance=self.max_distance)
            words[m[:, 0]] = self._prev_words[m[:, 1]]
        if self.radius is not None and self.n_words:
            free = np.flatnonzero(words < 0)
            if len(free):
                sims = desc[free] @ self.centres.T
                best = sims.argmax(axis=1)
                dist = np.sqrt(np.maximum(2.0 - 2.0 * sims[np.arange(len(free)), best], 0.0))
                near = dist < self.radius
                words[free[near]] = best[near]
        new = np.flatnonzero(words < 0)
        if len(new):
            self._grow(self.n_words + len(new))
            words[new] = np.arange(self.n_words, self.n_words + len(new))
            self.n_words += len(new)
        if n:
            touched, inv, per = np.unique(words, return_inverse=True, return_counts=True)
            self._sums[touched] += group_sums(desc, inv, len(touched))
            self._counts[touched] += per
            self._images[touched] += 1
            self._centres[touched] = normalise_rows(self._sums[touched])
        self.n_images += 1
        self._prev_desc, self._prev_words = desc, words
        return words
