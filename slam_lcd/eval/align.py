"""Least-squares alignment of an estimate to a reference (Umeyama 1991).

Why: a SLAM estimate lives in its own world frame (and, for monocular SLAM, its own
scale), so absolute errors are only meaningful after the best rigid (SE(3)) or similarity
(Sim(3)) transform has been applied. The mode used is carried into every result and
figure title, because the same numbers mean different things under different alignments.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..types import Trajectory
from .errors import AlignmentError

AlignMode = Literal["none", "se3", "sim3", "scale"]
ALIGN_MODES = ("none", "se3", "sim3", "scale")
ALIGN_LABELS = {
    "none": "no alignment",
    "se3": "SE(3) Umeyama alignment",
    "sim3": "Sim(3) Umeyama alignment",
    "scale": "scale-only correction",
    "origin": "origin alignment",  # evo's --align_origin (slam_lcd.eval.relations)
}


@dataclass
class Alignment:
    """``p_ref ≈ scale * R @ p_est + t`` (``mode`` says which parts were estimated)."""

    mode: str = "none"
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0
    n_used: int = 0  # how many pose pairs the alignment was fitted on

    @property
    def label(self) -> str:
        return ALIGN_LABELS.get(self.mode, self.mode)

    def apply(self, traj: Trajectory) -> Trajectory:
        """The trajectory moved by this transform (positions scaled, rotations rotated)."""
        poses = traj.poses.copy()
        poses[:, :3, :3] = self.R @ poses[:, :3, :3]
        poses[:, :3, 3] = self.scale * poses[:, :3, 3] @ self.R.T + self.t
        return Trajectory(
            stamps=traj.stamps.copy(),
            poses=poses,
            covariances=traj.covariances,
            frame_id=traj.frame_id,
            child_frame_id=traj.child_frame_id,
        )

    def to_dict(self) -> dict:
        return {
            "mode": self.mode,
            "label": self.label,
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "scale": float(self.scale),
            "n_used": int(self.n_used),
        }


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """``(R, t, s)`` minimising ``sum |dst_i - (s R src_i + t)|^2`` for (N, 3) point sets."""
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2:
        raise AlignmentError(f"point sets must have equal (N, d) shapes, got {src.shape} and {dst.shape}")
    n, dim = src.shape
    if n < dim:
        raise AlignmentError(f"alignment needs at least {dim} matched poses, got {n}")
    mu_src = src.mean(axis=0)
    mu_dst = dst.mean(axis=0)
    src_c = src - mu_src
    dst_c = dst - mu_dst
    var_src = float((src_c**2).sum()) / n
    cov = dst_c.T @ src_c / n
    u, d, vt = np.linalg.svd(cov)
    if np.count_nonzero(d > np.finfo(np.float64).eps) < dim - 1:
        raise AlignmentError("matched positions are degenerate (all on one point or line); cannot align")
    S = np.eye(dim)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        S[-1, -1] = -1.0
    R = u @ S @ vt
    if with_scale:
        if var_src <= 0:
            raise AlignmentError("estimate positions have zero spread; cannot estimate a scale")
        s = float(np.trace(np.diag(d) @ S) / var_src)
    else:
        s = 1.0
    t = mu_dst - s * R @ mu_src
    return R, t, s


def fit_alignment(ref: Trajectory, est: Trajectory, mode: str, n_to_align: int | None = None) -> Alignment:
    """Fit ``mode`` ('none' | 'se3' | 'sim3' | 'scale') on the first ``n_to_align`` matched poses."""
    if mode not in ALIGN_MODES:
        raise AlignmentError(f"unknown alignment {mode!r}; known: {', '.join(ALIGN_MODES)}")
    if len(ref) != len(est):
        raise AlignmentError(f"trajectories must be associated first ({len(ref)} vs {len(est)} poses)")
    n = len(ref) if n_to_align is None or n_to_align < 0 else min(int(n_to_align), len(ref))
    if mode == "none":
        return Alignment("none", n_used=0)
    R, t, s = umeyama(est.positions[:n], ref.positions[:n], with_scale=mode in ("sim3", "scale"))
    if mode == "scale":
        return Alignment("scale", scale=s, n_used=n)
    if mode == "se3":
        return Alignment("se3", R=R, t=t, scale=1.0, n_used=n)
    return Alignment("sim3", R=R, t=t, scale=s, n_used=n)


def align_mode_from_flags(align: bool, correct_scale: bool) -> str:
    """evo's flags: ``-a`` → se3, ``-a -s`` → sim3, ``-s`` → scale only, neither → none."""
    if align and correct_scale:
        return "sim3"
    if align:
        return "se3"
    if correct_scale:
        return "scale"
    return "none"
