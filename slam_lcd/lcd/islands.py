"""Candidates grouped into islands of consecutive keyframes (DBoW2, iBoW-LCD), verified island by island.

Why: a revisited place shows up in the BoW ranking as several consecutive keyframes, and
its best-scoring keyframe is not always the one that verifies (a neighbour may share more
words but overlap less, or overlap more but score a little lower). Grouping lets a place be
ranked by the evidence of all its keyframes (the island score, the sum of its members' BoW
scores) and be verified against its best member first, then its next best when that fails,
within a fixed number of members per island, so the work per query stays bounded
(at most ``top_k x island_tries`` verifications).

Islands are seeded by the top-K candidates: the ``island_pool`` best BoW candidates are
grouped by keyframe position (members at most ``island_gap`` positions apart), and only the
islands holding one of the top-K candidates are kept. So islands never add a place that the
top-K did not name; they add its temporal neighbours.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the vocabulary's candidate type, for the annotation only
    from ..types import LoopCandidate


@dataclass
class IslandMember:
    """One candidate to verify: the BoW candidate, its BoW rank, its island (0 = best island)."""

    candidate: LoopCandidate  # its match_id and bow_score
    rank: int
    island: int
    island_score: float


def group_islands(candidates: Sequence[LoopCandidate], positions: dict[int, int], top_k: int, gap: int,
                  tries: int) -> list[IslandMember]:
    """Candidates (BoW order, best first) -> the members to verify, island by island.

    ``positions`` maps a keyframe id to its position in the detector's keyframe order. Islands
    are ranked by the sum of their members' BoW scores (ties: the best member's score, then the
    earliest position, so the order is deterministic); within an island the members are taken
    by BoW score, at most ``tries`` of them.
    """
    if not candidates:
        return []
    ranked = list(enumerate(candidates))  # (BoW rank, candidate)
    ranked.sort(key=lambda rc: positions[rc[1].match_id])
    islands: list[list[tuple[int, LoopCandidate]]] = []
    last_pos = None
    for rank, cand in ranked:
        pos = positions[cand.match_id]
        if islands and last_pos is not None and pos - last_pos <= gap:
            islands[-1].append((rank, cand))
        else:
            islands.append([(rank, cand)])
        last_pos = pos
    seeded = [isl for isl in islands if any(rank < top_k for rank, _ in isl)]

    def key(isl):
        total = sum(float(c.bow_score) for _, c in isl)
        best = max(float(c.bow_score) for _, c in isl)
        first = min(positions[c.match_id] for _, c in isl)
        return (-total, -best, first)

    seeded.sort(key=key)
    out: list[IslandMember] = []
    for i, isl in enumerate(seeded[:top_k]):
        total = sum(float(c.bow_score) for _, c in isl)
        members = sorted(isl, key=lambda rc: rc[0])[:max(tries, 1)]  # BoW rank order = score order
        out.extend(IslandMember(c, rank, i, total) for rank, c in members)
    return out


def verification_order(candidates, positions: dict[int, int], conf) -> list[IslandMember]:
    """What is verified, in order: the top-K in BoW order, or island by island (``lcd.islands``).

    ``positions``: each candidate's keyframe position in the database (islands are runs of
    neighbouring positions)."""
    if not conf.islands:
        return [IslandMember(cand, rank, rank, float(cand.bow_score))
                for rank, cand in enumerate(candidates[:conf.top_k])]
    return group_islands(candidates[:conf.island_pool], positions, conf.top_k, conf.island_gap, conf.island_tries)
