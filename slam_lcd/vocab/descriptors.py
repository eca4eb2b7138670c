"""One descriptor space for every vocabulary: unit vectors compared by dot product.

SuperPoint descriptors are already float unit vectors. ORB descriptors are 256 bits; a bit
``b`` becomes ``(2b - 1) / 16`` so the vector has unit length and
``||u - v||^2 = hamming(a, b) / 64``: the nearest vector is the nearest in Hamming distance.
Word centres are then normalised means, and the tree descends by largest dot product, for
both kinds alike.
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError


def descriptor_kind(desc: np.ndarray) -> str:
    """'binary' for packed uint8 bit strings (ORB), 'float' otherwise."""
    return "binary" if np.asarray(desc).dtype == np.uint8 else "float"


def as_unit_vectors(desc: np.ndarray) -> np.ndarray:
    """float32 (N, D) unit rows; uint8 (N, B) bit strings become (N, 8B) ±1/sqrt(8B) rows."""
    d = np.asarray(desc)
    if d.ndim != 2:
        raise InputError(f"descriptors must be a 2-D array (N, D), got shape {d.shape}")
    if d.dtype == np.uint8:
        bits = np.unpackbits(d, axis=1).astype(np.float32)
        return (2.0 * bits - 1.0) / np.float32(np.sqrt(bits.shape[1]))
    out = d.astype(np.float32, copy=True)
    norm = np.sqrt(np.einsum("ij,ij->i", out, out))  # no (N, D) temporary, unlike np.linalg.norm
    out /= np.maximum(norm, 1e-12)[:, None]
    return out


def normalise_rows(x: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length (zero rows stay zero)."""
    x = np.asarray(x, dtype=np.float32)
    return x / np.maximum(np.linalg.norm(x, axis=1, keepdims=True), 1e-12)


def unit_distance(similarity):
    """Euclidean distance of unit vectors from their dot product, ``sqrt(2 - 2 s)`` (rounding below 0 clipped)."""
    return np.sqrt(np.maximum(2.0 - 2.0 * similarity, 0.0))


def default_match_distance(kind: str) -> float:
    """Distance bound on unit vectors: 0.8 for SuperPoint, 1.0 (= Hamming 64/256) for ORB."""
    return 1.0 if kind == "binary" else 0.8


def group_sums(x: np.ndarray, labels: np.ndarray, n_groups: int, weights: np.ndarray | None = None) -> np.ndarray:
    """Row sums per label (float64), by sorting and ``np.add.reduceat`` (much faster than ``np.add.at``)."""
    out = np.zeros((n_groups, x.shape[1]), dtype=np.float64)
    if len(labels) == 0:
        return out
    order = np.argsort(labels, kind="stable")
    lab = labels[order]
    xs = x[order].astype(np.float64)
    if weights is not None:
        xs *= np.asarray(weights, np.float64)[order, None]
    starts = np.flatnonzero(np.r_[True, lab[1:] != lab[:-1]])
    out[lab[starts]] = np.add.reduceat(xs, starts, axis=0)
    return out


# a product of rows against centres is formed in row blocks of at most this many floats (64 MB)
_PRODUCT_BLOCK_FLOATS = 16 * 1024 * 1024


def nearest_by_dot(x: np.ndarray, centres: np.ndarray, similarities: bool = False):
    """Index of the largest dot product of each row of ``x`` with ``centres`` (lowest on ties), and
    with ``similarities`` that dot product too (float32; -inf when there is no centre).

    The (rows x centres) product is formed in row blocks, so memory stays bounded whatever the
    sizes (a vocabulary trained on 600 keyframes has 170k words and 42k first-level parents: one
    product would be 26 GB; the online vocabulary reaches ~10^6 words).
    """
    n, m = len(x), len(centres)
    ids = np.zeros(n, dtype=np.int64)
    sims = np.full(n, -np.inf, dtype=np.float32)
    if n and m:
        step = max(1, _PRODUCT_BLOCK_FLOATS // m)
        for s in range(0, n, step):
            block = x[s:s + step] @ centres.T
            best = block.argmax(axis=1)
            ids[s:s + step] = best
            if similarities:
                sims[s:s + step] = block[np.arange(len(block)), best]
    return (ids, sims) if similarities else ids
