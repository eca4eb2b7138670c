"""Wheel-odometry simulation: ground-truth increments corrupted by noise and slowly varying biases.

Error model per step (planar robot, increments in the body frame of the previous step):

- ``dx, dy`` scaled by ``1 + k(t)``, where the scale error ``k`` is a constant (drawn per
  seed, a wheel-radius error of 1-3 %) plus a first-order Gauss-Markov wander;
- ``dyaw`` scaled by ``1 + e`` (a wheel-base error of 1-3 %, the classic systematic error of
  differential drives) plus ``b(t) dt``, where the yaw-rate bias ``b`` is a constant plus a
  Gauss-Markov wander. The constant is chosen per run (from a grid, preferring the sign
  drawn from the seed) so that the noise-free odometry with the scale errors ends
  ``drift_target`` (2-4.5 %, drawn from the seed) of the distance away from the truth:
  closed loops hide most heading error (a loop rotated about its centre ends near its
  start), so a fixed gyro-like bias would give 0.5 % on one path and 5 % on another. Its
  magnitude is at most 0.5 deg/s;
- white noise on every increment, growing with the distance and angle travelled.

So the odometry drifts clearly: a few percent of the distance after two laps.

Covariance is propagated honestly with a planar EKF. The biases cannot be white noise,
but a bias with standard deviation ``s`` acting over a run of length ``T`` gives an
error variance ``(s T)^2``; the equivalent white noise ``2 s^2 tau dt`` with
``tau = T_run / 2`` gives the same variance at ``T_run`` (and more before it), which is
what we add to each step. ``simulate_odometry`` reports the end error against the
propagated standard deviation so that this can be checked.

Published covariances (``Trajectory.covariances``) are the accumulated pose covariance in
GTSAM order ``[rx ry rz tx ty tz]`` in the body frame (right perturbation ``T Exp(xi)``).
The z, roll and pitch entries get a tiny variance (the robot is planar and these are exact).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..types import Trajectory

FLAT_VAR = 1e-8  # variance given to z, roll, pitch (exactly known for a planar robot)


@dataclass
class OdometryNoise:
    """Parameters of the odometry error model (units: m, rad, s)."""

    trans_white: float = 0.01  # m per sqrt(m) of travel, on each of dx, dy
    rot_white: float = np.radians(0.3)  # rad per sqrt(m) of travel
    rot_white_per_rad: float = 0.01  # rad per sqrt(rad) of rotation
    scale_bias_range: tuple[float, float] = (0.01, 0.03)  # |constant scale error|
    scale_wander: float = 0.005  # std of the Gauss-Markov part of the scale error
    drift_target: tuple[float, float] = (0.02, 0.045)  # end drift (fraction of distance) the yaw bias aims at
    yaw_bias_max: float = np.radians(0.5)  # largest |constant yaw-rate bias| rad/s
    rot_scale_range: tuple[float, float] = (0.01, 0.03)  # |wheel-base (rotation scale) error|
    yaw_wander: float = np.radians(0.05)  # rad/s std of the Gauss-Markov part
    wander_tau: float = 20.0  # s, correlation time of the Gauss-Markov parts


def _yaw(T: np.ndarray) -> np.ndarray:
    return np.arctan2(T[..., 1, 0], T[..., 0, 0])


def _gauss_markov(rng, n: int, dt: float, sigma: float, tau: float) -> np.ndarray:
    a = np.exp(-dt / tau)
    w = rng.normal(0.0, sigma * np.sqrt(1 - a * a), size=n)
    x = np.empty(n)
    x[0] = rng.normal(0.0, sigma)
    for i in range(1, n):
        x[i] = a * x[i - 1] + w[i]
    return x


def _noise_free_end(biases, x0, y0, th0, dx, dy, dth, dt) -> np.ndarray:
    """End positions (B, 2) of dead reckoning with each constant yaw-rate bias in ``biases``."""
    turned = np.cumsum(dth[None] + biases[:, None] * dt[None], axis=1)
    th = th0 + np.concatenate([np.zeros((len(biases), 1)), turned], 1)[:, :-1]
    c, s = np.cos(th), np.sin(th)
    return np.column_stack([x0 + (c * dx - s * dy).sum(1), y0 + (s * dx + c * dy).sum(1)])


def simulate_odometry(gt: Trajectory, seed: int = 0, noise: OdometryNoise | None = None,
                      frame_id: str = "odom", child_frame_id: str = "base_link",
                      start_at_identity: bool = False) -> Trajectory:
    """Drifting odometry from a planar ground-truth body trajectory (same stamps).

    The odometry frame coincides with the world frame at the first stamp (the first pose
    is exact). ``start_at_identity``: instead, the robot's start pose is the origin of its
    odometry frame (the first pose is the identity), as a robot switched on somewhere
    reports it; the errors are the same, the whole trajectory is only re-expressed in the
    start's frame (``T_world_body0^-1 @ T_odom_body``; the body-frame covariances do not
    change). Returns a Trajectory with accumulated covariances (see module docstring).
    """
    nz = noise or OdometryNoise()
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x0D0]))
    n = len(gt)
    if n < 2:
        raise ValueError("odometry needs at least two ground-truth poses")
    t = gt.times_s - gt.times_s[0]
    dt = np.diff(t)
    x, y, th = gt.poses[:, 0, 3], gt.poses[:, 1, 3], np.unwrap(_yaw(gt.poses))
    # true body-frame increments
    c, s = np.cos(th[:-1]), np.sin(th[:-1])
    dxw, dyw = np.diff(x), np.diff(y)
    dx, dy, dth = c * dxw + s * dyw, -s * dxw + c * dyw, np.diff(th)
    dist = np.hypot(dx, dy)

    # biases
    sign = rng.choice([-1.0, 1.0], size=3)
    k0 = sign[0] * rng.uniform(*nz.scale_bias_range)
    e0 = sign[2] * rng.uniform(*nz.rot_scale_range)
    target = rng.uniform(*nz.drift_target) * float(dist.sum())
    grid = np.linspace(-nz.yaw_bias_max, nz.yaw_bias_max, 81)
    ends = _noise_free_end(grid, x[0], y[0], th[0], dx * (1 + k0), dy * (1 + k0), dth * (1 + e0), dt)
    miss = np.abs(np.hypot(ends[:, 0] - x[-1], ends[:, 1] - y[-1]) - target)
    miss[np.sign(grid) != sign[1]] += 0.3 * target  # prefer the drawn sign when it can do it
    b0 = float(grid[int(np.argmin(miss))])
    b_mag = abs(b0)
    mdt = float(np.mean(dt))
    k = k0 + _gauss_markov(rng, n - 1, mdt, nz.scale_wander, nz.wander_tau)
    b = b0 + _gauss_markov(rng, n - 1, mdt, nz.yaw_wander, nz.wander_tau)

    # white noise
    sig_t = nz.trans_white * np.sqrt(dist)
    sig_r = np.sqrt(nz.rot_white ** 2 * dist + nz.rot_white_per_rad ** 2 * np.abs(dth))
    mdx = dx * (1 + k) + rng.normal(0.0, 1.0, n - 1) * sig_t
    mdy = dy * (1 + k) + rng.normal(0.0, 1.0, n - 1) * sig_t
    mdth = dth * (1 + e0) + b * dt + rng.normal(0.0, 1.0, n - 1) * sig_r

    # equivalent white noise of the biases over this run (tau = T_run / 2, see docstring)
    tau_eq = max(t[-1] / 2.0, 1.0)
    lo, hi = nz.scale_bias_range
    k_rms = np.sqrt((hi ** 3 - lo ** 3) / (3 * (hi - lo)) + nz.scale_wander ** 2)
    b_rms = np.sqrt(b_mag ** 2 + nz.yaw_wander ** 2)  # the bias size this odometry is known to have
    lo, hi = nz.rot_scale_range
    e_rms = np.sqrt((hi ** 3 - lo ** 3) / (3 * (hi - lo)))
    speed2 = (dist / np.maximum(dt, 1e-9)) ** 2
    q_t = sig_t ** 2 + 2 * k_rms ** 2 * tau_eq * speed2 * dt
    q_r = sig_r ** 2 + 2 * b_rms ** 2 * tau_eq * dt + (e_rms * dth) ** 2

    # integrate and propagate the planar covariance (world frame: X, Y, theta)
    ox, oy, oth = np.empty(n), np.empty(n), np.empty(n)
    ox[0], oy[0], oth[0] = x[0], y[0], th[0]
    P = np.zeros((3, 3))
    covs = np.zeros((n, 6, 6))
    covs[0] = np.diag([FLAT_VAR, FLAT_VAR, 1e-10, 1e-10, 1e-10, FLAT_VAR])
    for i in range(n - 1):
        ci, si = np.cos(oth[i]), np.sin(oth[i])
        ox[i + 1] = ox[i] + ci * mdx[i] - si * mdy[i]
        oy[i + 1] = oy[i] + si * mdx[i] + ci * mdy[i]
        oth[i + 1] = oth[i] + mdth[i]
        F = np.array([[1.0, 0.0, -si * mdx[i] - ci * mdy[i]], [0.0, 1.0, ci * mdx[i] - si * mdy[i]], [0.0, 0.0, 1.0]])
        G = np.array([[ci, -si, 0.0], [si, ci, 0.0], [0.0, 0.0, 1.0]])
        Q = np.diag([q_t[i], q_t[i], q_r[i]])
        P = F @ P @ F.T + G @ Q @ G.T
        # to the body frame: translation rotated by R(theta)^T; order [rx ry rz tx ty tz]
        c2, s2 = np.cos(oth[i + 1]), np.sin(oth[i + 1])
        J = np.array([[0.0, 0.0, 1.0], [c2, s2, 0.0], [-s2, c2, 0.0]])  # (rz, tx, ty) from (X, Y, th)
        Pb = J @ P @ J.T
        C = np.diag([FLAT_VAR, FLAT_VAR, 0.0, 0.0, 0.0, FLAT_VAR])
        sel = [2, 3, 4]
        C[np.ix_(sel, sel)] = Pb
        covs[i + 1] = C + np.diag([0, 0, 1e-10, 1e-10, 1e-10, 0])
    poses = np.repeat(np.eye(4)[None], n, axis=0)
    cth, sth = np.cos(oth), np.sin(oth)
    poses[:, 0, 0], poses[:, 0, 1], poses[:, 1, 0], poses[:, 1, 1] = cth, -sth, sth, cth
    poses[:, 0, 3], poses[:, 1, 3] = ox, oy
    if start_at_identity:
        poses = np.linalg.inv(gt.poses[0]) @ poses
        poses[0] = np.eye(4)  # exactly, not up to rounding
    return Trajectory(stamps=gt.stamps.copy(), poses=poses, covariances=covs, frame_id=frame_id,
                      child_frame_id=child_frame_id)


def open_route(rate_hz: float, length_m: float = 65.0, speed: float = 1.0, lateral: float = 0.0) -> Trajectory:
    """Ground truth of a gently winding open route (x forward, ``y = 4 sin(x / 10) + lateral`` m) sampled at
    ``rate_hz``: the drive the odometry model's calibration and the covariance tests use."""
    n = int(length_m / speed * rate_hz) + 1
    t = np.arange(n) / rate_hz
    x = speed * t
    y = 4.0 * np.sin(x / 10.0) + lateral
    th = np.arctan2(np.gradient(y), np.gradient(x))
    P = np.repeat(np.eye(4)[None], n, 0)
    P[:, 0, 0], P[:, 0, 1], P[:, 1, 0], P[:, 1, 1] = np.cos(th), -np.sin(th), np.sin(th), np.cos(th)
    P[:, 0, 3], P[:, 1, 3] = x, y
    return Trajectory(np.round(t * 1e9).astype(np.int64), P)


def end_drift(gt: Trajectory, odom: Trajectory) -> dict:
    """End-point drift of ``odom`` against ``gt`` (same stamps, unaligned: the frames coincide at start).

    When the first poses differ (an odometry in its own frame,
    ``simulate_odometry(start_at_identity=True)``), the ground truth is first moved so that
    the two coincide at the first stamp.
    """
    if not np.array_equal(odom.poses[0], gt.poses[0]):
        gt = Trajectory(stamps=gt.stamps, poses=odom.poses[0] @ np.linalg.inv(gt.poses[0]) @ gt.poses)
    err = float(np.linalg.norm(odom.positions[-1] - gt.positions[-1]))
    length = gt.path_length()
    dyaw = float(np.degrees(np.angle(np.exp(1j * (_yaw(odom.poses[-1]) - _yaw(gt.poses[-1]))))))
    cov = odom.covariances[-1] if odom.covariances is not None else None
    sigma = float(np.sqrt(cov[3, 3] + cov[4, 4])) if cov is not None else float("nan")
    return {"end_error_m": err, "path_length_m": length, "drift_percent": 100.0 * err / max(length, 1e-9),
            "end_yaw_error_deg": dyaw, "end_sigma_m": sigma,
            "error_over_sigma": err / sigma if sigma > 0 else float("nan")}
