"""Covariance propagation for the front end, in GTSAM's Pose3 conventions (numpy only).

A pose perturbation is on the right, ``T = T_hat @ Exp(xi)``, with ``xi = [omega, v]``
(rotation first), exactly like ``gtsam.Pose3``. Covariances therefore live in the body
frame of the pose they belong to, and relative motions compose with the adjoint
``Ad(T) = [[R, 0], [skew(t) R, R]]``. The SE(3) algebra itself lives in
:mod:`slam_lcd.geometry`; ``inv``, ``rotation_angle``, ``se3_exp``, ``se3_log`` (and the other
names imported below) are re-exported here for existing callers.
"""
from __future__ import annotations

import numpy as np

from ..geometry import adjoint, inv, rotation_angle, se3_exp, se3_log, skew, so3_exp, so3_log

__all__ = [
    "adjoint", "compose_covariance", "inv", "relative_covariance", "rotation_angle", "se3_exp", "se3_log",
    "skew", "so3_exp", "so3_log", "transform_covariance",
]


def compose_covariance(cov_ab: np.ndarray, T_bc: np.ndarray, cov_bc: np.ndarray) -> np.ndarray:
    """Covariance of ``T_ac = T_ab T_bc`` for independent right-perturbation noises.

    ``T_ab Exp(x) T_bc Exp(y) = T_ac Exp(Ad(T_bc^-1) x) Exp(y)``, so the first covariance
    is carried into the frame c by the adjoint of ``T_bc^-1`` and the second adds.
    """
    A = adjoint(inv(T_bc))
    out = A @ cov_ab @ A.T + cov_bc
    return 0.5 * (out + out.T)


def relative_covariance(T_wi: np.ndarray, cov_i: np.ndarray, T_wj: np.ndarray, cov_j: np.ndarray,
                        floor: np.ndarray | None = None) -> np.ndarray:
    """Covariance of the motion ``T_ij`` from two absolute (growing) pose covariances.

    Under the odometry model ``T_wj = T_wi T_ij`` with independent increments,
    ``cov_j = Ad(T_ij^-1) cov_i Ad(T_ij^-1)^T + cov_ij``; the difference is projected onto
    the positive semi-definite cone and a floor (a diagonal of variances) is added.
    """
    T_ij = inv(T_wi) @ T_wj
    A = adjoint(inv(T_ij))
    d = cov_j - A @ cov_i @ A.T
    d = 0.5 * (d + d.T)
    w, V = np.linalg.eigh(d)
    d = (V * np.maximum(w, 0.0)) @ V.T
    if floor is not None:
        d = d + np.diag(floor)
    return d


def transform_covariance(cov_c: np.ndarray, T_b_c: np.ndarray) -> np.ndarray:
    """Covariance of a motion of frame c re-expressed for frame b rigidly attached by ``T_b_c``.

    ``T_b_c A Exp(xi) T_c_b = (T_b_c A T_c_b) Exp(Ad(T_b_c) xi)``.
    """
    A = adjoint(T_b_c)
    return A @ cov_c @ A.T
