"""The loop outlier gate on its own: accept or reject one loop, with the reason.

Why a component of its own: a user who runs their own GTSAM graph (a VIO, a lidar odometry,
a multi-sensor iSAM2) wants our consistency checks without our graph. The gate knows
nothing about how a graph is built. It sees

- the new loop (:class:`GateLoop`: the two pose positions, ``T_match_query`` and its
  covariance) and the earlier loops with their current verdicts, all numpy;
- a :class:`Relatives` object that answers two questions about the user's poses: the current
  *estimate* of ``T_a_b`` with its covariance, and a loop-free (*odometry*) ``T_a_b`` with
  its covariance, used by the pairwise (PCM) cycles. :class:`ChainRelatives` answers from an
  odometry chain (what :class:`~slam_lcd.backend.pose_graph.PoseGraph` uses),
  :class:`~slam_lcd.backend.relatives.MarginalRelatives` from a user's ``ISAM2`` or
  ``Marginals``, and :class:`ArrayRelatives` from plain arrays.

Gates share one small protocol (``check(loop, relatives, earlier) -> GateDecision``), as
Kimera-RPGO's ``OutlierRemoval`` does; three implementations:

- :class:`AcceptAllGate`: no check (the robust kernel / GNC decide later);
- :class:`Chi2Gate`: chi-square test of the innovation against the estimate only;
- :class:`PcmGate`: the chi-square test, then PCM-style pairwise tests against earlier loops
  near it (veto by a majority of nearby accepted loops; rescue of a loop that failed the
  chi-square test by enough mutually consistent neighbours). This is the back end's gate.

Covariances and tangent vectors: GTSAM ``Pose3`` order ``[rx ry rz tx ty tz]``, right
perturbation, covariance of ``T_a_b`` expressed in frame b. Pose positions ``a``, ``b`` are
integers whose differences count keyframes (insertion positions), used for the PCM window.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.special import chdtri  # chi-square quantile without importing scipy.stats

from ..geometry import adjoint, inv, se3_log


@dataclass
class GateLoop:
    """What the gate knows of one loop: positions ``a`` (match) and ``b`` (query), ``Z = T_a_b``, its covariance."""

    a: int
    b: int
    Z: np.ndarray  # 4x4 T_match_query
    cov: np.ndarray  # 6x6, GTSAM order, frame of b
    accepted: bool = False  # its factor is in the graph now
    chi2: float | None = None  # its chi-square statistic against the estimate when it was checked
    excluded: bool = False  # no PCM partner any more (e.g. a batch re-check found it an outlier)

    @classmethod
    def from_closure(cls, closure, a: int, b: int) -> GateLoop:
        """A :class:`~slam_lcd.types.LoopClosure` at positions ``a`` (its match) and ``b`` (its query)."""
        info = np.asarray(closure.information, dtype=np.float64)
        return cls(int(a), int(b), np.asarray(closure.T_match_query, dtype=np.float64),
                   np.linalg.inv(0.5 * (info + info.T)))


@dataclass
class GateDecision:
    """A gate's verdict on one loop and the figures behind it."""

    accept: bool
    reason: str
    stage: str  # 'gate' | 'pairwise' | 'none'
    chi2: float | None = None
    threshold: float | None = None
    pairwise_checked: int = 0  # nearby accepted loops it was tested against
    pairwise_inconsistent: int = 0
    also_accept: list[GateLoop] = field(default_factory=list)  # earlier rejected loops accepted with it


class Relatives(Protocol):
    """Relative poses of a user's graph, as the gate asks for them."""

    def estimate(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """Current estimate of ``T_a_b`` (4x4) and its 6x6 covariance in frame b."""

    def odometry(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """``T_a_b`` independent of the loops (odometry chain; the estimate when there is none) and its covariance."""


class LoopGate(Protocol):
    """One loop in, a decision out; ``earlier`` are the loops offered before (with their verdicts)."""

    def check(self, loop: GateLoop, relatives: Relatives, earlier: Sequence[GateLoop] = ()) -> GateDecision: ...


def chi2_quantile(probability: float, dof: int = 6) -> float:
    """``chi2.ppf(probability, dof)``."""
    return float(chdtri(dof, 1.0 - probability))


def innovation_chi2(loop: GateLoop, T_est: np.ndarray, cov_est: np.ndarray) -> float:
    """Squared Mahalanobis norm of ``Log(Z^-1 T_est)`` with covariance ``cov_loop + cov_est``."""
    e = se3_log(inv(loop.Z) @ T_est)
    S = np.asarray(loop.cov) + np.asarray(cov_est)
    return float(e @ np.linalg.solve(S, e))


def pair_chi2(l1: GateLoop, l2: GateLoop, relatives: Relatives) -> float:
    """Cycle ``Z1^-1 * O(a1->a2) * Z2 * O(b2->b1)``: squared Mahalanobis norm with its propagated covariance."""
    A, SA = relatives.odometry(l1.a, l2.a)
    C, SC = relatives.odometry(l2.b, l1.b)
    return float(cycle_chi2(l1.Z, l1.cov, l2.Z, l2.cov, A, SA, C, SC))


def cycle_chi2(Z1, S1, Z2, S2, A, SA, C, SC) -> np.ndarray:
    """Chi-square of the cycles ``Z1^-1 A Z2 C`` (stacks broadcast over leading axes; covariances in frame b).

    Right perturbations of each factor carried into the frame of the cycle's end: ``A`` by
    ``Ad((Z2 C)^-1)``, ``Z2`` by ``Ad(C^-1)``; ``Z1`` and ``C`` end there already (to first order
    around the identity the cycle should be).
    """
    e = se3_log_stack(inv(Z1) @ A @ Z2 @ C)
    T1 = adjoint(inv(Z2 @ C))
    T2 = adjoint(inv(C))
    S = S1 + T1 @ SA @ np.swapaxes(T1, -1, -2) + T2 @ S2 @ np.swapaxes(T2, -1, -2) + SC
    return np.einsum("...i,...i->...", e, np.linalg.solve(S, e[..., None])[..., 0])


def se3_log_stack(T: np.ndarray) -> np.ndarray:
    """``Log`` of a stack of poses (..., 4, 4) -> (..., 6), ``[omega, v]``: :func:`se3_log`'s formulas, vectorised."""
    R, t = T[..., :3, :3], T[..., :3, 3]
    th = np.arccos(np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0))
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where((th < 1e-8)[..., None], 0.5 * v, (th / (2 * np.sin(th)))[..., None] * v)
        near_pi = np.pi - th < 1e-4
        if np.any(near_pi):  # the axis from the symmetric part cos^2(th/2) I + sin^2(th/2) a a^T
            B = (R + np.swapaxes(R, -1, -2)) / 4.0 + 0.5 * np.eye(3)
            d = np.sqrt(np.maximum(np.diagonal(B, axis1=-2, axis2=-1), 0.0))
            i = np.argmax(d, axis=-1)
            axis = np.take_along_axis(B, i[..., None, None], -2)[..., 0, :]
            axis = axis / np.maximum(np.take_along_axis(d, i[..., None], -1), 1e-12)
            axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
            axis = np.where((np.sum(axis * v, -1) < 0)[..., None], -axis, axis)
            w = np.where(near_pi[..., None], axis * th[..., None], w)
        a = np.linalg.norm(w, axis=-1)
        K = np.zeros(w.shape[:-1] + (3, 3))
        K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
        K = K - np.swapaxes(K, -1, -2)
        closed = (1 / a ** 2) * (1 - (a * np.sin(a)) / (2 * (1 - np.cos(a))))
        c = np.where(a < 1e-3, 1.0 / 12.0 + a ** 2 / 720.0, closed)  # series where the closed form cancels
    Vinv = np.eye(3) - 0.5 * K + c[..., None, None] * (K @ K)
    return np.concatenate([w, (Vinv @ t[..., None])[..., 0]], -1)


class AcceptAllGate:
    """Accepts every loop (outliers are left to the robust kernel and the GNC re-check)."""

    def __init__(self, reason: str = "accepted without a consistency check", stage: str = "none"):
        self.reason, self.stage = reason, stage

    def check(self, loop: GateLoop, relatives: Relatives, earlier: Sequence[GateLoop] = ()) -> GateDecision:
        return GateDecision(True, self.reason, self.stage)


class Chi2Gate:
    """Chi-square test of the loop against the current estimate (loop + relative covariance), 6 dof."""

    def __init__(self, probability: float = 0.999):
        self.threshold = chi2_quantile(probability)

    def check(self, loop: GateLoop, relatives: Relatives, earlier: Sequence[GateLoop] = ()) -> GateDecision:
        c2 = innovation_chi2(loop, *relatives.estimate(loop.a, loop.b))
        ok = c2 <= self.threshold
        reason = (f"consistent with the estimate (chi2 {c2:.1f} <= {self.threshold:.1f})" if ok
                  else f"inconsistent with the estimate: chi2 {c2:.1f} > {self.threshold:.1f}")
        return GateDecision(ok, reason, "gate", c2, self.threshold)


class PcmGate:
    """Chi-square test, then PCM-style pairwise tests against nearby earlier loops (see docs/backend.md).

    ``window``: earlier loops whose ends lie within this many positions of the new loop's
    ends are tested (0: no pairwise tests). ``min_support``: a loop failing the chi-square
    test is accepted, with its supporters, when at least this many nearby earlier loops are
    pairwise consistent with it, as long as its chi2 (and each supporter's) is at most
    ``rescue_max_factor`` x the threshold. ``max_inconsistent``: a loop passing the chi-square
    test is vetoed when it contradicts more than this fraction of the nearby accepted loops
    (and at least ``max(1, min_support)`` of them).
    """

    def __init__(self, probability: float = 0.999, window: int = 50, min_support: int = 2,
                 rescue_max_factor: float = 8.0, max_inconsistent: float = 0.5):
        self.threshold = chi2_quantile(probability)
        self.window, self.min_support = int(window), int(min_support)
        self.rescue_max_factor, self.max_inconsistent = float(rescue_max_factor), float(max_inconsistent)

    @classmethod
    def from_config(cls, conf) -> PcmGate:
        """The gate a :class:`~slam_lcd.backend.config.BackendConfig` describes."""
        return cls(conf.gate_chi2_probability, conf.gate_pairwise_window, conf.gate_min_support,
                   conf.gate_rescue_max_factor, conf.gate_pairwise_max_inconsistent)

    def check(self, loop: GateLoop, relatives: Relatives, earlier: Sequence[GateLoop] = ()) -> GateDecision:
        thr = self.threshold
        c2 = innovation_chi2(loop, *relatives.estimate(loop.a, loop.b))
        unary_ok = c2 <= thr
        rescue_max = self.rescue_max_factor * thr
        consistent: list[GateLoop] = []
        n_acc = n_acc_bad = 0
        W = self.window
        if W > 0:
            for other in earlier:
                if other is loop or other.excluded:
                    continue
                if abs(other.a - loop.a) > W or abs(other.b - loop.b) > W:
                    continue
                ok = pair_chi2(loop, other, relatives) <= thr
                if ok and (other.chi2 is None or other.chi2 <= rescue_max):
                    consistent.append(other)
                if other.accepted:
                    n_acc += 1
                    n_acc_bad += not ok
        d = GateDecision(False, "", "gate", c2, thr, n_acc, n_acc_bad)
        support = len(consistent)
        if unary_ok:
            # a veto needs a majority of the nearby accepted loops AND at least min_support of them:
            # one earlier loop (itself possibly false) must not lock out a loop that agrees with the
            # estimate; conflicts it leaves are settled by the GNC re-check
            if n_acc_bad >= max(1, self.min_support) and n_acc_bad > self.max_inconsistent * n_acc:
                d.stage = "pairwise"
                d.reason = f"inconsistent with {n_acc_bad} of {n_acc} nearby accepted loops (PCM)"
                return d
            d.accept = True
            d.reason = (f"consistent with the estimate (chi2 {c2:.1f} <= {thr:.1f})"
                        f" and with {n_acc - n_acc_bad} of {n_acc} nearby accepted loops")
            return d
        if self.min_support > 0 and support >= self.min_support and c2 <= rescue_max:
            d.accept, d.stage = True, "pairwise"
            d.reason = (f"pairwise consistent with {support} nearby loops (PCM support) although chi2 vs the"
                        f" estimate is {c2:.1f} > {thr:.1f}")
            d.also_accept = [o for o in consistent if not o.accepted]
            return d
        d.reason = (f"inconsistent with the estimate: chi2 {c2:.1f} > {thr:.1f},"
                    + (f" pairwise support {support} < {self.min_support}" if c2 <= rescue_max
                       else f" above the rescue bound {rescue_max:.1f} ({self.rescue_max_factor:g}x)"))
        return d


def default_gate(conf) -> LoopGate:
    """The gate ``outlier_rejection`` names: PCM for 'gate' / 'gate+gnc', accept-all for 'none' / 'gnc'."""
    mode = conf.outlier_rejection
    if mode in ("gate", "gate+gnc"):
        return PcmGate.from_config(conf)
    if mode == "gnc":
        return AcceptAllGate("accepted pending GNC re-check", "gnc")
    return AcceptAllGate()


class ChainRelatives:
    """Relatives from an odometry chain: O(1) chain covariances by prefix sums (an upper bound: no loops).

    With ``W_k = Ad(O_k) S_k Ad(O_k)^T`` (step k's covariance in the world frame) and prefix
    sums ``P_k``, ``Cov(O_a^-1 O_b)`` in frame b is ``Ad(O_b^-1) (P_max - P_min) Ad(O_b^-1)^T``.
    ``estimate_pose(k)`` (optional) gives the current estimate of pose k; without it the
    estimate is the odometry.
    """

    def __init__(self, estimate_pose=None):
        self._odom: list[np.ndarray] = []
        self._prefix: list[np.ndarray] = []
        self.estimate_pose = estimate_pose

    @classmethod
    def from_steps(cls, poses: np.ndarray, step_covs: np.ndarray, estimate_pose=None) -> ChainRelatives:
        """A whole chain at once: ``poses`` (n, 4, 4) and ``step_covs[i]``, the covariance of the step
        from pose i-1 to pose i in frame i (``step_covs[0]`` is not read)."""
        chain = cls(estimate_pose)
        for T, S in zip(poses, step_covs, strict=True):
            chain.append(T, chain.next_prefix(T, S))
        return chain

    def __len__(self) -> int:
        return len(self._odom)

    def next_prefix(self, T_world_body: np.ndarray, step_cov: np.ndarray | None) -> np.ndarray:
        """The prefix sum the next pose would get (``step_cov``: covariance of the step to it, frame of it)."""
        if not self._odom:
            return np.zeros((6, 6))
        A = adjoint(T_world_body)
        return self._prefix[-1] + A @ step_cov @ A.T

    def append(self, T_world_body: np.ndarray, prefix: np.ndarray) -> None:
        self._odom.append(T_world_body)
        self._prefix.append(prefix)

    def pose(self, k: int) -> np.ndarray:
        return self._odom[k]

    def chain_cov(self, a: int, b: int) -> np.ndarray:
        lo, hi = (a, b) if a <= b else (b, a)
        return chain_covariance(self._odom[b], self._prefix[lo], self._prefix[hi])

    def stacked(self) -> tuple[np.ndarray, np.ndarray]:
        """The chain's poses (N, 4, 4) and prefix sums (N, 6, 6) as arrays (for many chain covariances at once)."""
        return np.asarray(self._odom, float).reshape(-1, 4, 4), np.asarray(self._prefix, float).reshape(-1, 6, 6)

    def odometry(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        return inv(self._odom[a]) @ self._odom[b], self.chain_cov(a, b)

    def estimate(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        if self.estimate_pose is None:
            return self.odometry(a, b)
        return inv(self.estimate_pose(a)) @ self.estimate_pose(b), self.chain_cov(a, b)


def chain_covariance(T_world_b: np.ndarray, prefix_lo: np.ndarray, prefix_hi: np.ndarray) -> np.ndarray:
    """Covariance (frame b) of the chain between two poses from its prefix sums: ``Ad(O_b^-1) (P_hi - P_lo) Ad^T``.

    Stacks broadcast over leading axes.
    """
    Ai = adjoint(inv(T_world_b))
    return Ai @ (prefix_hi - prefix_lo) @ np.swapaxes(Ai, -1, -2)


class ArrayRelatives:
    """Relatives from arrays: poses ``(N, 4, 4)`` and per-pose marginal covariances ``(N, 6, 6)``.

    The relative covariance ignores the correlation of the two poses: for poses estimated in
    one graph the correlation is positive, so this over-states the relative uncertainty (a
    lenient gate). Odometry = estimate.
    """

    def __init__(self, poses: np.ndarray, covariances: np.ndarray):
        self.poses, self.covariances = np.asarray(poses, float), np.asarray(covariances, float)

    def estimate(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        return relative_from_marginals(self.poses[a], self.poses[b], self.covariances[a], self.covariances[b])

    odometry = estimate


def relative_from_marginals(Xa, Xb, Sa, Sb, Sab=None) -> tuple[np.ndarray, np.ndarray]:
    """``T_a_b = Xa^-1 Xb`` and its covariance (frame b) from the poses' marginal (and cross) covariances.

    Right perturbations ``Xa Exp(da)``, ``Xb Exp(db)``: ``d(T_a_b) = -Ad(T_a_b^-1) da + db``.
    ``Sab`` = Cov(da, db); None treats the poses as uncorrelated.
    """
    T = inv(Xa) @ Xb
    A = -adjoint(inv(T))
    S = A @ Sa @ A.T + Sb
    if Sab is not None:
        C = A @ Sab
        S = S + C + C.T
    return T, 0.5 * (S + S.T)
