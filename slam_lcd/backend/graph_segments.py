"""The tracking-loss segments of a :class:`~slam_lcd.backend.pose_graph.PoseGraph` (see :mod:`.segments`).

A mixin, as :class:`~.graph_outputs.GraphOutputs` is: it reads the graph's lists and iSAM2.
"""
from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

import gtsam

from ..runtime.interrupts import defer_sigint
from .gate import LoopGate, Relatives, chi2_quantile
from .poses import isam2_params
from .records import ACCEPTED
from .segments import SegmentRow, Segments, judge_join

if TYPE_CHECKING:
    from .config import BackendConfig
    from .gate import ChainRelatives, GateDecision
    from .records import LoopEntry

log = logging.getLogger(__name__)
T = TypeVar("T")


class GraphSegments:
    # set by PoseGraph (annotations only: no class attribute is created)
    conf: BackendConfig
    gate: LoopGate
    _isam: gtsam.ISAM2
    _qr: bool
    _user_graph: bool
    _base: gtsam.NonlinearFactorGraph
    _loops: list[LoopEntry]
    _segments: Segments
    _relatives: Relatives
    _ids: list[int]
    _keys: list[int]
    _stamps: list[int]
    _chain: ChainRelatives

    def _loop_noise(self, lp: LoopEntry):  # PoseGraph's
        raise NotImplementedError

    def _use_qr(self) -> None:
        """From the first segment on, iSAM2 (and the batch solves) factorise by QR: a weak segment prior beside
        precise odometry makes a system that Cholesky, squaring its condition number, declares indeterminate."""
        if self._qr:
            return
        isam = gtsam.ISAM2(isam2_params(self.conf, qr=True))
        held = [lp for lp in self._loops if lp.isam_index is not None]
        graph = gtsam.NonlinearFactorGraph(self._base)
        for lp in held:
            graph.add(lp.factor(self._loop_noise(lp)))
        values = gtsam.Values()
        for k, key in enumerate(self._keys):  # the keyframes registered (not one an update failed on)
            try:
                values.insert(key, self._isam.calculateEstimatePose3(key))
            except RuntimeError:  # an update that failed left no estimate: the odometry chain's pose
                values.insert(key, gtsam.Pose3(self._chain.pose(k)))
        with defer_sigint():
            res = isam.update(graph, values)
            slots = list(res.getNewFactorsIndices())[self._base.size():]
            for lp, idx in zip(held, slots, strict=True):
                lp.isam_index = int(idx)
            self._isam, self._qr = isam, True

    def _solvable(self, update: Callable[[], T]) -> T:
        """Run an iSAM2 ``update``; where Cholesky declares the system indeterminate (covariances whose scales lie
        orders of magnitude apart, e.g. absolute covariances read as relative ones), refactor by QR and run it
        again (said once)."""
        try:
            return update()
        except RuntimeError as e:
            if self._qr or "ndetermina" not in str(e):
                raise
        log.warning("the pose graph is too poorly conditioned for Cholesky factorisation (odometry covariances "
                    "of very different scales): it is solved by QR from here on")
        self._use_qr()
        return update()

    def _join_check(self, lp: LoopEntry):
        """The verdict on a loop between two components no accepted loop connects yet (None: not such a loop)."""
        if self._user_graph:
            return None
        threshold = getattr(self.gate, "threshold", None) or chi2_quantile(self.conf.gate_chi2_probability)
        return join_check(self._segments, self._loops, lp, self._relatives, threshold,
                          self.conf.segment_join_min_loops)

    def segment_rows(self) -> list[SegmentRow]:
        """One row per tracking-loss segment: keyframes, stamps, component, joining loops (:mod:`.segments`)."""
        return self._segments.rows(self._ids, self._stamps, accepted_pairs(self._loops)) if self._ids else []


def accepted_pairs(loops: list[LoopEntry]) -> list[tuple[int, int]]:
    """``(position_a, position_b)`` of the accepted loops: what joins segments."""
    return [(lp.a, lp.b) for lp in loops if lp.record.verdict == ACCEPTED]


def join_check(segments: Segments, loops: list[LoopEntry], new: LoopEntry, relatives: Relatives,
               threshold: float, min_loops: int) -> GateDecision | None:
    """:func:`judge_join` for ``new`` (the last of ``loops``) when it lies between two components; else None."""
    if len(segments) < 2:
        return None
    of = segments.of
    comp = segments.components(accepted_pairs(loops))
    ca, cb = comp[of[new.a]], comp[of[new.b]]
    if ca == cb:
        return None

    def side(p: int) -> int | None:
        return {ca: 0, cb: 1}.get(comp[of[p]])

    waiting = [o.gate for o in loops if o is not new and o.record.verdict != ACCEPTED and not o.gate.excluded
               and {side(o.a), side(o.b)} == {0, 1}]
    return judge_join(new.gate, side, waiting, relatives, threshold, min_loops, (of[new.a], of[new.b]))
