"""Pairwise consistency (PCM, Mangelson et al. 2018) of loops between two sessions, with propagated covariances.

Two loops ``l1: a1 -> b1`` and ``l2: a2 -> b2`` between sessions S (the ``a`` ends) and T (the
``b`` ends) are consistent when the cycle ``Z1^-1 * T_S(a1->a2) * Z2 * T_T(b2->b1)`` is the
identity within a chi-square bound (6 dof, ``map.pcm_probability``). The cycle's covariance is
propagated to first order through the adjoints (GTSAM's ``Pose3`` convention: right
perturbation, tangent ``[rot, trans]``) by :func:`slam_lcd.backend.gate.cycle_chi2`, the
function behind the single-session loop gate's ``pair_chi2``, and each session's chain
covariances come from :class:`slam_lcd.backend.gate.ChainRelatives` (``chain_covariance``), as
the gate's do; here many pairs at once. Without the adjoints a heading error's lever arm is lost,
and true loops tens of metres apart fail the test.

Each session's relative pose between two of its keyframes is its own best estimate
(``SessionPoses.own()``: its odometry corrected by its own loops, never a pose that another
session's loops bent, so that the verdict on a pair depends on the two sessions alone and not
on the order in which they joined the map); the covariance is its
odometry chain's, an upper bound for that estimate. A step's covariance is the one the odometry
gave; where it gave none (or no valid one), or the front end modelled it (``SessionPoses.cov_modelled``),
the per-metre allowance ``map.pcm_sigma_trans_per_m``, ``pcm_sigma_rot_per_m`` and
``pcm_sigma_rot_per_rad`` (variance growing with the distance and the angle of the step: a random
walk, the front end's motion model with the same default figures, docs/multisession.md).

The test is symmetric: each loop is turned so that its ``a`` end lies in the session listed first
in the map (a loop seen from its other end has ``Z^-1`` and its covariance carried by ``Ad(Z)``),
and the two loops are taken in a fixed order, so the verdict does not depend on the argument
order nor on which end of a loop was the query.
"""
from __future__ import annotations

import numpy as np

from ..backend.gate import ChainRelatives, GateLoop, chain_covariance, chi2_quantile, cycle_chi2, se3_log_stack
from ..geometry import adjoint, inv, rotation_angle
from ..loop_factor import valid_informations
from .config import MapConfig
from .joint_types import JointLoop, SessionPoses

# floor on each sigma of a step's allowance (rad, m): the front end's default floor (frontend.odom_min_sigma_*),
# so that a step that did not move still has a valid covariance, as the front end's modelled one has
FLOOR = np.array([np.radians(0.05) ** 2] * 3 + [0.002 ** 2] * 3)


def allowance(T_step: np.ndarray, conf: MapConfig) -> np.ndarray:
    """The per-metre allowance of one odometry step ``T_step`` (6x6, GTSAM order): a random walk, plus
    :data:`FLOOR`. With the default figures, the front end's modelled covariance of the same step."""
    d = float(np.linalg.norm(T_step[:3, 3]))
    v_r = conf.pcm_sigma_rot_per_m ** 2 * d + conf.pcm_sigma_rot_per_rad ** 2 * float(rotation_angle(T_step))
    return np.diag([v_r] * 3 + [conf.pcm_sigma_trans_per_m ** 2 * d] * 3 + FLOOR)


def is_modelled(s: SessionPoses, i: int) -> bool:
    """Did the front end model step i's covariance (the log gave none)?"""
    return s.cov_modelled is not None and bool(s.cov_modelled[i])


def step_covariances(s: SessionPoses, conf: MapConfig) -> np.ndarray:
    """(n, 6, 6): each odometry step's covariance as given, else (none, no valid one, or a modelled one)
    the per-metre allowance for its length and angle."""
    n = len(s.ids)
    out = np.zeros((n, 6, 6))
    c = np.asarray(s.cov, float).reshape(-1, 6, 6)
    given = valid_informations(c)
    if s.cov_modelled is not None:
        given &= ~np.asarray(s.cov_modelled, bool)
    out[given] = 0.5 * (c[given] + c[given].transpose(0, 2, 1))
    for i in np.flatnonzero(~given):
        if i:
            out[i] = allowance(inv(s.T_odom[i - 1]) @ s.T_odom[i], conf)
    return out


class SessionChains:
    """Every session's odometry chain: relative poses of two keyframes of one session and their covariance."""

    def __init__(self, sessions: list[SessionPoses], conf: MapConfig):
        self.sessions = sessions
        self.where = {int(k): (si, i) for si, s in enumerate(sessions) for i, k in enumerate(s.ids)}
        self.conf = conf
        self._chains: dict[int, ChainRelatives] = {}
        self._stacked: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def chain(self, si: int) -> ChainRelatives:
        """Session ``si``'s chain, built when first asked for: an append reads only the sessions it judges."""
        if si not in self._chains:
            s = self.sessions[si]
            self._chains[si] = ChainRelatives.from_steps(np.asarray(s.T_odom, float), step_covariances(s, self.conf))
        return self._chains[si]

    def session_of(self, kf: int) -> int:
        return self.where[int(kf)][0]

    def _same_session(self, a: int, b: int) -> tuple[int, int, int]:
        (sa, i), (sb, j) = self.where[int(a)], self.where[int(b)]
        if sa != sb:
            raise ValueError(f"keyframes {a} and {b} are in different sessions")
        return sa, i, j

    def odometry(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """``T_a_b`` by the odometry alone and its chain covariance (frame b); a and b in one session."""
        si, i, j = self._same_session(a, b)
        return self.chain(si).odometry(i, j)

    def stacked(self, si: int) -> tuple[np.ndarray, np.ndarray]:
        """Session ``si``'s odometry poses (N, 4, 4) and its chain's prefix sums (N, 6, 6), kept."""
        if si not in self._stacked:
            self._stacked[si] = self.chain(si).stacked()
        return self._stacked[si]

    def estimates(self, si: int, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``T_i_j`` by session ``si``'s own estimate, with its odometry chain's covariance (frame j), for
        many pairs of positions at once."""
        odom, P = self.stacked(si)
        X = self.sessions[si].own()
        return inv(X[i]) @ X[j], chain_covariance(odom[j], P[np.minimum(i, j)], P[np.maximum(i, j)])

    def own_pose(self, kf: int) -> np.ndarray:
        """A keyframe's pose (4x4) in its session's own estimate: the one source of :meth:`position` and of the
        viewing directions the join rules compare."""
        si, i = self.where[int(kf)]
        return self.sessions[si].own()[i]

    def position(self, kf: int) -> np.ndarray:
        """A keyframe's position in its session's own estimate."""
        return self.own_pose(kf)[:3, 3]


def oriented(lp: JointLoop, first_session: int, chains: SessionChains) -> GateLoop:
    """The loop as a :class:`GateLoop` whose ``a`` end lies in ``first_session`` (flipped when needed)."""
    info = np.asarray(lp.info, float)
    cov = np.linalg.inv(0.5 * (info + info.T))
    if chains.session_of(lp.match) == first_session:
        return GateLoop(int(lp.match), int(lp.query), np.asarray(lp.T, float), cov)
    # T_b_a = (Z Exp(e))^-1 = Z^-1 Exp(-Ad(Z) e): the covariance carried by Ad(Z)
    A = adjoint(np.asarray(lp.T, float))
    flipped = A @ cov @ A.T
    return GateLoop(int(lp.query), int(lp.match), inv(np.asarray(lp.T, float)), 0.5 * (flipped + flipped.T))


def _order_key(g: GateLoop) -> tuple:
    return (g.a, g.b, tuple(np.round(g.Z.ravel(), 12)))


CHUNK = 20000  # loop pairs tested at once (memory: ~3 kB a pair)


def pair_statistics(loops: list[JointLoop], chains: SessionChains) -> np.ndarray:
    """(n, n) chi-square statistics (6 dof) of the cycles of every two loops between the same two sessions.

    Symmetric, ``inf`` on the diagonal. Each loop is turned to start in the session listed first
    and every pair is taken in one fixed order, so a pair's figure does not depend on the order
    of ``loops`` nor on which end of a loop is the query; the cycles are those of
    :func:`slam_lcd.backend.gate.pair_chi2`, many at once.

    The cycle of a pair (p, q) is the one of :func:`~slam_lcd.backend.gate.cycle_chi2`, its error
    and covariance carried by ``Ad(X_b(p))`` (the chi-square does not change) into the second
    session's world frame, where most of it belongs to one loop: ``H = X_a Z X_b^-1`` (the
    relation of the two sessions each loop implies) gives the error ``Log(H_p^-1 H_q)``, each
    loop's own covariance ``Ad(X_b) S Ad(X_b)^T`` is computed once, and of each chain's covariance
    only the difference of its prefix sums is the pair's. What is left per pair: one product of
    poses, one logarithm, two congruences and a 6x6 solve (a third of the products of carrying
    every term per pair). 1000 loops (499,500 pairs): 1.2-1.4 s on a 2-core AMD EPYC
    (``tools/bench_pcm.py``).
    """
    n = len(loops)
    out = np.full((n, n), np.inf)
    if n < 2:
        return out
    sess = {chains.session_of(k) for lp in loops for k in (lp.query, lp.match)}
    if len(sess) != 2 or any(chains.session_of(lp.query) == chains.session_of(lp.match) for lp in loops):
        raise ValueError("pairwise consistency needs loops between the same two sessions")
    s_first, s_second = sorted(sess)
    g = [oriented(lp, s_first, chains) for lp in loops]
    rank = sorted(range(n), key=lambda k: _order_key(g[k]))
    ia = np.array([chains.where[gl.a][1] for gl in g])
    ib = np.array([chains.where[gl.b][1] for gl in g])
    Z = np.array([gl.Z for gl in g])
    S = np.array([gl.cov for gl in g])
    Oa, Pa = chains.stacked(s_first)
    Ob, Pb = chains.stacked(s_second)
    Xa = chains.sessions[s_first].own()[ia]
    Xb = chains.sessions[s_second].own()[ib]
    H = Xa @ Z @ inv(Xb)
    Hi = inv(H)
    Ab = adjoint(Xb)
    W = Ab @ S @ np.swapaxes(Ab, -1, -2)
    M = adjoint(Xb @ inv(Ob[ib]))  # carries b's chain covariance (its odometry's frame) to its estimate's
    N = adjoint(Xb @ inv(Z) @ inv(Oa[ia]))  # and a's, through the loop
    MT, NT = np.ascontiguousarray(np.swapaxes(M, -1, -2)), np.ascontiguousarray(np.swapaxes(N, -1, -2))
    Pa, Pb = Pa[ia], Pb[ib]
    iu, ju = np.triu_indices(n, 1)
    first, second = np.array(rank)[iu], np.array(rank)[ju]  # each pair in rank order
    for c in range(0, len(first), CHUNK):
        p, q = first[c:c + CHUNK], second[c:c + CHUNK]
        a_later, b_later = ia[q] >= ia[p], ib[q] >= ib[p]
        dPa = Pa[np.where(a_later, q, p)] - Pa[np.where(a_later, p, q)]  # the later prefix less the earlier
        dPb = Pb[np.where(b_later, q, p)] - Pb[np.where(b_later, p, q)]
        with np.errstate(all="ignore"):
            e = se3_log_stack(Hi[p] @ H[q])
            cov = W[p] + W[q] + M[p] @ dPb @ MT[p] + N[q] @ dPa @ NT[q]
            x, ok = _chi2_ldl(cov, e)
            if not ok.all():
                try:
                    x[~ok] = np.einsum("ki,ki->k", e[~ok], np.linalg.solve(cov[~ok], e[~ok, :, None])[..., 0])
                except np.linalg.LinAlgError:
                    x[~ok] = _each(p[~ok], q[~ok], g, chains, s_first, s_second)
        x = np.where(np.isfinite(x), x, np.inf)
        out[p, q] = out[q, p] = x
    return out


def _chi2_ldl(cov: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``e^T cov^-1 e`` for a stack of 6x6 covariances by LDL^T, one entry of every matrix at a time
    (a batched LAPACK solve spends most of its time per call); also which were positive definite
    (the others' figures are not to be read)."""
    a, E = np.moveaxis(cov, 0, -1), e.T
    L: list[list[np.ndarray]] = [[] for _ in range(6)]
    d: list[np.ndarray] = []
    y: list[np.ndarray] = []
    ok = np.ones(len(e), bool)
    for j in range(6):
        Ld = [L[j][m] * d[m] for m in range(j)]
        dj = a[j, j] - sum(Ld[m] * L[j][m] for m in range(j))
        ok &= dj > 0
        d.append(dj)
        for i in range(j + 1, 6):
            L[i].append((a[i, j] - sum(L[i][m] * Ld[m] for m in range(j))) / dj)
        y.append(E[j] - sum(L[j][m] * y[m] for m in range(j)))
    return np.asarray(sum(y[j] * y[j] / d[j] for j in range(6))), ok


def _each(p: np.ndarray, q: np.ndarray, g: list[GateLoop], chains: SessionChains, s_first: int,
          s_second: int) -> np.ndarray:
    """The pairs of a chunk one at a time in the cycle's own frame (a singular covariance: ``inf``)."""
    out = np.empty(len(p))
    for t, (k, m) in enumerate(zip(p, q, strict=True)):
        A, SA = chains.estimates(s_first, np.array([chains.where[g[k].a][1]]), np.array([chains.where[g[m].a][1]]))
        C, SC = chains.estimates(s_second, np.array([chains.where[g[m].b][1]]), np.array([chains.where[g[k].b][1]]))
        out[t] = _one(g[k].Z, g[k].cov, g[m].Z, g[m].cov, A[0], SA[0], C[0], SC[0])
    return out


def _one(*args) -> float:
    try:
        return float(cycle_chi2(*args))
    except np.linalg.LinAlgError:
        return float("inf")


def pcm_threshold(conf: MapConfig) -> float:
    return chi2_quantile(conf.pcm_probability, 6)


def pairwise_consistent(l1: JointLoop, l2: JointLoop, chains: SessionChains, threshold: float) -> bool:
    """Do two loops between the same two sessions close a consistent cycle (chi-square test)?"""
    return bool(pair_statistics([l1, l2], chains)[0, 1] <= threshold)


def consistency_matrix(loops: list[JointLoop], chains: SessionChains, threshold: float) -> np.ndarray:
    """(n, n) bool: which loops of one pair of sessions are pairwise consistent (diagonal False)."""
    return pair_statistics(loops, chains) <= threshold
