"""One loop closure as a GTSAM factor: ``BetweenFactorPose3`` with the noise of its information.

Convention, stated once: a :class:`~slam_lcd.types.LoopClosure` carries ``T_match_query``,
the pose of the query keyframe's **body** frame in the match keyframe's body frame (maps
query-body points into the match body frame). Its ``information`` is the 6x6 inverse
covariance of the right perturbation ``T_match_query * Exp(xi)``, ``xi`` in GTSAM's
``Pose3`` tangent order ``[rx ry rz tx ty tz]`` (radians, metres). That is exactly what
``gtsam.BetweenFactorPose3(key_match, key_query, Pose3(T_match_query), noise)`` measures, so
the factor is that one with a Gaussian (optionally robust) noise model from the information.

Body vs camera: the detector converts the camera-frame PnP solution into body frames with
each keyframe's ``T_body_camera``; a user whose graph holds camera poses passes
``T_body_camera = I`` on their keyframes (or converts with :func:`slam_lcd.backend.loop_factors.camera_frame_closure`).

Why a base module: :class:`~slam_lcd.types.LoopClosure` builds its own factor
(:meth:`~slam_lcd.types.LoopClosure.between_factor`), and ``types`` imports nothing above the
base modules. GTSAM is imported inside the functions, so importing this module costs numpy
only; :mod:`slam_lcd.backend.loop_factors` re-exports these names beside the graph-level ones.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .errors import InputError

if TYPE_CHECKING:
    import gtsam

KERNELS = ("none", "huber", "cauchy", "dcs", "geman_mcclure")


def robust_kernel(kind: str, width: float):
    """The mEstimator for a kernel name (None for 'none'); ``width`` on the whitened error."""
    import gtsam  # lazy: every stage imports slam_lcd.types, which imports this module

    M = gtsam.noiseModel.mEstimator
    if kind == "none":
        return None
    if kind == "huber":
        return M.Huber.Create(width)
    if kind == "cauchy":
        return M.Cauchy.Create(width)
    if kind == "dcs":
        return M.DCS.Create(width)
    if kind == "geman_mcclure":
        return M.GemanMcClure.Create(width)
    raise InputError(f"unknown robust kernel {kind!r} ({', '.join(KERNELS)})")


def valid_information(M) -> bool:
    """A finite, symmetric, positive definite 6x6 matrix."""
    if M is None:
        return False
    M = np.asarray(M, dtype=np.float64)
    if M.shape != (6, 6) or not np.all(np.isfinite(M)) or not np.allclose(M, M.T, rtol=1e-6, atol=1e-9):
        return False
    try:
        np.linalg.cholesky(M)
    except np.linalg.LinAlgError:
        return False
    return True


def valid_informations(M: np.ndarray) -> np.ndarray:
    """(n,) bool: :func:`valid_information` of each of ``n`` 6x6 matrices, at once (a session's steps)."""
    M = np.asarray(M, dtype=np.float64).reshape(-1, 6, 6)
    Mt = M.transpose(0, 2, 1)
    ok = np.all(np.isfinite(M), axis=(1, 2))
    ok[ok] = np.all(np.abs(M[ok] - Mt[ok]) <= 1e-9 + 1e-6 * np.abs(Mt[ok]), axis=(1, 2))
    if ok.any():
        ok[ok] = np.linalg.eigvalsh(0.5 * (M[ok] + Mt[ok]))[:, 0] > 0
    return ok


def loop_noise(information, kernel=None, kernel_width: float = 3.0):
    """Gaussian noise model from a 6x6 information matrix, wrapped in a robust kernel when one is named.

    ``kernel``: None / 'none', a kernel name (see :data:`KERNELS`) or a ``gtsam.noiseModel.mEstimator``.
    """
    if not valid_information(information):
        raise InputError("loop information is missing or not a symmetric positive definite 6x6 matrix")
    import gtsam  # lazy: as in robust_kernel

    info = np.asarray(information, dtype=np.float64)
    gaussian = gtsam.noiseModel.Gaussian.Information(0.5 * (info + info.T))
    if kernel is None or (isinstance(kernel, str) and kernel == "none"):
        return gaussian
    m = robust_kernel(kernel, kernel_width) if isinstance(kernel, str) else kernel
    return gtsam.noiseModel.Robust.Create(m, gaussian)


def between_factor(closure, key_match: int, key_query: int, *, kernel=None,
                   kernel_width: float = 3.0) -> gtsam.BetweenFactorPose3:
    """``BetweenFactorPose3(key_match, key_query, T_match_query)`` with the closure's information.

    Keys are any GTSAM keys (``gtsam.symbol('x', i)``, ``X(i)``, plain ints). Raises
    :class:`~slam_lcd.errors.InputError` for a closure without a finite pose or a positive
    definite information matrix (a failed pose estimate must not become a factor).
    """
    T = np.asarray(closure.T_match_query, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError(f"loop {closure.match_id}->{closure.query_id} has no metric pose (T_match_query)")
    import gtsam  # lazy: as in robust_kernel

    noise = loop_noise(closure.information, kernel, kernel_width)
    return gtsam.BetweenFactorPose3(int(key_match), int(key_query), gtsam.Pose3(T), noise)
