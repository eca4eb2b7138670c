"""A keyframe's bag of words (sparse word ids and term counts) and the direct tf-idf similarity.

:func:`bow_similarity` is the reference the database's inverted-index scores are checked
against (:mod:`slam_lcd.vocab.database`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class BowVector:
    """Sparse bag of words: sorted unique word ids and their term counts."""

    words: np.ndarray  # (M,) int64, sorted unique
    counts: np.ndarray  # (M,) float64

    @classmethod
    def from_word_ids(cls, ids: np.ndarray) -> BowVector:
        w, c = np.unique(np.asarray(ids, dtype=np.int64), return_counts=True)
        return cls(w, c.astype(np.float64))

    def weights(self, idf: np.ndarray) -> np.ndarray:
        """L1-normalised tf-idf weights aligned with ``words``."""
        v = self.counts * idf[self.words]
        s = v.sum()
        return v / s if s > 0 else v

    def __len__(self) -> int:
        return len(self.words)


def bow_similarity(a: BowVector, b: BowVector, idf: np.ndarray) -> float:
    """Direct ``1 - 0.5 * ||va - vb||_1`` (reference for the inverted-index scores)."""
    n = int(max(a.words.max(initial=-1), b.words.max(initial=-1))) + 1
    va, vb = np.zeros(n), np.zeros(n)
    va[a.words] = a.weights(idf)
    vb[b.words] = b.weights(idf)
    if va.sum() == 0 or vb.sum() == 0:
        return 0.0
    return float(1.0 - 0.5 * np.abs(va - vb).sum())
