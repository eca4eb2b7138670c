"""Odometry breaks (tracking lost) as the pipeline sees them: which frame opens a segment, which lie inside one.

Why a module: the built-in VO hands all its odometry in before the first frame, so several breaks
can wait for their frames at once, and a frame between the last pose before a break and the
break itself has no odometry pose at all (interpolating across the break would make one up, and a
keyframe on it would tie the two segments together).
"""
from __future__ import annotations

import bisect
from collections import deque
from collections.abc import Sequence


class OdometryBreaks:
    def __init__(self) -> None:
        self.stamps: list[int] = []  # every break handed in, in order
        self._waiting: deque[int] = deque()  # breaks not yet handed to a frame, oldest first

    def add(self, stamp_ns: int) -> None:
        self.stamps.append(int(stamp_ns))
        self._waiting.append(int(stamp_ns))

    def opens_segment(self, stamp_ns: int) -> bool:
        """A frame at ``stamp_ns`` is the first after one or more waiting breaks (they make one segment)."""
        brk = bool(self._waiting) and stamp_ns >= self._waiting[0]
        while self._waiting and stamp_ns >= self._waiting[0]:
            self._waiting.popleft()
        return brk

    def inside(self, stamp_ns: int, odom_stamps: Sequence[int]) -> bool:
        """``stamp_ns`` lies after the last odometry pose before a break and before the break's own pose."""
        i = bisect.bisect_left(self.stamps, stamp_ns)
        if i == len(self.stamps) or self.stamps[i] == stamp_ns:
            return False
        j = bisect.bisect_left(odom_stamps, self.stamps[i])  # the break's own sample
        return j > 0 and odom_stamps[j - 1] < stamp_ns
