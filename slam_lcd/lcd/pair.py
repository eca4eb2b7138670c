"""The checks of one candidate pair (matching, budget, graph, RANSAC) whatever side is the query.

Why: a verdict that changes when query and match swap roles is decided by the role, not by
the images (ORB pairs flipped between accepted and ``low_node_ratio`` with the one-sided
ratio test). The matching rule is symmetric (mutual nearest neighbours, a ratio taken in both
images, :func:`slam_lcd.features.matching.mutual_nn_match_symmetric`); on top of that the
pair is checked in one canonical orientation, chosen from the two keyframes' data alone, so
floating-point rounding of the descriptor distances, the budget's grid (laid over the first
image) and RANSAC's sampling see the same input either way. The results are handed back in
the caller's (query, match) orientation.

The graph chains take the one-to-one matches without a ratio test (``lcd.graph_match_ratio``,
default off: the paper keeps every one-to-one match and lets the graph reject the rest); the
RANSAC-only chain keeps its ratio (``lcd.match_ratio``). RANSAC of the graph+RANSAC chain runs
on the graph's survivors.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..types import CameraModel, Features
from .budget import select_matches
from .config import LcdConfig
from .geometry import EpipolarVerdict, verify_epipolar
from .graph import GraphVerdict, verify_graph


@dataclass
class PairChecks:
    """What the checks of one pair found, rows ``[query index, match index]``."""

    n_matches: int  # one-to-one matches of the main chain (graph when it ran, else RANSAC)
    n_verified: int  # of those, handed to verification (the budget)
    graph_matches: np.ndarray  # (G, 2) what the graph saw
    ransac_matches: np.ndarray  # (R, 2) what RANSAC-only saw
    graph: GraphVerdict | None = None
    ransac: EpipolarVerdict | None = None
    ransac_on_graph: EpipolarVerdict | None = None


def _fingerprint(feats: Features, desc: np.ndarray) -> tuple:
    kp = np.asarray(feats.keypoints, dtype=np.float64)
    return (len(kp), float(kp.sum()) if len(kp) else 0.0,
            float(np.abs(kp[:, 0] - 0.5 * kp[:, 1]).sum()) if len(kp) else 0.0,
            bytes(np.ascontiguousarray(desc[:4]).tobytes()))


def canonical_flip(fa: Features, da: np.ndarray, fb: Features, db: np.ndarray) -> bool:
    """True when the pair is checked as (b, a): an order of the two keyframes' own data (never of their roles)."""
    return _fingerprint(fa, da) > _fingerprint(fb, db)


def _ratio_mask(ratios: np.ndarray | None, n: int, ratio: float | None) -> np.ndarray:
    if ratio is None:
        return np.ones(n, bool)
    assert ratios is not None  # the matcher gives ratios whenever a ratio test is on (LoopDetector._match)
    return ratios < ratio


def _budget(matches, distances, feats_first: Features, conf: LcdConfig) -> np.ndarray:
    if 0 < conf.verify_max_matches < len(matches):
        keep = select_matches(matches, distances, feats_first.keypoints, conf.verify_max_matches,
                              feats_first.image_size, conf.verify_spread_cells)
        return matches[keep]
    return matches


def check_pair(fq: Features, fm: Features, dq: np.ndarray, dm: np.ndarray, cam_q: CameraModel, cam_m: CameraModel,
               conf: LcdConfig, *, graph: bool, ransac: bool, graph_ransac: bool, match, clock=None) -> PairChecks:
    """Match and verify (query, match) in the canonical orientation; results in the caller's orientation.

    ``match(d1, d2) -> (matches, distances, ratios or None)`` is the symmetric matcher; ``graph``,
    ``ransac``, ``graph_ransac``: which checks run (RANSAC on the graph's survivors only when
    the graph accepted).
    """
    flip = canonical_flip(fq, dq, fm, dm)
    f1, f2, d1, d2, c1, c2 = (fm, fq, dm, dq, cam_m, cam_q) if flip else (fq, fm, dq, dm, cam_q, cam_m)
    matches, distances, ratios = match(d1, d2)
    order = np.argsort(matches[:, 0], kind="stable")  # rows by the first image's index, as the matcher gives them
    matches, distances = matches[order], distances[order]
    ratios = ratios[order] if ratios is not None else None
    g_keep = _ratio_mask(ratios, len(matches), conf.graph_match_ratio)
    r_keep = _ratio_mask(ratios, len(matches), conf.match_ratio)
    g_all, r_all = matches[g_keep], matches[r_keep]
    g_matches = _budget(g_all, distances[g_keep], f1, conf)
    same = conf.graph_match_ratio == conf.match_ratio  # one set for both chains (the default: no ratio test)
    r_matches = g_matches if same else _budget(r_all, distances[r_keep], f1, conf)
    if clock is not None:
        clock.lap("matching")
    k1, k2 = f1.keypoints, f2.keypoints
    out_graph = out_ransac = out_rg = None
    if graph:
        out_graph = verify_graph(k1, k2, g_matches, conf)
        if clock is not None:
            clock.lap("graph")
        if graph_ransac:
            kept = g_matches[out_graph.kept] if out_graph.accepted else g_matches[:0]
            out_rg = verify_epipolar(k1, k2, kept, c1, c2, conf)
    if ransac:
        out_ransac = verify_epipolar(k1, k2, r_matches, c1, c2, conf)
    if clock is not None:
        clock.lap("ransac")
    if flip:  # back to (query, match) columns; row order (and so every mask and ``kept``) stays
        g_matches = g_matches[:, ::-1].copy()
        r_matches = g_matches if same else r_matches[:, ::-1].copy()
        for v in (out_ransac, out_rg):
            if v is not None and v.R_query_match is not None:
                v.R_query_match = v.R_query_match.T
    main_all, main = (g_all, g_matches) if graph else (r_all, r_matches)
    return PairChecks(n_matches=len(main_all), n_verified=len(main), graph_matches=g_matches, ransac_matches=r_matches,
                      graph=out_graph, ransac=out_ransac, ransac_on_graph=out_rg)
