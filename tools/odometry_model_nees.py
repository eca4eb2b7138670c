#!/usr/bin/env python
"""How the front end's motion model (``frontend.odom_*_sigma_per_sqrt_*``) fits the simulator's odometry drift.

The model stands in for the odometry's covariance where the log gives none
(:func:`slam_lcd.frontend.keyframes.motion_model_covariance`): a random walk, variance per metre
travelled and per radian turned. This tool drives the project's odometry simulator
(:func:`slam_lcd.sim.odometry.simulate_odometry`: scale and heading biases plus white noise) along
an open 65 m route at 1 m/s, at several odometry rates, selects keyframes (0.5 m) with the model,
and prints, per rate, the planar NEES (``rz, tx, ty``: 3 degrees of freedom, so a mean of 3 is a consistent
covariance, less is conservative) of the modelled covariance against the true error:

- of each keyframe step, and of the chains of keyframe steps 10 m and 50 m long (the chain
  covariance propagated through the adjoints, as the loop gate and PCM propagate it), with the
  share of them beyond the 99 % chi-square bound of 3 dof (11.3; 1 % for a consistent covariance:
  the odometry's biases make the errors of long chains heavy-tailed);
- the sigma of a keyframe step's translation (m), which must not change with the rate;
- the same NEES with the covariances the simulator publishes (``given``), for reference.

    python tools/odometry_model_nees.py [--rates 10,50,200] [--seeds 10] [--sigmas 0.05,0.02,0.05]
"""
from __future__ import annotations

import argparse

import numpy as np

from slam_lcd.backend.gate import ChainRelatives
from slam_lcd.frontend.config import FrontendConfig
from slam_lcd.frontend.keyframes import keyframes_from_trajectory
from slam_lcd.geometry import inv, se3_log
from slam_lcd.sim.odometry import open_route, simulate_odometry
from slam_lcd.types import Trajectory

PLANAR = [2, 3, 4]  # rz, tx, ty of GTSAM's [rx ry rz tx ty tz]


def keyframe_chain(gt: Trajectory, odo: Trajectory, conf: FrontendConfig):
    """(odometry poses, modelled step covariances, true poses) at the keyframes the selector takes."""
    kfs = keyframes_from_trajectory(odo, conf)
    idx = np.searchsorted(gt.stamps, [k.stamp for k in kfs])
    covs = np.array([np.eye(6) if k.covariance_since_last is None else k.covariance_since_last for k in kfs])
    return np.array([k.T_world_body for k in kfs]), covs, gt.poses[idx]


def nees(T_odo, covs, T_gt, span_m: float, step_m: float = 0.5) -> np.ndarray:
    """Planar NEES of the chains of keyframe steps ``span_m`` long (one step when ``span_m`` is 0)."""
    chain = ChainRelatives.from_steps(T_odo, covs)
    k = max(1, int(round(span_m / step_m)))
    out = []
    for i in range(0, len(T_odo) - k, max(1, k // 4)):
        T, S = chain.odometry(i, i + k)
        e = se3_log(inv(inv(T_gt[i]) @ T_gt[i + k]) @ T)[PLANAR]
        out.append(float(e @ np.linalg.solve(S[np.ix_(PLANAR, PLANAR)], e)))
    return np.array(out)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rates", default="10,50,200", help="odometry rates (Hz), comma-separated")
    ap.add_argument("--seeds", type=int, default=10, help="simulated drives per rate")
    ap.add_argument("--sigmas", default=None,
                    help="model figures to try: m/sqrt(m),rad/sqrt(m),rad/sqrt(rad) (default: frontend defaults)")
    a = ap.parse_args(argv)
    model = FrontendConfig(odom_covariance="model", kf_max_interval_s=0, kf_min_overlap=0)
    if a.sigmas:
        t, rm, rr = (float(x) for x in a.sigmas.split(","))
        model.odom_trans_sigma_per_sqrt_m, model.odom_rot_sigma_per_sqrt_m = t, rm
        model.odom_rot_sigma_per_sqrt_rad = rr
    given = FrontendConfig(odom_covariance="absolute", kf_max_interval_s=0, kf_min_overlap=0)
    print(f"model: {model.odom_trans_sigma_per_sqrt_m} m/sqrt(m), {model.odom_rot_sigma_per_sqrt_m} rad/sqrt(m), "
          f"{model.odom_rot_sigma_per_sqrt_rad} rad/sqrt(rad); NEES of 3 dof (rz, tx, ty), mean over {a.seeds} drives")
    print("| rate (Hz) | step sigma_t (m) | NEES step | NEES 10 m | NEES 50 m | given: step | 10 m | 50 m |")
    print("|---|---|---|---|---|---|---|---|")
    bound = 11.34  # chi-square 3 dof, 99 %
    for rate in (float(r) for r in a.rates.split(",")):
        gt = open_route(rate)
        rows: dict[str, list[list[np.ndarray]]] = {"m": [], "g": []}
        sig = []
        for seed in range(a.seeds):
            odo = simulate_odometry(gt, seed=seed, start_at_identity=True)
            gt0 = Trajectory(gt.stamps, inv(gt.poses[0]) @ gt.poses)
            for key, conf in (("m", model), ("g", given)):
                T, C, G = keyframe_chain(gt0, odo, conf)
                rows[key].append([nees(T, C, G, s) for s in (0.0, 10.0, 50.0)])
                if key == "m":
                    sig.append(float(np.median(np.sqrt(C[1:, 3, 3]))))
        cells = []
        for key in ("m", "g"):
            for k in range(3):
                x = np.concatenate([r[k] for r in rows[key]])
                cells.append(f"{x.mean():.2f} ({100 * np.mean(x > bound):.0f} %)")
        print(f"| {rate:g} | {np.mean(sig):.4f} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
