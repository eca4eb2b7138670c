"""What the joint graph of a map takes and gives: sessions, loops, the verdict on each pair of sessions.

Kept apart from :mod:`.joint_graph` so that the consistency tests (:mod:`.pcm`), the join rules
(:mod:`.joins`) and the link gate (:mod:`.links`) can name these types without importing the solver.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

LINK = "link"  # the reason of a visual link between consecutive keyframes (not a loop)
FOLD = "fold"  # the reason of a folded factor: dropped keyframes' factors marginalised (slam_lcd.map.fold)

# the decision on one pair of sessions (PairDecision.decision)
JOINED = "joined"
AMBIGUOUS = "ambiguous"
TOO_FEW = "too few"
TOO_SHORT = "too short a span"
UNDONE = "undone by gnc"


@dataclass
class SessionPoses:
    """One session for the joint graph: its keyframes, odometry and its own best poses."""

    name: str
    ids: np.ndarray  # (n,) int64
    T_odom: np.ndarray  # (n, 4, 4) in the session's odometry frame
    cov: np.ndarray  # (n, 6, 6) odometry covariance since the previous keyframe (NaN: none)
    T_init: np.ndarray  # (n, 4, 4) best-known poses: map frame if already placed, else own frame
    # the component an earlier solve put it in (T_init in that component's frame); None: own frame
    prev_component: int | None = None
    # is the odometry independent of the camera that gives the visual links? True: an odometry topic
    # (wheels, an IMU, a lidar); False: the built-in visual odometry on the same images, whose steps
    # and links then count half each; None: not known (the map does not record it), counted as True
    # (see map/links.py)
    odometry_independent: bool | None = None
    # (n,) bool: the steps whose covariance the front end modelled (the per-metre allowance replaces it,
    # slam_lcd.map.pcm.step_covariances); None: every covariance as given
    cov_modelled: np.ndarray | None = None
    # (n, 4, 4) the session's own estimate: its odometry corrected by its own loops, in its odometry frame,
    # never bent by other sessions' loops (what the pairwise test and the pair's own verdict read, so that a
    # verdict depends on the two sessions alone, not on the order of appends); None: ``T_init`` is it
    T_own: np.ndarray | None = None
    # (n,) bool: the keyframes folded out of the joint graph (no variable; slam_lcd.map.fold); None: none
    folded: np.ndarray | None = None

    def own(self) -> np.ndarray:
        """(n, 4, 4) the session's own estimate (:attr:`T_own`, else :attr:`T_init`)."""
        return np.asarray(self.T_own if self.T_own is not None else self.T_init, float)

    def in_graph(self) -> np.ndarray:
        """(n,) bool: the keyframes with a variable in the joint graph (not folded)."""
        return np.ones(len(self.ids), bool) if self.folded is None else ~np.asarray(self.folded, bool)

    def graph_init(self, T: np.ndarray, A: np.ndarray | None = None) -> dict[int, np.ndarray]:
        """Initial values of the session's variables from its poses ``T`` (one per keyframe), moved by ``A``."""
        live = self.in_graph()
        return {int(k): (A @ P if A is not None else P) for k, P, ok in zip(self.ids, T, live, strict=True) if ok}


@dataclass
class JointLoop:
    """A loop between two keyframes of the map (one session or two), or a visual link (reason ``LINK``)."""

    query: int
    match: int
    T: np.ndarray  # T_match_query
    info: np.ndarray  # 6x6 GTSAM order
    inter: bool
    accepted: bool = False
    reason: str = ""


def is_link(lp: JointLoop) -> bool:
    """A visual link (accepted or not: a rejected link's reason says why after ``LINK``)."""
    return not lp.inter and lp.reason.startswith(LINK)


@dataclass
class PairDecision:
    """What the joint graph decided for one pair of sessions that loops connect, and the figures behind it."""

    sessions: tuple[str, str]
    decision: str  # JOINED, AMBIGUOUS, TOO_FEW, TOO_SHORT or UNDONE
    offered: int  # loops offered between the two sessions
    largest: int  # size of the largest pairwise-consistent set
    second: int = 0  # size of the largest consistent set disjoint from it
    span_m: tuple[float, float] = (0.0, 0.0)  # the largest set's extent in the first and second session
    exact: bool = True  # False: the clique search ran out of its budget (best found so far taken)
    kept: int = 0  # loops of the pair in the final graph
    reason: str = ""
    # the largest set's viewing directions: the angle (deg) between its most different ones in each session
    span_deg: tuple[float, float] = (0.0, 0.0)
    # "judged": at this solve; "kept": the verdict of an earlier append, taken as it was; "re-judged":
    # an earlier verdict that the joint graph contradicted, judged again with every loop as a candidate
    status: str = "judged"
    recorded: str = ""  # a kept verdict's status when it was recorded ("judged" or "re-judged")
    folded: int = 0  # loops of the pair folded out of the graph since (slam_lcd.map.fold); its verdict stands


@dataclass
class JointResult:
    poses: dict[int, np.ndarray]  # kf id -> T_map_body
    component: dict[str, int]  # session name -> component id (0: the map's first session's)
    anchors: dict[str, np.ndarray]  # session name -> T_component_sessionodom
    loops: list[JointLoop] = field(default_factory=list)
    pairs: list[PairDecision] = field(default_factory=list)  # one per pair of sessions with loops between them
    rule: str = ""  # fingerprint of the rules the pairs were judged by (slam_lcd.map.pair_verdicts.rule_key)
