"""Visual links between consecutive keyframes of a session: checked against the odometry, and how much they count.

A link is the loop chain's relative pose of two consecutive keyframes (``map.visual_links``).
A wrong one (a repeated texture, a moving object) would bend its session, and as a known
inlier of the joint graph it would make the GNC re-check drop true loops instead. So:

- **Gate.** Each link is tested against the odometry between its two keyframes: the
  innovation ``Log(Z^-1 O)`` with covariance link + odometry chain (propagated as in the loop
  gate, :class:`slam_lcd.backend.gate.ChainRelatives`; the per-metre allowance where the
  odometry gave no covariance), chi-square with 6 dof at ``map.link_probability``. A link that
  fails is dropped (``accepted=False``, the reason gives the figures). The sum of the two
  covariances is right for independent sources and lenient for correlated ones.
- **GNC.** The links that pass are candidates of the GNC re-check like the loops between
  sessions, not known inliers.
- **Double counting.** A link and the odometry step it spans are independent only when the
  odometry does not come from the same images. When the session's odometry is the built-in
  visual odometry (``SessionPoses.odometry_independent`` False), the step and its link each
  enter with half their information: covariance intersection with weight 1/2, consistent
  whatever their correlation; the session's shape between the two is the same as with full
  weights, only its stiffness against the loops halves. With an odometry topic (True) both
  count in full. The session table records the source (``odometry_source``, written by the
  runner: the odometry topic, or the built-in VO); a topic's independence is not known (None,
  it may be a visual-inertial odometry of the same images) and counts in full: an assumption.
  ``Map.factor_graph`` gives a user the same weights.
"""
from __future__ import annotations

import numpy as np

from ..backend.gate import GateLoop, chi2_quantile, innovation_chi2
from .joint_types import LINK, JointLoop, SessionPoses
from .pcm import SessionChains


def gate_links(links: list[JointLoop], chains: SessionChains, probability: float) -> int:
    """Test each link against the odometry between its keyframes; set its verdict. Returns how many failed."""
    threshold = chi2_quantile(probability, 6)
    failed = 0
    for lp in links:
        info = np.asarray(lp.info, float)
        try:
            cov = np.linalg.inv(0.5 * (info + info.T))
            T_odo, S_odo = chains.odometry(lp.match, lp.query)
            c2 = innovation_chi2(GateLoop(int(lp.match), int(lp.query), np.asarray(lp.T, float), cov), T_odo, S_odo)
        except (np.linalg.LinAlgError, ValueError, KeyError) as e:
            c2, why = float("inf"), f"not testable ({e})"
        else:
            why = f"chi2 {c2:.1f} > {threshold:.1f}"
        lp.accepted = bool(c2 <= threshold)
        lp.reason = LINK if lp.accepted else f"{LINK}: inconsistent with the odometry step ({why})"
        failed += not lp.accepted
    return failed


def shared_weight(s: SessionPoses) -> float:
    """Share of its information a link and its odometry step each keep (1: independent sources)."""
    return 0.5 if s.odometry_independent is False else 1.0


def linked_steps(links: list[JointLoop], chains: SessionChains) -> set[int]:
    """Keyframe ids ending an odometry step that an accepted link spans (consecutive keyframes only)."""
    out = set()
    for lp in links:
        if not lp.accepted:
            continue
        (sa, i), (sb, j) = chains.where[int(lp.match)], chains.where[int(lp.query)]
        if sa == sb and abs(i - j) == 1:
            out.add(int(chains.sessions[sa].ids[max(i, j)]))
    return out


def link_weight(lp: JointLoop, chains: SessionChains) -> float:
    return shared_weight(chains.sessions[chains.session_of(lp.query)])
