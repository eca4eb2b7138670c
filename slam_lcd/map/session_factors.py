"""The GTSAM factors of a map's sessions: odometry steps and loops with their noise models.

Kept apart from :mod:`.joint_graph` so that the pair verdicts (:mod:`.pair_verdicts`), the joint
solve and :meth:`Map.factor_graph` build the same factors from one place.
"""
from __future__ import annotations

import gtsam
import numpy as np

from ..backend.loop_factors import valid_information
from ..geometry import inv
from ..loop_factor import valid_informations
from .config import MapConfig
from .joint_types import JointLoop, SessionPoses
from .pcm import allowance, is_modelled

ODOM_SIGMAS = np.r_[[0.01] * 3, [0.05] * 3]  # step noise when a session's odometry gave none


def information_noise(info: np.ndarray, scale: float = 1.0):
    """A Gaussian noise model from a (symmetrised) information matrix, GTSAM order, times ``scale``."""
    info = 0.5 * (np.asarray(info, float) + np.asarray(info, float).T)
    return gtsam.noiseModel.Gaussian.Information(scale * info)


def odometry_covariance(cov: np.ndarray | None, modelled: bool = False, T_step: np.ndarray | None = None,
                        conf: MapConfig | None = None) -> np.ndarray:
    """An odometry step's covariance as given when it is a valid one, else the default step noise; one the
    front end ``modelled`` is replaced by the map's per-metre allowance for ``T_step`` (:func:`.pcm.allowance`)."""
    if modelled and T_step is not None:
        return allowance(T_step, conf or MapConfig())
    return np.asarray(cov, float) if valid_information(cov) else np.diag(ODOM_SIGMAS ** 2)


def odometry_covariances(s: SessionPoses, conf: MapConfig) -> np.ndarray:
    """(n, 6, 6) every step's :func:`odometry_covariance` at once (row 0 unused): a session of thousands of
    steps is read at every append that judges it, and the checks one matrix at a time cost milliseconds."""
    cov = np.asarray(s.cov, float).reshape(-1, 6, 6)
    out = np.repeat(np.diag(ODOM_SIGMAS ** 2)[None], len(cov), 0)
    ok = valid_informations(cov)
    out[ok] = cov[ok]
    for i in range(1, len(cov)):
        if is_modelled(s, i):
            out[i] = allowance(inv(s.T_odom[i - 1]) @ s.T_odom[i], conf)
    return out


def odometry_factors(s: SessionPoses, conf: MapConfig, weights: np.ndarray | None = None) -> list:
    """Session ``s``'s odometry steps between its variables as factors (a step to or from a folded keyframe has
    none), step i's covariance divided by ``weights[i]`` (default 1)."""
    live = s.in_graph()
    both = np.flatnonzero(live[1:] & live[:-1]) + 1
    if not len(both):
        return []
    covs = odometry_covariances(s, conf)
    w = np.ones(len(s.ids)) if weights is None else weights
    steps = inv(s.T_odom[:-1]) @ s.T_odom[1:]
    return [gtsam.BetweenFactorPose3(int(s.ids[i - 1]), int(s.ids[i]), gtsam.Pose3(steps[i - 1]),
                                     gtsam.noiseModel.Gaussian.Covariance(covs[i] / w[i])) for i in both]


def between(lp: JointLoop, scale: float = 1.0) -> gtsam.BetweenFactorPose3:
    """A loop's factor ``T_match_query``, its information times ``scale``."""
    return gtsam.BetweenFactorPose3(lp.match, lp.query, gtsam.Pose3(lp.T), information_noise(lp.info, scale))
