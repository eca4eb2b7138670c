"""Tracking-loss segments of one pose graph, and the loops that join them.

Why: visual odometry loses tracking (a dark corridor, a person in front of the lens, a fast
turn, dropped frames). The odometry after a loss is not connected to the odometry before it:
chaining the two with a made-up large-noise step gives iSAM2 an information matrix whose
scales differ by ten orders of magnitude, and its Cholesky factorisation stops with an
``IndeterminateSystemException``. Instead each segment is a graph of its own, as
ORB-SLAM3's Atlas keeps a new map and RTAB-Map a new session after a loss:

- the first keyframe of the run has the usual tight prior (the gauge);
- the first keyframe of every later segment has a *weak* prior (``segment_prior_sigma_*``)
  at the pose the odometry continues from. It fixes the segment's gauge, so no keyframe is
  ever without a constraint, and it is weak enough that loops decide where a joined
  segment lies (a loop's information is 10^4 to 10^6 times larger);
- a loop between two segments that no accepted loop connects yet *joins* them only with at
  least ``segment_join_min_loops`` mutually consistent loops (pairwise cycle test along each
  segment's own odometry, as PCM does between the sessions of a map): there is no estimate
  of where one segment lies relative to the other to test a single loop against;
- a segment that no loop joins stays on its own, and every output says so.

Positions are insertion indices of the pose graph; components are named by their lowest
segment index.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ..geometry import adjoint, inv
from .gate import GateDecision, GateLoop, Relatives, pair_chi2


@dataclass
class SegmentRow:
    """One segment as the report lists it."""

    segment: int
    component: int
    keyframes: int
    first_keyframe: int  # keyframe ids
    last_keyframe: int
    first_stamp_ns: int
    last_stamp_ns: int
    joining_loops: int  # accepted loops between this segment and another one

    def as_dict(self) -> dict:
        return dict(vars(self))


class Segments:
    """Which segment each pose graph position belongs to, and the components accepted loops make."""

    def __init__(self) -> None:
        self.of: list[int] = []  # segment index per position
        self.first: list[int] = []  # first position of each segment

    def __len__(self) -> int:
        return len(self.first)

    def add(self, start: bool) -> int:
        """Register the next position; ``start`` opens a new segment (the first position always does)."""
        if start or not self.first:
            self.first.append(len(self.of))
        seg = len(self.first) - 1
        self.of.append(seg)
        return seg

    def components(self, joins: Iterable[tuple[int, int]]) -> list[int]:
        """Component label per segment (its lowest segment index) from loops ``(position_a, position_b)``."""
        parent = list(range(len(self.first)))

        def root(i: int) -> int:
            while parent[i] != i:
                parent[i] = parent[parent[i]]
                i = parent[i]
            return i

        for a, b in joins:
            ra, rb = root(self.of[a]), root(self.of[b])
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
        return [root(i) for i in range(len(self.first))]

    def rows(self, ids: Sequence[int], stamps: Sequence[int], joins: Sequence[tuple[int, int]]) -> list[SegmentRow]:
        """The report's table: one row per segment (``ids``/``stamps`` per position, ``joins`` accepted loops)."""
        comp = self.components(joins)
        joining = [0] * len(self.first)
        for a, b in joins:
            sa, sb = self.of[a], self.of[b]
            if sa != sb:
                joining[sa] += 1
                joining[sb] += 1
        out = []
        for s, p0 in enumerate(self.first):
            p1 = (self.first[s + 1] if s + 1 < len(self.first) else len(self.of)) - 1
            out.append(SegmentRow(s, comp[s], p1 - p0 + 1, int(ids[p0]), int(ids[p1]), int(stamps[p0]),
                                  int(stamps[p1]), joining[s]))
        return out


def flipped(loop: GateLoop) -> GateLoop:
    """The same loop seen from its other end: ``T_b_a = Z^-1`` with its covariance in frame a."""
    A = adjoint(loop.Z)
    return GateLoop(loop.b, loop.a, inv(loop.Z), A @ loop.cov @ A.T, loop.accepted, loop.chi2, loop.excluded)


def judge_join(loop: GateLoop, side_of, waiting: Sequence[GateLoop], relatives: Relatives, threshold: float,
               min_loops: int, names: tuple[int, int]) -> GateDecision:
    """Verdict on a loop between two components no accepted loop connects yet.

    ``side_of(position)`` is 0 on the loop's match side, 1 on its query side (None elsewhere);
    ``waiting``: earlier loops between the same two components that are not accepted. The loop
    is accepted, with the waiting loops it is consistent with, when they make a group of at
    least ``min_loops`` loops that are pairwise consistent (the cycle of two loops and the
    odometry within each side, chi-square at ``threshold``); otherwise it waits, rejected.
    """
    oriented = [w if side_of(w.a) == 0 else flipped(w) for w in waiting]
    scored = sorted(((pair_chi2(loop, w, relatives), i) for i, w in enumerate(oriented)), key=lambda t: t[0])
    group: list[int] = []
    for c2, i in scored:  # greedy: the most consistent first, each consistent with every one kept
        if c2 > threshold:
            break
        if all(pair_chi2(oriented[j], oriented[i], relatives) <= threshold for j in group):
            group.append(i)
    n = len(group) + 1
    what = f"segments {names[0]} and {names[1]}"
    if n >= min_loops:
        return GateDecision(True, f"joins {what}: {n} mutually consistent loops between them (>= {min_loops})",
                            "join", also_accept=[waiting[i] for i in group])
    return GateDecision(False, f"would join {what}: {n} mutually consistent loop(s) between them, "
                               f"{min_loops} needed (waits for more)", "join")


def break_covariance(sigma_rot: float, sigma_trans: float) -> np.ndarray:
    """Covariance standing for the unknown motion across a break (GTSAM order), as the weak prior's."""
    return np.diag([sigma_rot**2] * 3 + [sigma_trans**2] * 3)
