"""SE(3) / SO(3) / quaternion helpers on numpy arrays, shared by every stage (no gtsam here).

Conventions (the same everywhere in slam-lcd):

* poses are 4x4 float64 ``T_a_b``; most helpers also take a stack ``(..., 4, 4)``;
* quaternions are ``(x, y, z, w)`` (ROS / scipy order);
* tangent vectors are ``[omega, v]`` (rotation first), exactly like ``gtsam.Pose3``, with
  perturbations on the right: ``T = T_hat @ Exp(xi)``; the adjoint is
  ``Ad(T) = [[R, 0], [skew(t) R, R]]`` so that ``T Exp(xi) T^-1 = Exp(Ad(T) xi)``;
  covariances therefore live in the body frame of the pose they belong to, and relative
  motions compose with the adjoint (:func:`compose_covariance`, :func:`relative_covariance`,
  :func:`transform_covariance`).

This is the one SE(3) module: every stage, the back end included, uses it.
"""
from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation, Slerp

from .errors import ConfigError, InvalidPoseError

# ----------------------------------------------------------------------------- rigid transforms


def inv(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (or a stack of them)."""
    T = np.asarray(T, dtype=np.float64)
    out = np.zeros_like(T)
    R = T[..., :3, :3]
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3:4])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def make_T(R: np.ndarray, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """Closest rotation matrix (Frobenius norm) to nearly orthonormal 3x3 matrix/matrices."""
    u, _, vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(u @ vt))
    D = np.zeros(np.shape(M))
    D[..., 0, 0] = 1.0
    D[..., 1, 1] = 1.0
    D[..., 2, 2] = d
    return u @ D @ vt


def project_to_se3(T: np.ndarray) -> np.ndarray:
    """Nearest proper rigid transform (re-orthonormalises the rotation block)."""
    T = np.asarray(T, dtype=np.float64)
    return make_T(nearest_rotation(T[:3, :3]), T[:3, 3])


# ----------------------------------------------------------------------------- SO(3)


def skew(w: np.ndarray) -> np.ndarray:
    """3x3 cross-product matrix ``[w]x``."""
    x, y, z = np.asarray(w, dtype=np.float64).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def rotation_angle(R: np.ndarray):
    """Angle (rad) of one rotation matrix (a float) or of a stack ``(..., 3, 3)`` (an array).

    Only the top-left 3x3 block is read, so 4x4 poses work too. ``atan2(sin, cos)`` stays
    accurate for tiny angles, where ``arccos`` of the trace loses ~1e-8 rad.
    """
    R = np.asarray(R)[..., :3, :3]
    cos = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    axis = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    sin = np.linalg.norm(axis, axis=-1) / 2.0
    ang = np.arctan2(sin, cos)
    return float(ang) if np.ndim(ang) == 0 else ang


def rotation_angle_deg(R: np.ndarray):
    """Angle (degrees) of one rotation matrix (a float) or of a stack (an array); see :func:`rotation_angle`."""
    ang = np.degrees(rotation_angle(R))
    return float(ang) if np.ndim(ang) == 0 else ang


def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrix ``Exp(w)`` of a rotation vector (Rodrigues)."""
    w = np.asarray(w, dtype=np.float64).reshape(3)
    th = np.linalg.norm(w)
    K = skew(w)
    if th < 1e-10:
        return np.eye(3) + K
    return np.eye(3) + np.sin(th) / th * K + (1 - np.cos(th)) / th**2 * (K @ K)


def so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector ``Log(R)``; exact near 0 and near pi."""
    c = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    th = np.arccos(c)
    v = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if th < 1e-8:
        return 0.5 * v
    if np.pi - th < 1e-4:  # near pi: the axis from the symmetric part cos^2(th/2) I + sin^2(th/2) a a^T
        B = (R + R.T) / 4.0 + 0.5 * np.eye(3)
        axis = np.sqrt(np.maximum(np.diag(B), 0.0))
        i = int(np.argmax(axis))
        axis = B[i] / max(axis[i], 1e-12)
        axis /= np.linalg.norm(axis)
        if axis @ v < 0:
            axis = -axis
        return axis * th
    return th / (2 * np.sin(th)) * v


# ----------------------------------------------------------------------------- SE(3) Lie algebra


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """``Exp([omega, v])`` as a 4x4 matrix (GTSAM Pose3::Expmap)."""
    xi = np.asarray(xi, dtype=np.float64).reshape(6)
    w, v = xi[:3], xi[3:]
    th = np.linalg.norm(w)
    K = skew(w)
    if th < 1e-10:
        V = np.eye(3) + 0.5 * K
    else:
        V = np.eye(3) + (1 - np.cos(th)) / th**2 * K + (th - np.sin(th)) / th**3 * (K @ K)
    T = np.eye(4)
    T[:3, :3] = so3_exp(w)
    T[:3, 3] = V @ v
    return T


def se3_log(T: np.ndarray) -> np.ndarray:
    """``Log(T)`` as ``[omega, v]`` (GTSAM Pose3::Logmap)."""
    w = so3_log(T[:3, :3])
    th = np.linalg.norm(w)
    K = skew(w)
    if th < 1e-3:  # series: the closed form below cancels catastrophically for small angles
        Vinv = np.eye(3) - 0.5 * K + (1.0 / 12.0 + th**2 / 720.0) * (K @ K)
    else:
        Vinv = np.eye(3) - 0.5 * K + (1 / th**2) * (1 - (th * np.sin(th)) / (2 * (1 - np.cos(th)))) * (K @ K)
    return np.concatenate([w, Vinv @ T[:3, 3]])


def adjoint(T: np.ndarray) -> np.ndarray:
    """Adjoint of one 4x4 or a stack (..., 4, 4) in [rot, trans] order: ``[[R, 0], [t^ R, R]]``."""
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    tx = np.zeros(T.shape[:-2] + (3, 3))
    tx[..., 0, 1], tx[..., 0, 2] = -t[..., 2], t[..., 1]
    tx[..., 1, 0], tx[..., 1, 2] = t[..., 2], -t[..., 0]
    tx[..., 2, 0], tx[..., 2, 1] = -t[..., 1], t[..., 0]
    A = np.zeros(T.shape[:-2] + (6, 6))
    A[..., :3, :3] = R
    A[..., 3:, 3:] = R
    A[..., 3:, :3] = tx @ R
    return A


# ----------------------------------------------------------------------------- quaternions (x, y, z, w)


def quat_to_rot(q_xyzw: npt.ArrayLike) -> np.ndarray:
    """Quaternion(s) ``(x, y, z, w)``, shape (4,) or (..., 4), normalised first -> rotation matrix/matrices."""
    q = np.asarray(q_xyzw, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - z * w)
    R[..., 0, 2] = 2 * (x * z + y * w)
    R[..., 1, 0] = 2 * (x * y + z * w)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - x * w)
    R[..., 2, 0] = 2 * (x * z - y * w)
    R[..., 2, 1] = 2 * (y * z + x * w)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def rot_to_quat(R: np.ndarray, w_nonnegative: bool = False) -> np.ndarray:
    """Rotation matrix/matrices (3, 3) or (N, 3, 3) -> unit quaternion(s) (x, y, z, w).

    Shepperd's method: of the four algebraically equal formulas, each matrix uses the one
    dividing by its largest quaternion component (which comes out positive), so every angle
    (180° included) is exact. ``w_nonnegative`` flips the sign of those with ``w < 0``.
    """
    m = np.asarray(R, dtype=np.float64)
    single = m.ndim == 2
    if single and m.shape == (3, 3):
        q1 = _rot_to_quat_one(m.tolist())
        if q1 is not None:
            if w_nonnegative and q1[3] < 0:
                q1 = [-v for v in q1]
            return np.array(q1)
    m = m.reshape(-1, 3, 3)
    d0, d1, d2 = m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]
    tr = d0 + d1 + d2
    cands = np.stack([tr, d0, d1, d2], axis=1)
    case = np.argmax(cands, axis=1)
    q = np.empty((len(m), 4))
    with np.errstate(invalid="ignore", divide="ignore"):
        s = 2.0 * np.sqrt(np.maximum(1.0 + np.choose(case, [tr, 2 * d0 - tr, 2 * d1 - tr, 2 * d2 - tr]), 0.0))
        a21, a12 = m[:, 2, 1], m[:, 1, 2]
        a02, a20 = m[:, 0, 2], m[:, 2, 0]
        a10, a01 = m[:, 1, 0], m[:, 0, 1]
        cases = [
            np.stack([(a21 - a12) / s, (a02 - a20) / s, (a10 - a01) / s, 0.25 * s], axis=1),
            np.stack([0.25 * s, (a01 + a10) / s, (a02 + a20) / s, (a21 - a12) / s], axis=1),
            np.stack([(a01 + a10) / s, 0.25 * s, (a12 + a21) / s, (a02 - a20) / s], axis=1),
            np.stack([(a02 + a20) / s, (a12 + a21) / s, 0.25 * s, (a10 - a01) / s], axis=1),
        ]
    for k in range(4):
        sel = case == k
        q[sel] = cases[k][sel]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    if w_nonnegative:
        q[q[:, 3] < 0] *= -1.0
    return q[0] if single else q


def _rot_to_quat_one(m: list) -> list | None:
    """:func:`rot_to_quat` of one matrix (nested lists) in plain floats: the same operations in
    the same order, so the same bits, ~50x faster than the array path for a single pose (a log
    writer converts one pose per message). None where the array path must decide (s == 0)."""
    (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = m
    tr = a00 + a11 + a22
    cands = (tr, a00, a11, a22)
    case = max(range(4), key=lambda k: (cands[k], -k))  # np.argmax: the first of equal maxima
    val = (tr, 2 * a00 - tr, 2 * a11 - tr, 2 * a22 - tr)[case]
    s = 2.0 * math.sqrt(max(1.0 + val, 0.0))
    if not s > 0.0:
        return None
    if case == 0:
        q = [(a21 - a12) / s, (a02 - a20) / s, (a10 - a01) / s, 0.25 * s]
    elif case == 1:
        q = [0.25 * s, (a01 + a10) / s, (a02 + a20) / s, (a21 - a12) / s]
    elif case == 2:
        q = [(a01 + a10) / s, 0.25 * s, (a12 + a21) / s, (a02 - a20) / s]
    else:
        q = [(a02 + a20) / s, (a12 + a21) / s, 0.25 * s, (a10 - a01) / s]
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return [v / n for v in q]


def quat_slerp(q0: np.ndarray, q1: np.ndarray, a: float) -> np.ndarray:
    """Spherical interpolation between unit quaternions (x, y, z, w), shortest arc."""
    d = float(np.dot(q0, q1))
    if d < 0:
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + a * (q1 - q0)
        return q / np.linalg.norm(q)
    th = math.acos(min(1.0, d))
    s = math.sin(th)
    return (math.sin((1 - a) * th) / s) * q0 + (math.sin(a * th) / s) * q1


def pose_from_list(values, where: str = "frontend.T_body_camera") -> np.ndarray:
    """A 4x4 pose from 16 row-major numbers or 7 numbers ``x y z qx qy qz qw``."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if v.size == 16:
        T = v.reshape(4, 4)
        if not np.allclose(T[3], [0, 0, 0, 1]) or not np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-6):
            raise ConfigError(f"{where}: 16 numbers must form a rigid transform (row-major 4x4)")
        return T
    if v.size == 7:
        q = v[3:]
        if np.linalg.norm(q) < 1e-9:
            raise ConfigError(f"{where}: zero quaternion")
        T = np.eye(4)
        T[:3, :3] = quat_to_rot(q)
        T[:3, 3] = v[:3]
        return T
    raise ConfigError(f"{where}: expected 16 numbers (4x4 row-major) or 7 (x y z qx qy qz qw), got {v.size}")


# ----------------------------------------------------------------------------- trajectories


def interpolate_poses(stamps: np.ndarray, poses: np.ndarray, query: np.ndarray) -> np.ndarray:
    """SE(3) interpolation (slerp rotation, linear translation) of ``poses`` at ``query`` stamps.

    Query stamps outside the range are clamped to the first/last pose. ``stamps`` must not
    decrease; a repeated stamp (real ground-truth files have them) counts with its first pose.
    """
    stamps = np.asarray(stamps, dtype=np.int64)
    query = np.asarray(query, dtype=np.int64)
    if len(stamps) > 1:
        first = np.ones(len(stamps), bool)
        first[1:] = stamps[1:] != stamps[:-1]
        if not first.all():
            stamps, poses = stamps[first], np.asarray(poses)[first]
    if len(stamps) == 1:
        return np.repeat(poses[:1], len(query), axis=0)
    if len(stamps) == 2 and len(query) == 1:  # the per-frame case of a stream: no scipy set-up
        span = float(stamps[1] - stamps[0])
        a = min(max(float(query[0] - stamps[0]) / span, 0.0), 1.0) if span > 0 else 0.0
        P0, P1 = np.asarray(poses[0], np.float64), np.asarray(poses[1], np.float64)
        out = np.eye(4)[None].copy()
        out[0, :3, :3] = P0[:3, :3] @ so3_exp(a * so3_log(P0[:3, :3].T @ P1[:3, :3]))
        out[0, :3, 3] = (1.0 - a) * P0[:3, 3] + a * P1[:3, 3]
        return out
    t0 = stamps[0]
    x = (stamps - t0).astype(np.float64)
    q = np.clip((query - t0).astype(np.float64), x[0], x[-1])
    rots = Rotation.from_matrix(poses[:, :3, :3])
    out = np.repeat(np.eye(4)[None], len(query), axis=0)
    out[:, :3, :3] = Slerp(x, rots)(q).as_matrix()
    for k in range(3):
        out[:, k, 3] = np.interp(q, x, poses[:, k, 3])
    return out


# ----------------------------------------------------------------------------- covariances
# permutation from ROS [x y z rx ry rz] to GTSAM [rx ry rz tx ty tz]
ROS_TO_GTSAM_ORDER = np.array([3, 4, 5, 0, 1, 2])


def ros_covariance_to_gtsam(cov, T_world_body, frame: str = "parent") -> np.ndarray | None:
    """A ROS 6x6 pose covariance → the 6x6 covariance slam-lcd (GTSAM ``Pose3``) expects.

    ROS (``geometry_msgs/PoseWithCovariance``, ``nav_msgs/Odometry.pose``) orders it
    ``[x y z rx ry rz]`` (translation first) about the *parent* frame's axes; GTSAM orders the
    tangent ``[rx ry rz tx ty tz]`` (rotation first) about the *body* axes (right perturbation
    ``T Exp(xi)``). Passing a ROS covariance unconverted swaps the rotation and translation
    blocks: silently wrong, hence this helper. ``cov``: 36 values or 6x6; ``T_world_body``:
    the pose the covariance belongs to (4x4, or its 3x3 rotation); ``frame='body'`` when the
    covariance is already about the body axes (only the order changes). Returns None for ROS's
    "unknown" conventions (all zeros, or ``cov[0] == -1``).
    """
    c = np.asarray(cov, dtype=np.float64).reshape(6, 6)
    if not c.any() or c[0, 0] == -1:
        return None
    if not np.all(np.isfinite(c)):
        raise InvalidPoseError("covariance has NaN/inf values")
    if frame not in ("parent", "body"):
        raise ValueError(f"frame must be 'parent' or 'body', got {frame!r}")
    c = c[np.ix_(ROS_TO_GTSAM_ORDER, ROS_TO_GTSAM_ORDER)]
    if frame == "body":
        return c
    R = np.asarray(T_world_body, dtype=np.float64)[:3, :3]
    J = np.zeros((6, 6))
    J[:3, :3] = R.T
    J[3:, 3:] = R.T
    return J @ c @ J.T


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
