"""The demo world's image noise: a bank of seeded noise images added to rendered frames.

A bank of :data:`NOISE_BANK` images drawn once per log (cheap per frame, still varying from frame
to frame), shared by the demo log and every layout's renderer so that they add the same noise.
"""
from __future__ import annotations

import numpy as np

NOISE_SIGMA = 1.5  # image noise (grey levels)
NOISE_BANK = 16


def noise_bank(seed: int, shape) -> np.ndarray:
    """:data:`NOISE_BANK` noise images of ``shape`` (int16 grey levels), from ``seed``."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x401CE]))
    return np.round(rng.normal(0.0, NOISE_SIGMA, size=(NOISE_BANK, *shape))).astype(np.int16)


def add_noise(img: np.ndarray, noise: np.ndarray) -> np.ndarray:
    """``img`` (uint8) plus ``noise``, clipped to 0..255."""
    return np.clip(img.astype(np.int16) + noise, 0, 255).astype(np.uint8)
