"""Benchmark scenario on a real trajectory: drifting odometry, true and false loops.

From a ground-truth trajectory (KITTI-00 by default) we make

- odometry: every ground-truth step perturbed by Gaussian noise plus a constant bias
  (a slow yaw drift and a scale error, as wheel/visual odometry does), chained;
- true loops: keyframe pairs whose ground-truth positions are < ``loop_max_dist`` m apart
  and > ``loop_min_gap`` frames apart (the nearest earlier frame, for one query every
  ``loop_every`` frames), measured as the true relative pose plus noise;
- false loops: random pairs (same frame-gap rule, ground truth > ``false_min_dist`` m
  apart) carrying a relative pose drawn like a real loop's (a few metres, a few degrees),
  so they look plausible on their own. ``false_fraction`` is the share of false loops
  among all loops (0.5: as many false as true).

Loops are emitted in query order, as an online detector would. Everything is seeded.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from slam_lcd.errors import FileMissingError, TrajectoryFormatError
from slam_lcd.geometry import inv, project_to_se3
from slam_lcd.types import LoopClosure


@dataclass
class ScenarioConfig:
    stride: int = 1  # use every stride-th ground-truth pose as a keyframe
    odom_sigma_rot: float = 2e-4  # rad per frame (noise)
    odom_sigma_trans: float = 0.02  # m per frame (noise)
    odom_bias_yaw: float = 5e-5  # rad per frame about the vertical axis
    odom_scale_error: float = 0.01  # relative translation error
    odom_cov_inflation: float = 2.0  # declared sigma = inflation * sqrt(noise^2 + bias^2)
    loop_max_dist: float = 3.0
    loop_min_gap: int = 100  # in ground-truth frames
    loop_every: int = 5  # one loop query every n keyframes (subsampling)
    loop_sigma_rot: float = 0.01
    loop_sigma_trans: float = 0.1
    false_fraction: float = 0.0
    false_min_dist: float = 20.0
    false_max_dist: float | None = None  # set to make hard false loops between nearby places
    seed: int = 0


@dataclass
class Scenario:
    stamps: np.ndarray  # (N,) int ns
    gt: np.ndarray  # (N, 4, 4)
    odom: np.ndarray  # (N, 4, 4)
    odom_cov: np.ndarray  # (6, 6) declared per-step covariance
    loops: list[LoopClosure]
    is_true: np.ndarray  # (L,) bool, aligned with loops
    events: list = field(default_factory=list)  # (keyframe index, [loop indices]) in order

    @property
    def n_true(self) -> int:
        return int(self.is_true.sum())

    @property
    def n_false(self) -> int:
        return int((~self.is_true).sum())


def read_kitti_poses(path: str | Path) -> np.ndarray:
    """KITTI odometry ground truth: one 3x4 row-major matrix per line -> (N, 4, 4)."""
    path = Path(path)
    if not path.is_file():
        raise FileMissingError("KITTI pose file not found", path)
    try:
        a = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except ValueError as e:
        raise TrajectoryFormatError(f"not a KITTI pose file ({e})", path) from None
    if a.shape[1] != 12:
        raise TrajectoryFormatError(f"expected 12 numbers per line, got {a.shape[1]}", path)
    T = np.tile(np.eye(4), (len(a), 1, 1))
    T[:, :3, :4] = a.reshape(-1, 3, 4)
    return np.array([project_to_se3(x) for x in T])


def _exp_small(xi: np.ndarray) -> np.ndarray:
    """Decoupled exponential of (N, 6) [r, t] vectors (fine for small perturbations)."""
    T = np.tile(np.eye(4), (len(xi), 1, 1))
    T[:, :3, :3] = Rotation.from_rotvec(xi[:, :3]).as_matrix()
    T[:, :3, 3] = xi[:, 3:]
    return T


def make_scenario(
    gt_path: str | Path, conf: ScenarioConfig | None = None, times_path: str | Path | None = None
) -> Scenario:
    c = conf or ScenarioConfig()
    rng = np.random.default_rng(c.seed)
    gt_all = read_kitti_poses(gt_path)
    idx = np.arange(0, len(gt_all), c.stride)
    gt = gt_all[idx]
    if times_path is not None and Path(times_path).is_file():
        t = np.loadtxt(times_path, dtype=np.float64).reshape(-1)[idx]
        stamps = np.round(t * 1e9).astype(np.int64)
    else:
        stamps = (idx * 100_000_000).astype(np.int64)  # 10 Hz
    n = len(gt)
    s = c.stride
    # Odometry: true steps * Exp(bias + noise). KITTI camera frame: y points down, so the
    # vertical (yaw) axis is y.
    steps = inv(gt[:-1]) @ gt[1:]
    sig = np.r_[[c.odom_sigma_rot * np.sqrt(s)] * 3, [c.odom_sigma_trans * np.sqrt(s)] * 3]
    noise = rng.normal(size=(n - 1, 6)) * sig
    noise[:, 1] += c.odom_bias_yaw * s
    noisy = steps @ _exp_small(noise)
    noisy[:, :3, 3] *= 1.0 + c.odom_scale_error
    odom = np.empty_like(gt)
    odom[0] = gt[0]
    for k in range(1, n):
        odom[k] = project_to_se3(odom[k - 1] @ noisy[k - 1])
    step_len = float(np.median(np.linalg.norm(steps[:, :3, 3], axis=1)))
    bias = np.r_[[c.odom_bias_yaw * s] * 3, [c.odom_scale_error * step_len] * 3]
    odom_cov = np.diag((c.odom_cov_inflation**2) * (sig**2 + bias**2))

    # True loops.
    pos = gt[:, :3, 3]
    tree = cKDTree(pos)
    min_gap = max(1, int(np.ceil(c.loop_min_gap / s)))
    loop_sig = np.r_[[c.loop_sigma_rot] * 3, [c.loop_sigma_trans] * 3]
    info = np.diag(1.0 / loop_sig**2)
    loops: list[tuple[int, int, np.ndarray, bool]] = []
    for q in range(min_gap, n, c.loop_every):
        cand = [m for m in tree.query_ball_point(pos[q], c.loop_max_dist) if q - m > min_gap]
        if not cand:
            continue
        m = min(cand, key=lambda m: np.linalg.norm(pos[m] - pos[q]))
        Z = inv(gt[m]) @ gt[q] @ _exp_small(rng.normal(size=(1, 6)) * loop_sig)[0]
        loops.append((q, m, Z, True))
    n_true = len(loops)
    # False loops: random far-apart pairs with a loop-like relative pose.
    f = c.false_fraction
    n_false = int(round(f / (1.0 - f) * n_true)) if 0 < f < 1 else 0
    made = 0
    while made < n_false:
        q = int(rng.integers(min_gap + 1, n))
        m = int(rng.integers(0, q - min_gap))
        dist = np.linalg.norm(pos[q] - pos[m])
        if dist < c.false_min_dist or (c.false_max_dist is not None and dist > c.false_max_dist):
            continue
        xi = np.r_[rng.normal(0, 0.05, 3), rng.uniform(-c.loop_max_dist, c.loop_max_dist, 3) * [1, 0.1, 1]]
        loops.append((q, m, _exp_small(xi[None])[0], False))
        made += 1
    loops.sort(key=lambda x: x[0])
    closures = [
        LoopClosure(query_id=q, match_id=m, T_match_query=Z, information=info.copy(),
                    query_stamp=int(stamps[q]), match_stamp=int(stamps[m]))
        for q, m, Z, _ in loops
    ]
    is_true = np.array([t for *_, t in loops], dtype=bool)
    events: dict[int, list[int]] = {}
    for i, (q, *_rest) in enumerate(loops):
        events.setdefault(q, []).append(i)
    return Scenario(stamps, gt, odom, odom_cov, closures, is_true, sorted(events.items()))


def align_se3(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation/translation (Umeyama, no scale) mapping points src -> dst."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    H = (dst - mu_d).T @ (src - mu_s) / len(src)
    U, _, Vt = np.linalg.svd(H)
    D = np.eye(3)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        D[2, 2] = -1
    R = U @ D @ Vt
    return R, mu_d - R @ mu_s


def ate_rmse(gt_poses: np.ndarray, est_poses: np.ndarray) -> float:
    """Position RMSE after SE(3) alignment of the estimate onto the ground truth."""
    p, q = est_poses[:, :3, 3], gt_poses[:, :3, 3]
    R, t = align_se3(p, q)
    return float(np.sqrt(np.mean(np.sum((p @ R.T + t - q) ** 2, axis=1))))


@dataclass
class RunResult:
    ate_odometry: float
    ate: float
    true_kept: int
    true_total: int
    false_rejected: int
    false_total: int
    seconds: float

    @property
    def true_kept_frac(self) -> float:
        return self.true_kept / self.true_total if self.true_total else 1.0

    @property
    def false_rejected_frac(self) -> float:
        return self.false_rejected / self.false_total if self.false_total else 1.0

    def line(self, name: str) -> str:
        return (
            f"{name}: ATE {self.ate:.2f} m (odometry {self.ate_odometry:.2f} m), true loops kept "
            f"{self.true_kept}/{self.true_total}, false loops rejected {self.false_rejected}/{self.false_total}, "
            f"{self.seconds:.1f} s"
        )


def run_scenario(sc: Scenario, backend_conf=None, finalize: bool = True):
    """Feed the scenario keyframe by keyframe into a PoseGraph; returns (graph, RunResult)."""
    import time

    from slam_lcd.backend.pose_graph import ACCEPTED, PoseGraph

    t0 = time.perf_counter()
    g = PoseGraph(backend_conf)
    ev = dict(sc.events)
    for k in range(len(sc.stamps)):
        g.add_keyframe(k, int(sc.stamps[k]), sc.odom[k], sc.odom_cov if k else None)
        for i in ev.get(k, ()):
            g.add_loop(sc.loops[i])
    if finalize:
        g.finalize()
    secs = time.perf_counter() - t0
    acc = np.array([r.verdict == ACCEPTED for r in g.loop_records], dtype=bool)
    res = RunResult(
        ate_odometry=ate_rmse(sc.gt, sc.odom),
        ate=ate_rmse(sc.gt, g.estimate_array()),
        true_kept=int((acc & sc.is_true).sum()),
        true_total=sc.n_true,
        false_rejected=int((~acc & ~sc.is_true).sum()),
        false_total=sc.n_false,
        seconds=secs,
    )
    return g, res
