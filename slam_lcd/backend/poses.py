"""Small GTSAM helpers of the pose graph: checked poses in, iSAM2 parameters, Values out."""
from __future__ import annotations

import gtsam
import numpy as np

from ..errors import InvalidPoseError
from ..geometry import project_to_se3
from .config import BackendConfig


def check_pose(T, what: str) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InvalidPoseError(f"{what}: expected a finite 4x4 pose, got shape {T.shape}")
    R = T[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-3 or np.linalg.det(R) < 0:
        raise InvalidPoseError(f"{what}: rotation block is not a proper rotation")
    return project_to_se3(T)  # remove round-off so GTSAM gets an exact rotation


def isam2_params(conf: BackendConfig, qr: bool = False) -> gtsam.ISAM2Params:
    """iSAM2 parameters of the config; ``qr`` forces QR factorisation."""
    p = gtsam.ISAM2Params()
    p.setRelinearizeThreshold(conf.isam2_relinearize_threshold)
    p.relinearizeSkip = int(conf.isam2_relinearize_skip)
    p.setFactorization("QR" if qr or conf.isam2_factorization == "qr" else "CHOLESKY")
    return p


def lm_params(qr: bool = False) -> gtsam.LevenbergMarquardtParams:
    """Levenberg-Marquardt parameters; ``qr``: QR factorisation (a graph with weak segment priors, see
    :mod:`.segments`: Cholesky squares its condition number)."""
    params = gtsam.LevenbergMarquardtParams()
    if qr:
        params.setLinearSolverType("MULTIFRONTAL_QR")
    return params


def levenberg_marquardt(graph: gtsam.NonlinearFactorGraph, initial: gtsam.Values, qr: bool = False) -> gtsam.Values:
    """Batch Levenberg-Marquardt to tight tolerances (the final solve of a written graph)."""
    params = lm_params(qr)
    params.setRelativeErrorTol(1e-9)
    params.setAbsoluteErrorTol(1e-9)
    params.setMaxIterations(100)
    return gtsam.LevenbergMarquardtOptimizer(graph, initial, params).optimize()



def values_to_array(values: gtsam.Values, n: int) -> np.ndarray:
    """Pose3 values with keys 0..n-1 -> (n, 4, 4)."""
    flat = np.asarray(gtsam.utilities.extractPose3(values))
    keys = np.asarray(list(values.keys()), dtype=np.int64)
    out = np.tile(np.eye(4), (n, 1, 1))
    out[keys, :3, :3] = flat[:, :9].reshape(-1, 3, 3)
    out[keys, :3, 3] = flat[:, 9:12]
    return out
