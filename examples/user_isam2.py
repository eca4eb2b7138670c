"""Example (a): slam-lcd's verified loops inside a user's own GTSAM iSAM2.

The user owns the graph: ``Symbol('x', i)`` keys, their own odometry factors, and factors
slam-lcd never makes (here a GPS-like ``PriorFactorPose3`` every 50 keyframes). slam-lcd
contributes only

1. a :class:`~slam_lcd.lcd.LoopDetector` fed with the user's keyframes (image + camera +
   depth, ids = the user's GTSAM keys), and
2. a :class:`~slam_lcd.backend.PoseGraph` on the user's iSAM2 (``add_odometry=False``):
   each loop goes through the consistency gate (chi-square against the user's estimate
   with iSAM2's marginals, PCM against earlier loops) and, if it passes, into the user's
   iSAM2 as a ``BetweenFactorPose3``; the GNC re-check at the end weighs, removes or
   restores only those loop factors.

Run on the demo world (rendered keyframes with exact ground truth)::

    python examples/user_isam2.py [--weights superpoint_v1.pth]   # default: $SLAM_LCD_SUPERPOINT_WEIGHTS
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from slam_lcd.backend import PoseGraph
from slam_lcd.backend.config import BackendConfig
from slam_lcd.geometry import inv, se3_exp
from slam_lcd.lcd import LcdConfig, LoopDetector
from slam_lcd.sim import simulate_odometry
from slam_lcd.types import Keyframe, Trajectory

# the user's own noise models
ODOM_SIGMAS = np.array([1e-3, 1e-3, 0.01, 0.03, 0.03, 1e-3])  # per keyframe step, [rx ry rz tx ty tz]
GPS_EVERY = 50
GPS_SIGMAS = np.array([0.05, 0.05, 0.05, 0.3, 0.3, 0.3])  # a loose absolute fix


@dataclass
class UserRun:
    isam: gtsam.ISAM2
    graph: PoseGraph  # slam-lcd's bookkeeping on the user's iSAM2
    keys: list[int]
    gt: np.ndarray  # (N, 4, 4)
    odometry: np.ndarray  # (N, 4, 4)
    user_factors: list = field(default_factory=list)  # (iSAM2 slot, factor) of every factor the user added
    closures: list = field(default_factory=list)
    false_accepted: int = 0

    def estimate(self) -> np.ndarray:
        v = self.isam.calculateEstimate()
        return np.array([v.atPose3(k).matrix() for k in self.keys])


def ate(gt: np.ndarray, est: np.ndarray) -> float:
    """Position RMSE (both trajectories start at the same pose: no alignment)."""
    return float(np.sqrt(np.mean(np.sum((gt[:, :3, 3] - est[:, :3, 3]) ** 2, axis=1))))


def is_false_loop(gt: np.ndarray, kq: int, km: int, T_body_camera: np.ndarray) -> bool:
    """Ground truth: the two cameras are far apart or look elsewhere."""
    D = inv(gt[km] @ T_body_camera) @ gt[kq] @ T_body_camera
    ang = np.degrees(np.arccos(np.clip((np.trace(D[:3, :3]) - 1) / 2, -1, 1)))
    return bool(np.linalg.norm(D[:3, 3]) > 2.0 or ang > 45.0)


def run(frames, extractor=None, seed: int = 0, backend: BackendConfig | None = None) -> UserRun:
    """The user's loop: odometry into their iSAM2, keyframes into our detector, loops through our gate.

    ``frames``: :class:`~slam_lcd.sim.keyframes.DemoKeyframes` (keyframes whose ``T_world_body``
    is the ground truth; the user's odometry is simulated from it).
    """
    n = len(frames.keyframes)
    gt = frames.gt.poses
    odom = simulate_odometry(Trajectory(frames.gt.stamps, gt), seed=seed).poses
    rng = np.random.default_rng(seed)
    isam = gtsam.ISAM2()
    keys = [X(i) for i in range(n)]
    graph = PoseGraph(backend or BackendConfig(), isam=isam, key=lambda kf_id: kf_id, add_odometry=False)
    det = LoopDetector(LcdConfig(exclude_recent_s=20.0, exclude_recent_n=0), extractor=extractor)
    run_ = UserRun(isam, graph, keys, gt, odom)
    odom_noise = gtsam.noiseModel.Diagonal.Sigmas(ODOM_SIGMAS)
    gps_noise = gtsam.noiseModel.Diagonal.Sigmas(GPS_SIGMAS)
    for i, kf in enumerate(frames.keyframes):
        # --- the user's own graph update (slam-lcd is not involved)
        f = gtsam.NonlinearFactorGraph()
        v = gtsam.Values()
        if i == 0:
            f.add(gtsam.PriorFactorPose3(keys[0], gtsam.Pose3(odom[0]), gtsam.noiseModel.Isotropic.Sigma(6, 1e-4)))
            v.insert(keys[0], gtsam.Pose3(odom[0]))
        else:
            step = inv(odom[i - 1]) @ odom[i]
            f.add(gtsam.BetweenFactorPose3(keys[i - 1], keys[i], gtsam.Pose3(step), odom_noise))
            v.insert(keys[i], isam.calculateEstimatePose3(keys[i - 1]).compose(gtsam.Pose3(step)))
        if i > 0 and i % GPS_EVERY == 0:  # a GPS-like absolute fix: ground truth plus noise
            fix = gt[i] @ se3_exp(rng.normal(0.0, 1.0, 6) * GPS_SIGMAS * 0.5)
            f.add(gtsam.PriorFactorPose3(keys[i], gtsam.Pose3(fix), gps_noise))
        slots = isam.update(f, v).getNewFactorsIndices()
        run_.user_factors += [(int(s), f.at(j)) for j, s in enumerate(slots)]
        # --- slam-lcd: the keyframe (own id = the user's key) into the detector, its loops through the gate
        # the user's minimal keyframe: their id (the GTSAM key), image, camera and mounting, depth;
        # no pose needed (features are passed when the user has them, else extracted)
        kf = Keyframe(keys[i], kf.stamp, np.eye(4), image=kf.image, camera=kf.camera,
                      T_body_camera=kf.T_body_camera, depth=kf.depth, features=kf.features)
        graph.add_keyframe(kf.id, kf.stamp)
        for c in det.add(kf):
            run_.closures.append(c)
            graph.add_loop(c)
    graph.finalize()
    index = {k: i for i, k in enumerate(keys)}
    run_.false_accepted = sum(
        is_false_loop(gt, index[r.query_id], index[r.match_id], frames.T_body_camera)
        for r in graph.loop_records if r.verdict == "accepted")
    return run_


def main(argv=None) -> int:
    import argparse
    import os

    from slam_lcd.errors import SlamLcdError
    from slam_lcd.features import FeaturesConfig, load_extractor
    from slam_lcd.sim.keyframes import demo_keyframes

    ap = argparse.ArgumentParser(description="slam-lcd loops in a user's own iSAM2 (demo world)")
    ap.add_argument("--weights", default=os.environ.get("SLAM_LCD_SUPERPOINT_WEIGHTS"), help="SuperPoint weights")
    args = ap.parse_args(argv)
    try:
        ex = load_extractor(FeaturesConfig(kind="superpoint"), weights=args.weights, device="cpu")
        r = run(demo_keyframes(ex), extractor=ex)
    except SlamLcdError as e:
        print(f"user_isam2: {e}", file=sys.stderr)
        return 2
    acc = sum(rec.verdict == "accepted" for rec in r.graph.loop_records)
    print(f"keyframes {len(r.keys)}, loops offered {len(r.closures)}, accepted {acc}, "
          f"false accepted {r.false_accepted}")
    print(f"ATE odometry {ate(r.gt, r.odometry):.3f} m -> user's graph with our loops {ate(r.gt, r.estimate()):.3f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
