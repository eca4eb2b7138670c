"""What the pose graph keeps of each loop: its explained record and its bookkeeping entry."""
from __future__ import annotations

from dataclasses import dataclass, field

import gtsam
import numpy as np

from .gate import GateLoop

ACCEPTED = "accepted"
REJECTED = "rejected"


@dataclass
class LoopRecord:
    """What happened to one loop closure, and why."""

    query_id: int
    match_id: int
    verdict: str  # 'accepted' | 'rejected'
    reason: str
    chi2_gate: float | None = None  # gate test: innovation vs the current estimate (6 dof)
    chi2_threshold: float | None = None
    pairwise_checked: int = 0  # earlier loops it was tested against (PCM)
    pairwise_inconsistent: int = 0
    chi2_residual: float | None = None  # whitened squared residual at the current estimate
    gnc_weight: float | None = None  # last GNC weight (1 inlier, 0 outlier)
    stage: str = "gate"  # which check gave the verdict: 'gate' | 'pairwise' | 'gnc' | 'none'
    history: list[str] = field(default_factory=list)


@dataclass
class LoopEntry:
    """One offered loop: the gate's view (positions, pose, covariance, verdict), its GTSAM keys and factor slot."""

    gate: GateLoop
    key_match: int
    key_query: int
    gaussian: gtsam.noiseModel.Base
    record: LoopRecord
    passed_gate: bool = False  # passed the consistency gate at some point (GNC candidate)
    isam_index: int | None = None  # factor slot in iSAM2 while the loop is in it

    @property
    def a(self) -> int:
        return self.gate.a

    @property
    def b(self) -> int:
        return self.gate.b

    @property
    def Z(self) -> np.ndarray:
        return self.gate.Z

    @property
    def cov(self) -> np.ndarray:
        return self.gate.cov

    def factor(self, noise) -> gtsam.BetweenFactorPose3:
        return gtsam.BetweenFactorPose3(self.key_match, self.key_query, gtsam.Pose3(self.Z), noise)

    def set_verdict(self, verdict: str, stage: str | None = None, reason: str | None = None) -> None:
        """Record and gate view change together (the gate's PCM partners follow the verdicts)."""
        r = self.record
        r.verdict = verdict
        if stage is not None:
            r.stage = stage
        if reason is not None:
            r.reason = reason
        self.gate.accepted = verdict == ACCEPTED
        self.gate.excluded = verdict == REJECTED and r.stage == "gnc"
