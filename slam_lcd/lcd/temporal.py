"""Temporal consistency of loop detections (as DBoW2 does it).

Why: a single verified match can still be an aliased place; a real revisit produces a run
of detections whose matched keyframes move along with the query. A detection is accepted
only after ``k`` consecutive query keyframes were matched to keyframes within ``window``
positions of each other.
"""
from __future__ import annotations


class TemporalConsistency:
    """Counts consecutive consistent detections; ``k = 0`` accepts everything."""

    def __init__(self, k: int = 0, window: int = 3):
        self.k = int(k)
        self.window = int(window)
        self._last_query: int | None = None  # position (not id) of the last query that detected
        self._last_match: int | None = None
        self._run = 0

    def update(self, query_pos: int, match_pos: int | None) -> tuple[bool, int]:
        """Register the detection of one query (``match_pos=None``: none); returns (accept, run length)."""
        if match_pos is None:
            self._run = 0
            self._last_query = query_pos
            self._last_match = None
            return False, 0
        consecutive = self._last_query is not None and query_pos - self._last_query == 1
        near = self._last_match is not None and abs(match_pos - self._last_match) <= self.window
        self._run = self._run + 1 if (consecutive and near) else 1
        self._last_query, self._last_match = query_pos, match_pos
        return (self.k <= 0 or self._run >= self.k), self._run
