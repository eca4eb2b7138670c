"""Absolute trajectory error (ATE) and relative pose error (RPE).

Definitions follow the ones the field reports (Sturm et al. 2012, as implemented by evo):
- ATE: after association and alignment, the translation error of pose *i* is
  ``|p_ref_i - p_est_i|`` and the rotation error the angle of ``R_ref_i^T R_est_i``.
- RPE: for pose pairs ``(i, j)`` ``delta`` apart (frames, or metres travelled along the
  reference), the error of the relative motion ``(T_ref_i^-1 T_ref_j)^-1 (T_est_i^-1 T_est_j)``.
Statistics use the population standard deviation (numpy's default, as evo does).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from ..geometry import inv, rotation_angle_deg
from ..types import Trajectory
from .align import Alignment, fit_alignment
from .associate import associate
from .config import EvalConfig
from .errors import AssociationError


@dataclass
class ErrorStats:
    """Summary statistics of one error series."""

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float

    @classmethod
    def of(cls, errors: np.ndarray) -> ErrorStats:
        e = np.asarray(errors, dtype=np.float64)
        if e.size == 0:
            nan = float("nan")
            return cls(nan, nan, nan, nan, nan, nan)
        return cls(
            rmse=float(np.sqrt(np.mean(e**2))),
            mean=float(np.mean(e)),
            median=float(np.median(e)),
            std=float(np.std(e)),
            min=float(np.min(e)),
            max=float(np.max(e)),
        )

    def to_dict(self) -> dict:
        return {k: float(v) for k, v in self.__dict__.items()}


@dataclass
class AteResult:
    """Absolute trajectory error of ``est`` against ``ref`` under ``alignment``.

    ``errors`` are per-pose translation errors (m), ``rot_errors_deg`` rotation errors;
    ``stamps`` the reference stamps (ns) of the matched poses; ``est_aligned`` the matched
    estimate after alignment (for plots).
    """

    alignment: Alignment
    errors: np.ndarray
    rot_errors_deg: np.ndarray
    stamps: np.ndarray
    n_ref: int
    n_est: int
    t_max_diff: float
    t_offset: float
    ref_matched: Trajectory | None = field(default=None, repr=False)
    est_aligned: Trajectory | None = field(default=None, repr=False)

    @property
    def translation(self) -> ErrorStats:
        return ErrorStats.of(self.errors)

    @property
    def rotation(self) -> ErrorStats:
        return ErrorStats.of(self.rot_errors_deg)

    # the names of the contract (translation statistics, metres)
    @property
    def rmse(self) -> float:
        return self.translation.rmse

    @property
    def mean(self) -> float:
        return self.translation.mean

    @property
    def median(self) -> float:
        return self.translation.median

    @property
    def std(self) -> float:
        return self.translation.std

    @property
    def max(self) -> float:
        return self.translation.max

    @property
    def n_matched(self) -> int:
        return int(len(self.errors))

    def summary(self) -> str:
        tr = self.translation
        return (
            f"ATE ({self.alignment.label}"
            + (f", scale {self.alignment.scale:.6g}" if self.alignment.mode in ("sim3", "scale") else "")
            + f"): RMSE {tr.rmse:.6f} m, mean {tr.mean:.6f} m, median {tr.median:.6f} m, "
            f"max {tr.max:.6f} m, std {tr.std:.6f} m; rotation RMSE {self.rotation.rmse:.4f} deg; "
            f"{self.n_matched} matched poses (ref {self.n_ref}, est {self.n_est})"
        )

    def to_dict(self) -> dict:
        return {
            "metric": "ate",
            "alignment": self.alignment.to_dict(),
            "translation_m": self.translation.to_dict(),
            "rotation_deg": self.rotation.to_dict(),
            "n_matched": self.n_matched,
            "n_ref": self.n_ref,
            "n_est": self.n_est,
            "t_max_diff_s": self.t_max_diff,
            "t_offset_s": self.t_offset,
        }


# an error below this (m) is numerical noise: a ratio against it would say nothing (a perfect
# odometry would print "0.000 m -> 0.000 m (192.2% of odometry)")
RATIO_FLOOR_M = 1e-3


def ratio_or_none(after: float | None, before: float | None) -> float | None:
    """``after / before``, or None when ``before`` is ~0 (below :data:`RATIO_FLOOR_M`) or missing."""
    if after is None or before is None or before < RATIO_FLOOR_M:
        return None
    return after / before


def ate(
    ref: Trajectory,
    est: Trajectory,
    align: str = "se3",
    *,
    t_max_diff: float = 0.01,
    t_offset: float = 0.0,
    n_to_align: int | None = None,
) -> AteResult:
    """Associate ``est`` to ``ref`` in time, align it (``'none'|'se3'|'sim3'|'scale'``), measure ATE."""
    ref_m, est_m = associate(ref, est, t_max_diff, t_offset)
    alignment = fit_alignment(ref_m, est_m, align, n_to_align)
    est_a = alignment.apply(est_m)
    trans = np.linalg.norm(ref_m.positions - est_a.positions, axis=1)
    R_err = np.transpose(ref_m.poses[:, :3, :3], (0, 2, 1)) @ est_a.poses[:, :3, :3]
    return AteResult(
        alignment=alignment,
        errors=trans,
        rot_errors_deg=rotation_angle_deg(R_err),
        stamps=ref_m.stamps.copy(),
        n_ref=len(ref),
        n_est=len(est),
        t_max_diff=float(t_max_diff),
        t_offset=float(t_offset),
        ref_matched=ref_m,
        est_aligned=est_a,
    )


@dataclass
class RpeResult:
    """Relative pose error over pose pairs ``delta`` ``delta_unit`` apart."""

    alignment: Alignment
    delta: float
    delta_unit: str
    pairs: np.ndarray  # (M, 2) indices into the matched trajectories
    errors: np.ndarray  # translation error of each pair's relative motion (m)
    rot_errors_deg: np.ndarray
    stamps: np.ndarray  # reference stamp (ns) of each pair's second pose

    @property
    def translation(self) -> ErrorStats:
        return ErrorStats.of(self.errors)

    @property
    def rotation(self) -> ErrorStats:
        return ErrorStats.of(self.rot_errors_deg)

    @property
    def rmse(self) -> float:
        return self.translation.rmse

    def summary(self) -> str:
        return (
            f"RPE (delta {self.delta:g} {self.delta_unit}, {self.alignment.label}): "
            f"translation RMSE {self.translation.rmse:.6f} m, rotation RMSE {self.rotation.rmse:.4f} deg, "
            f"{len(self.errors)} pairs"
        )

    def to_dict(self) -> dict:
        return {
            "metric": "rpe",
            "delta": self.delta,
            "delta_unit": self.delta_unit,
            "alignment": self.alignment.to_dict(),
            "translation_m": self.translation.to_dict(),
            "rotation_deg": self.rotation.to_dict(),
            "n_pairs": int(len(self.errors)),
        }


def pairs_by_frames(n: int, delta: int) -> np.ndarray:
    """Consecutive pairs ``(0, d), (d, 2d), …`` of indices ``delta`` frames apart."""
    ids = np.arange(0, n, max(int(delta), 1))
    return np.stack([ids[:-1], ids[1:]], axis=1) if len(ids) > 1 else np.zeros((0, 2), dtype=np.int64)


def pairs_by_distance(positions: np.ndarray, delta_m: float) -> np.ndarray:
    """Consecutive pairs whose path length along ``positions`` first reaches ``delta_m``."""
    picked = [0]
    travelled = 0.0
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    for i, step in enumerate(steps, start=1):
        travelled += float(step)
        if travelled >= delta_m:
            picked.append(i)
            travelled = 0.0
    ids = np.asarray(picked, dtype=np.int64)
    return np.stack([ids[:-1], ids[1:]], axis=1) if len(ids) > 1 else np.zeros((0, 2), dtype=np.int64)


def rpe(
    ref: Trajectory,
    est: Trajectory,
    delta: float = 1.0,
    delta_unit: Literal["frames", "m"] = "frames",
    align: str = "none",
    *,
    t_max_diff: float = 0.01,
    t_offset: float = 0.0,
    n_to_align: int | None = None,
    pairs_from: Literal["ref", "est"] = "ref",
) -> RpeResult:
    """Relative pose error; pairs are chosen on ``pairs_from`` (frames, or metres travelled).

    The default picks pairs on the reference, so a delta in metres means metres of the real
    motion whatever the estimate's scale (evo's ``--pairs_from_reference``).
    """
    if delta <= 0:
        raise AssociationError(f"RPE delta must be > 0, got {delta}")
    ref_m, est_m = associate(ref, est, t_max_diff, t_offset)
    alignment = fit_alignment(ref_m, est_m, align, n_to_align)
    est_a = alignment.apply(est_m)
    if delta_unit == "frames":
        pairs = pairs_by_frames(len(ref_m), int(round(delta)))
    elif delta_unit == "m":
        basis = ref_m if pairs_from == "ref" else est_a
        pairs = pairs_by_distance(basis.positions, float(delta))
    else:
        raise AssociationError(f"unknown RPE delta unit {delta_unit!r}; use 'frames' or 'm'")
    i, j = pairs[:, 0], pairs[:, 1]
    rel_ref = inv(ref_m.poses[i]) @ ref_m.poses[j]
    rel_est = inv(est_a.poses[i]) @ est_a.poses[j]
    E = inv(rel_ref) @ rel_est
    return RpeResult(
        alignment=alignment,
        delta=float(delta),
        delta_unit=delta_unit,
        pairs=pairs,
        errors=np.linalg.norm(E[:, :3, 3], axis=1),
        rot_errors_deg=rotation_angle_deg(E[:, :3, :3]),
        stamps=ref_m.stamps[j],
    )


def ate_with_config(ref: Trajectory, est: Trajectory, conf=None) -> AteResult:
    """:func:`ate` with the association and alignment settings of an ``EvalConfig``."""
    conf = conf or EvalConfig()
    return ate(ref, est, conf.align, t_max_diff=conf.t_max_diff, t_offset=conf.t_offset, n_to_align=conf.n_to_align)


def rpe_with_config(ref: Trajectory, est: Trajectory, conf=None) -> RpeResult:
    """:func:`rpe` with the association, alignment and pair spacing of an ``EvalConfig``.

    The alignment is the ATE's: an SE(3) one leaves relative motions (so RPE) unchanged; a
    Sim(3) or scale one puts a scale-free estimate's translations in metres first.
    """
    conf = conf or EvalConfig()
    return rpe(ref, est, conf.rpe_delta, conf.rpe_delta_unit, conf.align, t_max_diff=conf.t_max_diff,
               t_offset=conf.t_offset, n_to_align=conf.n_to_align)


def ate_before_after(ref: Trajectory, before: Trajectory, after: Trajectory, conf=None) -> dict[str, AteResult]:
    """ATE of odometry (``before``) and corrected (``after``) under identical settings.

    Both use the same ``t_max_diff``/``t_offset`` and alignment mode; each gets its own
    best alignment (the fair comparison: neither is penalised for its world frame).
    """
    return {"before": ate_with_config(ref, before, conf), "after": ate_with_config(ref, after, conf)}
