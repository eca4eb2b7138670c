"""Growing numpy arrays in place (the online vocabulary's words and the database's postings arena).

Why in place: memory touched for the first time costs page faults, and on the 2-core benchmark
machine those cost ~3-10 ms per MB. Doubling an array into a fresh copy touches
the whole new array at once: one keyframe paused for up to ~1 s. ``ndarray.resize`` reallocs,
which remaps the pages in use instead of copying them, and only zeroes the new tail, so with
small growth steps each pause stays short. Where the array cannot be resized (someone holds a
view of it) it is copied instead; the view stays valid.
"""
from __future__ import annotations

import numpy as np


def grow_in_place(owner, name: str, shape: tuple, used: int) -> None:
    """Give ``owner.<name>`` the (larger) ``shape``, keeping its first ``used`` rows; the new rows are zero."""
    try:
        getattr(owner, name).resize(shape, refcheck=True)  # (no local name: it would be another reference)
    except ValueError:
        old = getattr(owner, name)
        new = np.zeros(shape, dtype=old.dtype)
        new[:used] = old[:used]
        setattr(owner, name, new)
