"""Incremental pose graph: iSAM2 bookkeeping for keyframes and loops, on our graph or a user's.

This module keeps iSAM2 and the Python-side lists in step; the decisions live in modules
usable without a ``PoseGraph``: :mod:`.gate` (accept/reject one new loop: chi-square against the
estimate, PCM pairwise tests), :mod:`.gnc` (the batch GNC re-check; verdicts: :mod:`.gnc_verdicts`),
:mod:`.loop_factors` (robust ``BetweenFactorPose3``), :mod:`.segments` (tracking-loss segments).

Two ways to run:
- **own graph** (default): one ``Pose3`` per keyframe, key = insertion index (or ``key(kf_id)``),
  a prior on the first, odometry ``BetweenFactorPose3`` between consecutive keyframes; the
  gate's relative covariances come from the odometry chain (:class:`.gate.ChainRelatives`).
  After a tracking loss (``segment_start``) a keyframe opens a new segment with a weak prior
  instead of an odometry step; loops join segments (:mod:`.segments`).
- **a user's graph**: ``PoseGraph(isam=their_isam2, key=lambda kf_id: X(kf_id),
  add_odometry=False)``. The user adds their own values and factors (IMU, GPS, odometry ...)
  to their iSAM2; :meth:`add_keyframe` only registers a keyframe id; loops go through the
  gate with relative covariances from iSAM2's marginals (:class:`.relatives.MarginalRelatives`)
  and the GNC re-check weighs, removes and restores only the loop factors added here.

GNC re-checks: every ``gnc_every_n_loops`` gated loops, spaced by ``gnc_every_fraction`` of the loops
so far (constant cost per keyframe: docs/backend.md), and in ``finalize``.

Interrupts (Ctrl-C, or an error inside a step): the bookkeeping follows iSAM2, never runs
ahead of it; a loop that never reached iSAM2 is dropped as if it had not been offered, and a
record says 'accepted' exactly when its factor is in iSAM2.
"""
from __future__ import annotations

import logging
import time
from collections.abc import Callable

import gtsam
import numpy as np

from ..errors import InputError
from ..geometry import inv
from ..runtime.interrupts import defer_sigint
from ..types import LoopClosure
from .config import BackendConfig, gnc_due
from .g2o import G2oEdge
from .gate import ChainRelatives, GateLoop, LoopGate, default_gate
from .gnc import gnc_loop_weights
from .gnc_verdicts import gnc_changes, record_gnc_verdicts
from .graph_outputs import GraphOutputs
from .graph_segments import GraphSegments
from .loop_factors import robust_kernel, valid_information
from .poses import check_pose, isam2_params, levenberg_marquardt, values_to_array
from .records import ACCEPTED, REJECTED, LoopEntry, LoopRecord
from .relatives import MarginalRelatives
from .segments import Segments, break_covariance

__all__ = ["ACCEPTED", "REJECTED", "LoopRecord", "PoseGraph", "isam2_params", "robust_kernel", "values_to_array"]

log = logging.getLogger(__name__)


class PoseGraph(GraphOutputs, GraphSegments):
    """Keyframe pose graph kept optimised by iSAM2 (see module docstring).

    ``isam``: a user's ``gtsam.ISAM2`` to put loops into (None: our own). ``key``: keyframe
    id -> GTSAM key (None: insertion index). ``add_odometry``: add the prior and odometry
    factors and the initial values ourselves (default True without ``isam``, False with it).
    ``gate``: a :class:`~slam_lcd.backend.gate.LoopGate` (default from ``conf.outlier_rejection``).
    """

    def __init__(self, conf: BackendConfig | None = None, *, isam: gtsam.ISAM2 | None = None,
                 key: Callable[[int], int] | None = None, add_odometry: bool | None = None,
                 gate: LoopGate | None = None):
        self.conf = conf or BackendConfig()
        c = self.conf
        self.add_odometry = (isam is None) if add_odometry is None else bool(add_odometry)
        self._user_graph, self._key_fn = not self.add_odometry, key
        self.gate = gate if gate is not None else default_gate(c)
        self._kernel = robust_kernel(c.loop_kernel, c.loop_kernel_width)
        self._isam = isam if isam is not None else gtsam.ISAM2(isam2_params(c))
        self._ids: list[int] = []
        self._keys: list[int] = []  # GTSAM key per insertion position
        self._index: dict[int, int] = {}
        self._stamps: list[int] = []
        self._segments = Segments()
        self._qr = c.isam2_factorization == "qr"  # QR from the first tracking-loss segment on (_use_qr)
        self._chain = ChainRelatives(lambda k: self._isam.calculateEstimatePose3(self._keys[k]).matrix())
        self._relatives = (MarginalRelatives(lambda k: self._keys[k], isam=self._isam) if self._user_graph
                           else self._chain)
        self._base = gtsam.NonlinearFactorGraph()  # prior + odometry we added (Gaussian)
        self._base_edges: list[G2oEdge] = []
        self._loops: list[LoopEntry] = []
        self._loops_since_gnc = 0
        self._default_odom_cov = np.diag(np.r_[[c.odom_sigma_rot**2] * 3, [c.odom_sigma_trans**2] * 3])
        self._default_loop_cov = np.diag(np.r_[[c.loop_sigma_rot**2] * 3, [c.loop_sigma_trans**2] * 3])
        self.update_times: list[float] = []  # seconds per add_keyframe iSAM2 update
        self.loop_times: list[float] = []  # seconds per add_loop (gate + iSAM2)
        self.gnc_times: list[float] = []  # seconds per GNC re-check
        # the batch optimum of the written graph once finalize() ran (None: iSAM2's estimate)
        self._final_values: gtsam.Values | None = None

    # ------------------------------------------------------------------ keyframes
    def __len__(self) -> int:
        return len(self._ids)

    @property
    def keyframe_ids(self) -> list[int]:
        return list(self._ids)

    @property
    def isam(self) -> gtsam.ISAM2:
        return self._isam

    def key(self, kf_id: int) -> int:
        """GTSAM key of a keyframe that was added."""
        return self._keys[self._index[int(kf_id)]]

    def add_keyframe(self, kf_id: int, stamp_ns: int, T_world_body_odom=None, cov_since_last=None, *,
                     segment_start: bool = False) -> None:
        """Add a keyframe with its odometry pose; the step from the previous one becomes a factor.

        ``segment_start``: the odometry broke before this keyframe (tracking lost): it opens a new
        segment, anchored by a weak prior where the odometry continues, with no step from the
        previous keyframe (``cov_since_last`` is not read).

        On a user's graph (``add_odometry=False``) this only registers the id (and the pose,
        when given, for :meth:`odometry_array`); the user's iSAM2 must hold its key before a
        loop uses it.
        """
        kf_id = int(kf_id)
        if kf_id in self._index:
            raise InputError(f"keyframe id {kf_id} added twice")
        k = len(self._ids)
        key = int(self._key_fn(kf_id)) if self._key_fn is not None else k
        if self._user_graph:
            T = check_pose(T_world_body_odom, f"keyframe {kf_id}") if T_world_body_odom is not None else np.eye(4)
            with defer_sigint():
                self._register(kf_id, key, stamp_ns, T, np.zeros((6, 6)), segment_start)
            return
        if T_world_body_odom is None:
            raise InputError(f"keyframe {kf_id}: an odometry pose is needed when the pose graph adds odometry")
        T = check_pose(T_world_body_odom, f"keyframe {kf_id}")
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        c = self.conf
        self._final_values = None
        cov = None
        if k == 0:
            sig = np.r_[[c.prior_sigma_rot] * 3, [c.prior_sigma_trans] * 3]
            graph.add(gtsam.PriorFactorPose3(key, gtsam.Pose3(T), gtsam.noiseModel.Diagonal.Sigmas(sig)))
            values.insert(key, gtsam.Pose3(T))
        elif segment_start:  # where the previous segment's correction carries the odometry on, weakly
            self._use_qr()
            step = inv(self._chain.pose(k - 1)) @ T
            cov = break_covariance(c.segment_prior_sigma_rot, c.segment_prior_sigma_trans)
            at = self._isam.calculateEstimatePose3(self._keys[-1]).compose(gtsam.Pose3(step))
            graph.add(gtsam.PriorFactorPose3(key, at, gtsam.noiseModel.Gaussian.Covariance(cov)))
            values.insert(key, at)
        else:
            step = inv(self._chain.pose(k - 1)) @ T
            ok = c.use_odometry_covariance and valid_information(cov_since_last)  # SPD test fits covariances too
            cov = np.asarray(cov_since_last if ok else self._default_odom_cov, dtype=np.float64)
            graph.add(gtsam.BetweenFactorPose3(self._keys[-1], key, gtsam.Pose3(step),
                                               gtsam.noiseModel.Gaussian.Covariance(cov)))
            # Chain the new pose from the corrected estimate of the previous keyframe.
            values.insert(key, self._isam.calculateEstimatePose3(self._keys[-1]).compose(gtsam.Pose3(step)))
        prefix = self._chain.next_prefix(T, cov)
        t0 = time.perf_counter()
        with defer_sigint():  # iSAM2 and the lists change together
            self._solvable(lambda: self._isam.update(graph, values))
            self._base.push_back(graph)
            if k and cov is not None:  # (every keyframe after the first has its odometry step)
                self._base_edges.append(G2oEdge(k - 1, k, step, np.linalg.inv(cov)))
            self._register(kf_id, key, stamp_ns, T, prefix, segment_start)
        self.update_times.append(time.perf_counter() - t0)

    def _register(self, kf_id: int, key: int, stamp_ns: int, T: np.ndarray, prefix: np.ndarray,
                  segment_start: bool) -> None:
        self._segments.add(segment_start)
        self._chain.append(T, prefix)
        self._ids.append(kf_id)
        self._keys.append(key)
        self._index[kf_id] = len(self._ids) - 1
        self._stamps.append(int(stamp_ns))

    # ------------------------------------------------------------------ loops
    @property
    def loop_records(self) -> list[LoopRecord]:
        return [lp.record for lp in self._loops]

    @property
    def n_loops(self) -> int:
        """Loops offered so far (accepted or not)."""
        return len(self._loops)

    def loop_factor_indices(self) -> list[int]:
        """iSAM2 factor slots of the loops this graph holds now (everything else is not ours to touch)."""
        return [lp.isam_index for lp in self._loops if lp.isam_index is not None]

    def add_loop(self, closure: LoopClosure) -> LoopRecord:
        """Test a verified loop with the gate and, if it passes, add it to iSAM2."""
        t0 = time.perf_counter()
        self._final_values = None
        what = f"loop {closure.match_id}->{closure.query_id}"
        for kid in (closure.query_id, closure.match_id):
            if int(kid) not in self._index:
                raise InputError(f"{what}: keyframe {kid} was never added")
        a, b = self._index[int(closure.match_id)], self._index[int(closure.query_id)]
        if a == b:
            raise InputError(f"{what}: a keyframe cannot close a loop with itself")
        if self._user_graph:
            for k in (a, b):
                if not self._isam.valueExists(self._keys[k]):
                    raise InputError(f"{what}: the user's iSAM2 holds no value for keyframe {self._ids[k]}")
        Z = check_pose(closure.T_match_query, what)
        rec = LoopRecord(int(closure.query_id), int(closure.match_id), REJECTED, "pending")
        if valid_information(closure.information):
            info = np.asarray(closure.information, dtype=np.float64)
            info = 0.5 * (info + info.T)
            cov = np.linalg.inv(info)
        else:
            cov = self._default_loop_cov
            info = np.linalg.inv(cov)
            rec.history.append("information missing or not positive definite: config loop sigmas used")
        lp = LoopEntry(GateLoop(a, b, Z, cov), self._keys[a], self._keys[b],
                       gtsam.noiseModel.Gaussian.Information(info), rec)
        self._loops.append(lp)
        mode = self.conf.outlier_rejection

        group: list[LoopEntry] = []
        ok = False
        done = False
        try:
            d = self._join_check(lp) or self.gate.check(lp.gate, self._relatives, [o.gate for o in self._loops[:-1]])
            lp.gate.chi2 = d.chi2
            rec.chi2_gate, rec.chi2_threshold = d.chi2, d.threshold
            rec.pairwise_checked, rec.pairwise_inconsistent = d.pairwise_checked, d.pairwise_inconsistent
            rec.stage, rec.reason = d.stage, d.reason
            ok = d.accept
            if ok:
                lp.passed_gate = True
                by_gate = {id(g) for g in d.also_accept}
                group = [o for o in self._loops[:-1] if id(o.gate) in by_gate]
                self._isam_apply(add=[lp, *group], remove=[])
                self._commit_accept(lp, group)
            done = True
        finally:
            if not done:  # interrupted: the records follow what iSAM2 holds
                if lp.isam_index is not None:
                    self._commit_accept(lp, group)
                else:  # iSAM2 never saw it: as if it had not been offered
                    self._loops = [o for o in self._loops if o is not lp]
        if ok:
            rec.chi2_residual = self._residual_chi2(lp)
        rec.history.append(f"{rec.verdict}: {rec.reason}")
        log.debug("loop %d->%d %s: %s", rec.match_id, rec.query_id, rec.verdict, rec.reason)
        self.loop_times.append(time.perf_counter() - t0)

        if mode in ("gate+gnc", "gnc") and lp.passed_gate:
            self._loops_since_gnc += 1
            if gnc_due(self._loops_since_gnc, self.n_loops, self.conf):
                self.gnc_recheck()
        return rec

    def _commit_accept(self, lp: LoopEntry, group: list[LoopEntry]) -> None:
        """Records of a loop (and the earlier loops accepted with it) once iSAM2 holds them."""
        lp.set_verdict(ACCEPTED)
        for o in group:
            if o.record.verdict == ACCEPTED:
                continue
            o.passed_gate = True
            o.set_verdict(ACCEPTED, "pairwise",
                          f"accepted by later PCM support (loop {lp.record.match_id}->{lp.record.query_id})")
            o.record.history.append(f"{ACCEPTED}: {o.record.reason}")

    def _loop_noise(self, lp: LoopEntry):
        if self._kernel is None:
            return lp.gaussian
        return gtsam.noiseModel.Robust.Create(self._kernel, lp.gaussian)

    def _isam_apply(self, add: list[LoopEntry], remove: list[LoopEntry]) -> None:
        """Add and/or remove loop factors in iSAM2, then iterate a few times to converge."""
        graph = gtsam.NonlinearFactorGraph()
        for lp in add:
            graph.add(lp.factor(self._loop_noise(lp)))
        with defer_sigint():  # iSAM2's factor slots and ours change together
            res = self._solvable(lambda: self._isam.update(
                graph, gtsam.Values(), [lp.isam_index for lp in remove if lp.isam_index is not None]))
            for lp in remove:
                lp.isam_index = None
            for lp, idx in zip(add, res.getNewFactorsIndices(), strict=True):
                lp.isam_index = int(idx)
        for _ in range(self.conf.isam2_extra_updates_per_loop):
            self._solvable(lambda: self._isam.update())

    def _residual_chi2(self, lp: LoopEntry, values: gtsam.Values | None = None) -> float:
        if values is None:
            values = gtsam.Values()
            for k in (lp.key_match, lp.key_query):
                values.insert(k, self._isam.calculateEstimatePose3(k))
        return 2.0 * lp.factor(lp.gaussian).error(values)

    # ------------------------------------------------------------------ batch re-check
    def known_factors(self) -> gtsam.NonlinearFactorGraph:
        """Every factor that is not one of our loops: our prior + odometry, or all of the user's iSAM2 factors."""
        if not self._user_graph:
            return gtsam.NonlinearFactorGraph(self._base)
        ours = set(self.loop_factor_indices())
        fs = self._isam.getFactorsUnsafe()
        g = gtsam.NonlinearFactorGraph()
        for i in range(fs.size()):
            f = fs.at(i)
            if i not in ours and f is not None:
                g.push_back(f)
        return g

    def batch_graph(
        self, loops: str = "accepted", robust: bool = False
    ) -> tuple[gtsam.NonlinearFactorGraph, list[LoopEntry]]:
        """Known factors + loops ('accepted', 'candidates' (accepted or turned away by the pairwise test) or 'all')."""
        g, chosen = self.known_factors(), [lp for lp in self._loops if self._selected(lp, loops)]
        for lp in chosen:
            g.add(lp.factor(self._loop_noise(lp) if robust else lp.gaussian))
        return g, chosen

    @staticmethod
    def _selected(lp: LoopEntry, loops: str) -> bool:
        return (loops == "all" or (loops == "accepted" and lp.record.verdict == ACCEPTED)
                or (loops == "candidates" and (lp.passed_gate or lp.record.stage == "pairwise")))

    def gnc_recheck(self) -> list[LoopRecord]:
        """Batch GNC (TLS) over the known factors + candidate loops; sync iSAM2 with its verdicts.

        Only loop factors added by this graph are weighted, removed or restored. Returns the
        records whose verdict changed.
        """
        self._loops_since_gnc = 0
        if not self._loops:
            return []
        t0 = time.perf_counter()
        which = "candidates" if self.conf.gnc_includes_gated else "accepted"
        cands = [lp for lp in self._loops if self._selected(lp, which)]
        if not cands:
            return []
        loops = [lp.factor(lp.gaussian) for lp in cands]
        res = gnc_loop_weights(self.known_factors(), loops, self._isam.calculateEstimate(),
                               inlier_probability=self.conf.gnc_inlier_probability,
                               max_iterations=self.conf.gnc_max_iterations, qr=self._qr)
        # decide first, then change iSAM2 and the records together (an interrupt in between
        # leaves the records as iSAM2 is)
        stats, add, remove = gnc_changes(cands, res.weights, res.residual_chi2, self.conf.gnc_outlier_weight)
        changed: list[LoopRecord] = []
        try:
            if add or remove:
                self._isam_apply(add=add, remove=remove)
        finally:
            changed = record_gnc_verdicts(stats, add, remove)
        self.gnc_times.append(time.perf_counter() - t0)
        self._last_gnc_values = res.values
        return changed

    def finalize(self) -> list[LoopRecord]:
        """Final batch re-check (GNC when enabled), then the estimate at the optimum of the written graph.

        iSAM2 relinearises lazily and its loop factors carry a robust kernel, so after the last
        loop its estimate is not the minimum of the graph that ``write_g2o`` writes (prior,
        odometry and accepted loops, all Gaussian): measured on the demo, graph error 451 at
        iSAM2's values against 25.7 after Levenberg-Marquardt. With ``final_solver='lm'`` a batch
        LM solve of exactly that graph, started from iSAM2's estimate, gives the values every
        output uses. On a user's graph the estimate stays iSAM2's (the graph is theirs).
        Returns the records whose verdict changed.
        """
        changed = []
        if self.conf.outlier_rejection in ("gate+gnc", "gnc"):
            changed = self.gnc_recheck()
        for _ in range(3):
            self._isam.update()
        lm = self.conf.final_solver == "lm" and self._ids and not self._user_graph
        self._final_values = self.solve_written_graph() if lm else None
        for lp in self._loops:
            if lp.record.verdict == ACCEPTED:
                lp.record.chi2_residual = self._residual_chi2(lp, self._final_values)
        return changed

    def solve_written_graph(self) -> gtsam.Values:
        """Levenberg-Marquardt on prior + odometry + accepted loops (Gaussian), from iSAM2's estimate."""
        t0 = time.perf_counter()
        graph, _ = self.batch_graph("accepted", robust=False)
        values = levenberg_marquardt(graph, self._isam.calculateEstimate(), qr=self._qr)
        self.final_solve_seconds = time.perf_counter() - t0
        return values

    def _values(self) -> gtsam.Values:
        return self._final_values if self._final_values is not None else self._isam.calculateEstimate()
