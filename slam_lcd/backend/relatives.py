"""Relative poses and covariances of a user's GTSAM graph, for the gate (:mod:`slam_lcd.backend.gate`).

A user's graph has no odometry chain we know of, so both questions the gate asks (current
estimate, loop-free relative pose) are answered from the user's estimate and its marginals:

- from a ``gtsam.ISAM2``: ``calculateEstimatePose3`` and ``marginalCovariance`` per key; the
  cross-covariance of the two poses is ignored (over-states the relative uncertainty for
  positively correlated poses: a lenient, never a stricter, gate);
- from a ``gtsam.Marginals`` (+ the values it was built at): the joint marginal of the two
  keys, so the relative covariance is exact to first order.

``key(position)`` maps the gate's integer positions to GTSAM keys.
"""
from __future__ import annotations

from collections.abc import Callable

import gtsam
import numpy as np

from .gate import relative_from_marginals


class MarginalRelatives:
    """Gate relatives from an ``ISAM2`` (or a ``Marginals`` with its ``Values``)."""

    def __init__(self, key: Callable[[int], int], isam: gtsam.ISAM2 | None = None,
                 marginals: gtsam.Marginals | None = None, values: gtsam.Values | None = None):
        if (isam is None) == (marginals is None):
            raise ValueError("give exactly one of isam or marginals")
        if marginals is not None and values is None:
            raise ValueError("marginals need the values they were computed at")
        self.key, self.isam, self.marginals, self.values = key, isam, marginals, values

    def _pose(self, k: int) -> np.ndarray:
        if self.isam is not None:
            return self.isam.calculateEstimatePose3(k).matrix()
        assert self.values is not None  # marginals come with their values (__init__)
        return self.values.atPose3(k).matrix()

    def estimate(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        ka, kb = self.key(a), self.key(b)
        Xa, Xb = self._pose(ka), self._pose(kb)
        if self.isam is not None:
            return relative_from_marginals(Xa, Xb, self.isam.marginalCovariance(ka), self.isam.marginalCovariance(kb))
        assert self.marginals is not None  # exactly one of isam and marginals (__init__)
        J = self.marginals.jointMarginalCovariance(gtsam.KeyVector([ka, kb])).fullMatrix()
        return relative_from_marginals(Xa, Xb, J[:6, :6], J[6:, 6:], J[:6, 6:])

    odometry = estimate
