"""evo's APE and RPE with every pose relation, pair rule and alignment (``slam-lcd ate``).

Why a second module beside :mod:`.metrics`: ``metrics.ate`` is the project's before/after
figure (translation and rotation together); this module reproduces evo's command-line
metrics one relation at a time, with evo's meanings, so that ``slam-lcd ate`` and
``evo_ape``/``evo_rpe`` give the same numbers for the same flags:

- APE error pose ``E_i = P_est,i^-1 P_ref,i``; RPE ``E_ij = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)``
  (Q reference, P estimate);
- relations: ``trans_part`` |t(E)| (APE: |p_est - p_ref|), ``rot_part`` ||R(E) - I||_F,
  ``full`` ||E - I||_F, ``angle_deg``/``angle_rad`` the rotation-vector norm of R(E) (scipy,
  as evo), ``point_distance`` (APE: as trans_part; RPE: | |q_i - q_j| - |p_i - p_j| |) and,
  RPE only, ``point_distance_error_ratio`` (that difference in % of |q_i - q_j|; pairs with
  zero reference distance are dropped);
- RPE pairs: ``delta`` in frames (``f``), metres travelled (``m``), or degrees/radians
  (``d``/``r``) of rotation; consecutive pairs, or with ``all_pairs`` every start index whose
  best partner is within ``rel_delta_tol * delta``; chosen on the **estimate** unless
  ``pairs_from_reference`` (evo's default; the estimate is aligned first);
- alignment before the metric: Umeyama SE(3) / Sim(3) / scale only on the first
  ``n_to_align`` matched poses, or ``align_origin`` (the estimate's first pose moved onto the
  reference's), as evo orders them (scale, then origin).

Association is :func:`.associate.associate` (evo's nearest-stamp rule on exact integer
nanoseconds).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geometry import inv
from ..types import Trajectory
from .align import Alignment, fit_alignment
from .associate import associate
from .errors import AlignmentError, AssociationError
from .relation_names import APE_RELATIONS, RPE_RELATIONS

RELATION_UNITS = {"full": "", "trans_part": "m", "rot_part": "", "angle_deg": "deg", "angle_rad": "rad",
                  "point_distance": "m", "point_distance_error_ratio": "%"}
RELATION_TITLES = {  # evo's PoseRelation values (used in titles and saved results)
    "full": "full transformation", "trans_part": "translation part", "rot_part": "rotation part",
    "angle_deg": "rotation angle in degrees", "angle_rad": "rotation angle in radians",
    "point_distance": "point distance", "point_distance_error_ratio": "point distance error ratio",
}
DELTA_UNITS = {"f": "frames", "m": "m", "d": "deg", "r": "rad"}
# evo's Unit values, for saved results (evo_res reads the label)
EVO_UNIT_NAMES = {"m": "m", "deg": "deg", "rad": "rad", "": "", "%": "%", "frames": "frames"}
STAT_KEYS = ("rmse", "mean", "median", "std", "min", "max", "sse")


def error_statistics(errors: np.ndarray) -> dict[str, float]:
    """evo's statistics of an error array (population std, as numpy and evo)."""
    e = np.asarray(errors, dtype=np.float64)
    if e.size == 0:
        return {k: float("nan") for k in STAT_KEYS}
    return {
        "rmse": float(np.sqrt(np.mean(e**2))), "mean": float(np.mean(e)), "median": float(np.median(e)),
        "std": float(np.std(e)), "min": float(np.min(e)), "max": float(np.max(e)), "sse": float(np.sum(e**2)),
    }


def rotation_vector_angles(R: np.ndarray) -> np.ndarray:
    """Rotation angles (rad) of a stack of rotation matrices, as evo computes them (scipy rotvec norm)."""
    from scipy.spatial.transform import Rotation

    R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
    if len(R) == 0:
        return np.zeros(0)
    return np.linalg.norm(Rotation.from_matrix(R).as_rotvec(), axis=1)


def relation_errors(E: np.ndarray, relation: str) -> np.ndarray:
    """Per-pose error of error poses ``E`` (N, 4, 4) under ``relation`` (not the point-distance ones)."""
    if relation == "trans_part":
        return np.linalg.norm(E[:, :3, 3], axis=1)
    if relation == "rot_part":
        return np.linalg.norm(E[:, :3, :3] - np.eye(3), axis=(1, 2))
    if relation == "full":
        return np.linalg.norm(E - np.eye(4), axis=(1, 2))
    if relation == "angle_rad":
        return np.abs(rotation_vector_angles(E[:, :3, :3]))
    if relation == "angle_deg":
        return np.abs(np.rad2deg(rotation_vector_angles(E[:, :3, :3])))
    raise AssociationError(f"unknown pose relation {relation!r}; known: {', '.join(RPE_RELATIONS)}")


@dataclass
class PoseErrorResult:
    """APE or RPE under one pose relation; ``errors`` in ``unit`` (see :data:`RELATION_UNITS`)."""

    metric: str  # 'ape' | 'rpe'
    relation: str
    errors: np.ndarray
    stamps: np.ndarray  # reference stamp (ns) per error (RPE: of the pair's second pose)
    alignment: Alignment
    n_ref: int
    n_est: int
    t_max_diff: float
    t_offset: float
    ref_matched: Trajectory | None = field(default=None, repr=False)
    est_aligned: Trajectory | None = field(default=None, repr=False)
    pairs: np.ndarray | None = None  # RPE: (M, 2) indices into the matched trajectories
    delta: float | None = None
    delta_unit: str | None = None  # 'f' | 'm' | 'd' | 'r'
    all_pairs: bool = False
    pairs_from_reference: bool = False

    @property
    def unit(self) -> str:
        return RELATION_UNITS[self.relation]

    @property
    def n_matched(self) -> int:
        return 0 if self.ref_matched is None else len(self.ref_matched)

    @property
    def stats(self) -> dict[str, float]:
        return error_statistics(self.errors)

    def title(self) -> str:
        """evo's title: the metric, the relation, the pairs (RPE) and the alignment."""
        unit = f" ({self.unit})" if self.unit else ""
        if self.metric == "ape":
            text = f"APE w.r.t. {RELATION_TITLES[self.relation]}{unit}"
        else:
            assert self.delta_unit is not None  # an RPE result carries its pair spacing (see rpe_by_relation)
            text = (f"RPE w.r.t. {RELATION_TITLES[self.relation]}{unit} for delta = {self.delta:g} "
                    f"({DELTA_UNITS[self.delta_unit]}) using {'all' if self.all_pairs else 'consecutive'} pairs"
                    + (", pairs from the reference" if self.pairs_from_reference else ", pairs from the estimate"))
        label = {"none": "not aligned", "scale": "scale corrected"}.get(self.alignment.mode,
                                                                        f"with {self.alignment.label}")
        text += f" ({label}"
        if self.alignment.mode in ("se3", "sim3", "scale") and self.alignment.n_used < self.n_matched:
            text += f", aligned poses: {self.alignment.n_used}"
        return text + ")"

    def to_dict(self) -> dict:
        d = {
            "metric": self.metric, "pose_relation": self.relation, "unit": self.unit, "title": self.title(),
            "stats": self.stats, "alignment": self.alignment.to_dict(), "n_matched": self.n_matched,
            "n_errors": int(len(self.errors)), "n_ref": self.n_ref, "n_est": self.n_est,
            "t_max_diff_s": self.t_max_diff, "t_offset_s": self.t_offset,
        }
        if self.metric == "rpe":
            d.update(delta=self.delta, delta_unit=self.delta_unit, all_pairs=self.all_pairs,
                     pairs_from_reference=self.pairs_from_reference)
        return d


def origin_alignment(ref: Trajectory, est: Trajectory, scale: float = 1.0) -> Alignment:
    """evo's ``--align_origin``: the transform moving the estimate's first pose onto the reference's."""
    if len(ref) == 0 or len(est) == 0:
        raise AlignmentError("cannot align the origin of an empty trajectory")
    first = est.poses[0].copy()
    first[:3, 3] *= scale
    T = ref.poses[0] @ inv(first)
    return Alignment("origin", R=T[:3, :3].copy(), t=T[:3, 3].copy(), scale=float(scale), n_used=1)


def _align(ref_m: Trajectory, est_m: Trajectory, align: str, align_origin: bool, n_to_align: int | None) -> Alignment:
    if align_origin and align in ("se3", "sim3"):
        raise AlignmentError("Umeyama alignment (-a) and --align_origin exclude each other (as in evo)")
    alignment = fit_alignment(ref_m, est_m, align, n_to_align)
    if align_origin:  # evo: scale correction (-s) first, then the origin
        alignment = origin_alignment(ref_m, est_m, scale=alignment.scale)
    return alignment


def ape_by_relation(
    ref: Trajectory,
    est: Trajectory,
    relation: str = "trans_part",
    align: str = "none",
    *,
    align_origin: bool = False,
    t_max_diff: float = 0.01,
    t_offset: float = 0.0,
    n_to_align: int | None = None,
) -> PoseErrorResult:
    """evo_ape: associate, align (``'none'|'se3'|'sim3'|'scale'`` or ``align_origin``), error per pose."""
    if relation not in APE_RELATIONS:
        raise AssociationError(f"unknown APE pose relation {relation!r}; known: {', '.join(APE_RELATIONS)}")
    ref_m, est_m = associate(ref, est, t_max_diff, t_offset)
    alignment = _align(ref_m, est_m, align, align_origin, n_to_align)
    est_a = alignment.apply(est_m)
    if relation in ("trans_part", "point_distance"):
        errors = np.linalg.norm(est_a.positions - ref_m.positions, axis=1)
    else:
        errors = relation_errors(inv(est_a.poses) @ ref_m.poses, relation)
    return PoseErrorResult("ape", relation, errors, ref_m.stamps.copy(), alignment, len(ref), len(est),
                           float(t_max_diff), float(t_offset), ref_m, est_a)


# --------------------------------------------------------------------------- RPE pairs (evo.core.filters)
def pairs_by_index(n: int, delta: int, all_pairs: bool = False) -> np.ndarray:
    if all_pairs:
        i = np.arange(max(n - delta, 0))
        return np.stack([i, i + delta], axis=1).astype(np.int64)
    ids = np.arange(0, n, delta)
    return np.stack([ids[:-1], ids[1:]], axis=1).astype(np.int64) if len(ids) > 1 else np.zeros((0, 2), np.int64)


def pairs_by_path(positions: np.ndarray, delta: float, tol: float, all_pairs: bool = False) -> np.ndarray:
    """Pairs ``delta`` metres apart along the path (consecutive; or every start within ``tol``)."""
    if all_pairs:
        dist = np.concatenate(([0.0], np.cumsum(np.linalg.norm(positions[:-1] - positions[1:], axis=1))))
        out = []
        for i in range(dist.size - 1):
            ahead = dist[i + 1:] - dist[i]
            k = int(np.argmin(np.abs(ahead - delta)))
            if np.abs(ahead[k] - delta) <= tol:
                out.append((i, k + i + 1))
        return np.array(out, dtype=np.int64).reshape(-1, 2)
    picked = [0]
    travelled = 0.0
    for i in range(1, len(positions)):
        travelled += float(np.linalg.norm(positions[i, :3] - positions[i - 1, :3]))
        if travelled >= delta:
            picked.append(i)
            travelled = 0.0
    ids = np.asarray(picked, dtype=np.int64)
    return np.stack([ids[:-1], ids[1:]], axis=1) if len(ids) > 1 else np.zeros((0, 2), np.int64)


def pairs_by_angle(rotations: np.ndarray, delta: float, tol: float, degrees: bool,
                   all_pairs: bool = False) -> np.ndarray:
    """Pairs ``delta`` of rotation apart (consecutive: accumulated along the path; all pairs: direct)."""
    from scipy.spatial.transform import Rotation

    bound = 180.0 if degrees else np.pi
    if not 0.0 <= delta <= bound:
        raise AssociationError(f"RPE angle delta must be within [0, {bound:g}], got {delta:g}")
    delta = np.deg2rad(delta) if degrees else delta
    tol = np.deg2rad(tol) if degrees else tol
    n = len(rotations)
    if all_pairs:
        return _pairs_by_angle_all(np.asarray(rotations, dtype=np.float64), delta - tol, delta + tol)
    steps = [float(np.linalg.norm(Rotation.from_matrix(rotations[k].T @ rotations[k + 1]).as_rotvec()))
             for k in range(n - 1)]
    out, acc, start = [], 0.0, 0
    for k, step in enumerate(steps):
        acc += step
        if acc >= delta:
            out.append((start, k + 1))
            acc, start = 0.0, k + 1
    return np.array(out, dtype=np.int64).reshape(-1, 2)


# margin (rad) of the cheap trace-based pre-selection around [lo, hi]: far above its rounding error
_ANGLE_PRESELECT_MARGIN = 1e-6


def _pairs_by_angle_all(rotations: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Every pair (i < j) whose relative rotation angle lies in [lo, hi] (radians).

    Why two steps: the angle of every pair by scipy's rotation vectors (what evo computes)
    costs ~8 s for a 2,900-pose trajectory. The angle from the trace of ``R_i^T R_j`` is cheap
    and accurate to ~1e-14 rad away from 0 and pi, so it pre-selects the pairs within
    ``_ANGLE_PRESELECT_MARGIN`` of the band; only those are decided by the rotation vector,
    exactly as before (same quaternions, same products), so the pairs are the same.
    """
    from scipy.spatial.transform import Rotation

    n = len(rotations)
    if n == 0:
        return np.zeros((0, 2), dtype=np.int64)
    quats = Rotation.from_matrix(rotations)
    out = []
    for i in range(n - 1):
        cos = (np.einsum("kab,ab->k", rotations[i + 1:], rotations[i]) - 1.0) / 2.0
        rough = np.arccos(np.clip(cos, -1.0, 1.0))
        near = np.flatnonzero((rough >= lo - _ANGLE_PRESELECT_MARGIN) & (rough <= hi + _ANGLE_PRESELECT_MARGIN))
        if not len(near):
            continue
        js = near + i + 1
        ang = np.linalg.norm((quats[[i] * len(js)].inv() * quats[js]).as_rotvec(), axis=1)
        out += [(i, int(j)) for j in js[(lo <= ang) & (ang <= hi)]]
    return np.array(out, dtype=np.int64).reshape(-1, 2)


def rpe_pairs(poses: np.ndarray, delta: float, delta_unit: str, rel_tol: float = 0.1,
              all_pairs: bool = False) -> np.ndarray:
    """evo's ``id_pairs_from_delta``: index pairs of ``poses`` (N, 4, 4) ``delta`` ``delta_unit`` apart."""
    if delta_unit == "f":
        if float(delta) != int(delta) or delta < 1:
            raise AssociationError(f"RPE delta in frames must be a whole number >= 1, got {delta:g}")
        pairs = pairs_by_index(len(poses), int(delta), all_pairs)
    elif delta_unit == "m":
        pairs = pairs_by_path(poses[:, :3, 3], float(delta), float(delta) * rel_tol, all_pairs)
    elif delta_unit in ("d", "r"):
        pairs = pairs_by_angle(poses[:, :3, :3], float(delta), float(delta) * rel_tol, delta_unit == "d", all_pairs)
    else:
        raise AssociationError(f"unknown RPE delta unit {delta_unit!r}; use f (frames), m, d (deg) or r (rad)")
    if len(pairs) == 0:
        raise AssociationError(f"RPE delta {delta:g} ({DELTA_UNITS[delta_unit]}) gives no pose pair; "
                               "try a smaller delta" + (" or a larger tolerance" if all_pairs else ""))
    return pairs


def rpe_by_relation(
    ref: Trajectory,
    est: Trajectory,
    relation: str = "trans_part",
    delta: float = 1,
    delta_unit: str = "f",
    align: str = "none",
    *,
    all_pairs: bool = False,
    pairs_from_reference: bool = False,
    rel_delta_tol: float = 0.1,
    align_origin: bool = False,
    t_max_diff: float = 0.01,
    t_offset: float = 0.0,
    n_to_align: int | None = None,
) -> PoseErrorResult:
    """evo_rpe: associate, align, pick pairs (on the aligned estimate unless ``pairs_from_reference``),
    error per pair."""
    if relation not in RPE_RELATIONS:
        raise AssociationError(f"unknown RPE pose relation {relation!r}; known: {', '.join(RPE_RELATIONS)}")
    if not delta > 0:
        raise AssociationError(f"RPE delta must be > 0, got {delta}")
    ref_m, est_m = associate(ref, est, t_max_diff, t_offset)
    alignment = _align(ref_m, est_m, align, align_origin, n_to_align)
    est_a = alignment.apply(est_m)
    pairs = rpe_pairs((ref_m if pairs_from_reference else est_a).poses, delta, delta_unit, rel_delta_tol, all_pairs)
    i, j = pairs[:, 0], pairs[:, 1]
    if relation in ("point_distance", "point_distance_error_ratio"):
        d_ref = np.linalg.norm(ref_m.positions[i] - ref_m.positions[j], axis=1)
        d_est = np.linalg.norm(est_a.positions[i] - est_a.positions[j], axis=1)
        errors = np.abs(d_ref - d_est)
        if relation == "point_distance_error_ratio":
            keep = np.flatnonzero(d_ref)
            pairs, j = pairs[keep], j[keep]
            errors = errors[keep] / d_ref[keep] * 100
    else:
        Q = inv(ref_m.poses[i]) @ ref_m.poses[j]
        P = inv(est_a.poses[i]) @ est_a.poses[j]
        errors = relation_errors(inv(Q) @ P, relation)
    return PoseErrorResult("rpe", relation, errors, ref_m.stamps[j].copy(), alignment, len(ref), len(est),
                           float(t_max_diff), float(t_offset), ref_m, est_a, pairs=pairs, delta=float(delta),
                           delta_unit=delta_unit, all_pairs=all_pairs, pairs_from_reference=pairs_from_reference)
