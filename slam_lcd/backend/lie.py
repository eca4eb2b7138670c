"""SE(3) log/exp through GTSAM, for the back end.

Everything else (inverse, adjoint, quaternions, projection onto SE(3)) lives in
:mod:`slam_lcd.geometry`, in the same conventions: tangent vectors and covariances are
ordered ``[rx ry rz tx ty tz]`` and perturbations are on the right (``T * Exp(xi)``),
exactly as ``gtsam.Pose3`` does, so a covariance computed here can be handed to a GTSAM
noise model unchanged. These two stay on GTSAM because its Logmap is exact for rotation
angles near 0 and near pi.
"""
from __future__ import annotations

import numpy as np

import gtsam


def log(T: np.ndarray) -> np.ndarray:
    """SE(3) logarithm ``[w, v]`` of one 4x4 (gtsam.Pose3.Logmap)."""
    return np.asarray(gtsam.Pose3.Logmap(gtsam.Pose3(np.asarray(T, dtype=np.float64))))


def exp(xi: np.ndarray) -> np.ndarray:
    """SE(3) exponential of one 6-vector ``[w, v]`` (gtsam.Pose3.Expmap)."""
    return gtsam.Pose3.Expmap(np.asarray(xi, dtype=np.float64)).matrix()
