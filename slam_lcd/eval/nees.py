"""Normalised estimation error squared (NEES) of loop closures against ground truth.

``xi = Log(T_gt^-1 T_match_query)`` is the error of a loop's pose as a right perturbation in
GTSAM order ``[rx ry rz tx ty tz]`` (the perturbation its information matrix describes), and
``NEES = xi^T Info xi``. For an honest 6x6 information NEES follows chi2(6): median 5.35,
1 % of loops above the 99 % quantile 16.81. Much larger values mean the loop claims more
certainty than it has, which breaks every chi-square gate downstream.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import chdtri

from ..geometry import inv, se3_log
from ..lcd.config import LcdConfig

CHI2_6_99 = float(chdtri(6, 0.01))  # 16.81


def loop_error(T_match_query: np.ndarray, T_gt: np.ndarray) -> np.ndarray:
    """Right-perturbation error ``Log(T_gt^-1 T)``, ``[rx ry rz tx ty tz]``."""
    return se3_log(inv(np.asarray(T_gt, float)) @ np.asarray(T_match_query, float))


def nees(T_match_query, information, T_gt) -> float:
    e = loop_error(T_match_query, T_gt)
    return float(e @ np.asarray(information, float) @ e)


@dataclass
class NeesReport:
    nees: np.ndarray  # (L,)
    errors: np.ndarray  # (L, 6)
    sigmas: np.ndarray  # (L, 6) claimed 1-sigma (sqrt of the covariance diagonal)
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0))
    n_false: int = 0  # accepted loops between places the ground truth says do not overlap

    @property
    def median(self) -> float:
        return float(np.median(self.nees)) if len(self.nees) else float("nan")

    @property
    def frac_above_99(self) -> float:
        return float(np.mean(self.nees > CHI2_6_99)) if len(self.nees) else float("nan")

    def summary(self) -> str:
        return (f"loops {len(self.nees)}: NEES median {self.median:.2f} (chi2(6): 5.35), mean {np.mean(self.nees):.2f} "
                f"(6), above the 99% bound {CHI2_6_99:.2f}: {100 * self.frac_above_99:.1f}% (1%)")

    def detail_lines(self) -> list[str]:
        rot_err = np.degrees(np.linalg.norm(self.errors[:, :3], axis=1))
        tr_err = np.linalg.norm(self.errors[:, 3:], axis=1)
        rot_sig = np.degrees(np.linalg.norm(self.sigmas[:, :3], axis=1))
        tr_sig = np.linalg.norm(self.sigmas[:, 3:], axis=1)
        q = lambda a: f"{np.median(a):.3g} (p90 {np.percentile(a, 90):.3g})"  # noqa: E731
        return [f"rotation error deg {q(rot_err)} vs claimed 1-sigma {q(rot_sig)}",
                f"translation error m {q(tr_err)} vs claimed 1-sigma {q(tr_sig)}",
                f"NEES quartiles {np.percentile(self.nees, [25, 50, 75]).round(2).tolist()}, max {self.nees.max():.1f}"
                + (f"; PnP inliers median {np.median(self.inliers):.0f}" if np.any(self.inliers) else "")]


def report(closures, gt_poses: dict) -> NeesReport:
    """NEES of every closure with a pose, against ``gt_poses[kf_id]`` (ground-truth ``T_world_body``)."""
    ne, er, sg, inl = [], [], [], []
    for c in closures:
        T = np.asarray(c.T_match_query, float)
        if not np.all(np.isfinite(T)):
            continue
        T_gt = inv(gt_poses[c.match_id]) @ gt_poses[c.query_id]
        e = loop_error(T, T_gt)
        info = np.asarray(c.information, float)
        ne.append(float(e @ info @ e))
        er.append(e)
        sg.append(np.sqrt(np.diag(np.linalg.inv(info))))
        inl.append(c.evidence.get("pose_inliers", 0))
    z = np.zeros((0, 6))
    return NeesReport(np.array(ne), np.array(er) if er else z, np.array(sg) if sg else z, np.array(inl))


def run_detector(frames, extractor, conf=None):
    """A :class:`~slam_lcd.lcd.LoopDetector` fed with every keyframe of ``frames`` (demo settings)."""
    from ..lcd.detector import LoopDetector  # lazy: OpenCV

    det = LoopDetector(conf or LcdConfig(exclude_recent_s=20.0, exclude_recent_n=0), extractor=extractor)
    for kf in frames.keyframes:
        det.add(kf)
    return det


def detector_nees(det, frames) -> NeesReport:
    """NEES of a detector's closures on demo keyframes, and how many are false (ground truth)."""
    gt = {kf.id: frames.gt.poses[k] for k, kf in enumerate(frames.keyframes)}
    rep = report(det.closures, gt)
    cams = {kf.id: frames.gt.poses[k] @ frames.T_body_camera for k, kf in enumerate(frames.keyframes)}
    for c in det.closures:  # a false loop: cameras far apart or looking elsewhere
        D = inv(cams[c.match_id]) @ cams[c.query_id]
        ang = np.degrees(np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1, 1)))
        rep.n_false += bool(np.linalg.norm(D[:3, 3]) > 2.0 or ang > 45.0)
    return rep
