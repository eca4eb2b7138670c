"""Benchmark of the built-in visual odometry on the rendered demo world (RGB-D and stereo).

Writes a seeded demo-world MCAP with depth and stereo (slam_lcd.sim.make_demo_log, ~2
laps), runs RgbdOdometry and StereoOdometry on it through
slam_lcd.sensors.log_vo.visual_odometry_from_log, and prints ATE (SE(3)-aligned RMSE,
also as % of path length), the relative-pose error per metre, tracking statistics,
covariance consistency (NEES) and the time per frame. ``--direct`` renders in memory
instead (no image noise, no log). Usage:

    python tools/bench_vo.py [--laps 2] [--width 640 --height 480] [--rate 10] [--frames N]
                             [--log demo.mcap] [--modes rgbd,stereo] [--direct]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from slam_lcd.eval.align import umeyama
from slam_lcd.frontend import FrontendConfig, RgbdOdometry, StereoOdometry
from slam_lcd.geometry import inv, rotation_angle, se3_log
from slam_lcd.sim.renderer import render
from slam_lcd.sim.rig import STEREO_BASELINE, T_body_camera, T_left_right, demo_camera
from slam_lcd.sim.trajectory import make_trajectory
from slam_lcd.sim.world import build_world


def ate_rmse(est: np.ndarray, ref: np.ndarray) -> float:
    R, t, _ = umeyama(est[:, :3, 3], ref[:, :3, 3], with_scale=False)
    e = (est[:, :3, 3] @ R.T + t) - ref[:, :3, 3]
    return float(np.sqrt(np.mean(np.sum(e * e, 1))))


def rpe_per_metre(est: np.ndarray, ref: np.ndarray, delta_m: float = 5.0):
    """Relative-pose error over segments of ~delta_m path length: (% translation, deg/m)."""
    d = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(ref[:, :3, 3], axis=0), axis=1))])
    te, re = [], []
    for i in range(len(ref)):
        j = int(np.searchsorted(d, d[i] + delta_m))
        if j >= len(ref):
            break
        Er = inv(inv(ref[i]) @ ref[j]) @ (inv(est[i]) @ est[j])
        L = d[j] - d[i]
        te.append(np.linalg.norm(Er[:3, 3]) / L)
        re.append(np.degrees(rotation_angle(Er[:3, :3])) / L)
    return 100 * float(np.mean(te)), float(np.mean(re))


def nees(vo_traj, gt: dict, T_bc) -> float:
    """Mean normalised estimation error squared of relative motions over VO frames (6 = consistent)."""
    P, C, S = vo_traj.poses, vo_traj.covariances, vo_traj.stamps
    vals = []
    step = 10
    for i in range(0, len(S) - step, step):
        j = i + step
        T_ij = inv(P[i]) @ P[j]
        G_ij = inv(gt[S[i]]) @ gt[S[j]]
        from slam_lcd.geometry import relative_covariance
        c = relative_covariance(P[i], C[i], P[j], C[j], floor=np.full(6, 1e-10))
        e = se3_log(inv(G_ij) @ T_ij)
        vals.append(float(e @ np.linalg.solve(c, e)))
    return float(np.median(vals)) if vals else float("nan")


def run_on_log(args) -> int:
    """Write a seeded demo MCAP with depth and stereo (slam_lcd.sim), then run VO reading it back."""
    import tempfile
    from pathlib import Path

    from slam_lcd.io import read_trajectory_from_log
    from slam_lcd.sensors.log_vo import visual_odometry_from_log
    from slam_lcd.sim.demo_log import make_demo_log

    tmp = None
    path = Path(args.log) if args.log else None
    if path is None:
        tmp = tempfile.TemporaryDirectory()
        path = Path(tmp.name) / "demo_vo.mcap"
    if not path.exists():
        t0 = time.perf_counter()
        info = make_demo_log(path, "mcap", frames=args.frames, seed=args.seed, stereo=True, depth=True,
                             laps=args.laps, width=args.width, height=args.height, camera_rate=args.rate)
        print(info.summary().splitlines()[0], f"[{time.perf_counter() - t0:.0f} s]")
    gt_all = read_trajectory_from_log(path, "/ground_truth/pose")
    gtd = {int(s): p for s, p in zip(gt_all.stamps, gt_all.poses, strict=True)}
    for mode in args.modes.split(","):
        t0 = time.perf_counter()
        kw = {"depth_topic": "/camera/depth"} if mode == "rgbd" else {"right_topic": "/camera/right/image_raw"}
        out = visual_odometry_from_log(path, FrontendConfig(), **kw)
        dt = time.perf_counter() - t0
        report(mode, out.result, gtd, dt, out.T_body_camera)
    if tmp is not None:
        tmp.cleanup()
    return 0


def report(mode, res, gtd, wall_s, T_bc) -> None:
    tr = res.trajectory()
    ref = np.array([gtd[int(s)] for s in tr.stamps])
    L = float(np.linalg.norm(np.diff(ref[:, :3, 3], axis=0), axis=1).sum())
    ate = ate_rmse(tr.poses, ref)
    rpe_t, rpe_r = rpe_per_metre(tr.poses, ref)
    n_kf = sum(f.status == "keyframe" for f in res.frames)
    n = len(res.frames)
    print(f"[{mode}] {wall_s / n * 1e3:.1f} ms/frame (decode + features + tracking); tracked {len(tr)}/{n} frames, "
          f"lost {res.n_lost}, segments {res.n_segments}, tracking keyframes {n_kf}")
    drift = np.linalg.norm((inv(tr.poses[0]) @ tr.poses[-1])[:3, 3] - (inv(ref[0]) @ ref[-1])[:3, 3])
    print(f"[{mode}] ATE rmse {ate:.3f} m = {100 * ate / L:.2f}% of path {L:.1f} m (end-point drift {drift:.3f} m)")
    print(f"[{mode}] RPE over 5 m: {rpe_t:.2f}% translation, {rpe_r:.3f} deg/m rotation")
    print(f"[{mode}] covariance consistency: median NEES of 10-frame motions {nees(tr, gtd, T_bc):.2f} "
          f"(6 = consistent)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--laps", type=float, default=2.0)
    ap.add_argument("--width", type=int, default=640)
    ap.add_argument("--height", type=int, default=480)
    ap.add_argument("--rate", type=float, default=10.0)
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--modes", default="rgbd,stereo")
    ap.add_argument("--direct", action="store_true",
                    help="render in memory instead of writing and reading a demo MCAP log")
    ap.add_argument("--log", default=None, help="demo log path to write/reuse (default: a temporary file)")
    args = ap.parse_args(argv)
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    if not args.direct:
        return run_on_log(args)

    world = build_world(args.seed)
    gt = make_trajectory(laps=args.laps, rate_hz=args.rate, seed=args.seed, frames=args.frames)
    cam = demo_camera(args.width, args.height, baseline=STEREO_BASELINE)
    T_bc = T_body_camera()
    T_lr = T_left_right()
    print(f"demo world seed {args.seed}: {len(gt)} frames, path {gt.path_length():.1f} m, {args.width}x{args.height}")
    t0 = time.perf_counter()
    frames = []
    for T in gt.poses:
        T_wc = T @ T_bc
        img, depth = render(world, cam, T_wc)
        right = None
        if "stereo" in args.modes:
            right, _ = render(world, cam, T_wc @ T_lr, with_depth=False)
        frames.append((img, depth, right))
    print(f"rendering: {(time.perf_counter() - t0) / len(gt) * 1e3:.1f} ms/frame")
    gtd = {int(s): p for s, p in zip(gt.stamps, gt.poses, strict=True)}
    conf = FrontendConfig()
    for mode in args.modes.split(","):
        vo = RgbdOdometry(cam, conf, T_bc) if mode == "rgbd" else StereoOdometry(cam, conf, T_bc)
        t0 = time.perf_counter()
        for s, (img, depth, right) in zip(gt.stamps, frames, strict=True):
            vo.process(int(s), img, depth if mode == "rgbd" else right)
        dt = (time.perf_counter() - t0) / len(gt)
        res = vo.result()
        tr = res.trajectory()
        ref = np.array([gtd[int(s)] for s in tr.stamps])
        ate = ate_rmse(tr.poses, ref)
        L = gt.path_length()
        rpe_t, rpe_r = rpe_per_metre(tr.poses, ref)
        n_kf = sum(f.status == "keyframe" for f in res.frames)
        print(f"[{mode}] {dt * 1e3:.1f} ms/frame; tracked {len(tr)}/{len(gt)} frames, lost {res.n_lost}, "
              f"segments {res.n_segments}, tracking keyframes {n_kf}")
        drift = (inv(tr.poses[0]) @ tr.poses[-1])[:3, 3] - (inv(ref[0]) @ ref[-1])[:3, 3]
        print(f"[{mode}] ATE rmse {ate:.3f} m = {100 * ate / L:.2f}% of path {L:.1f} m "
              f"(end-point drift {np.linalg.norm(drift):.3f} m)")
        print(f"[{mode}] RPE over 5 m: {rpe_t:.2f}% translation, {rpe_r:.3f} deg/m rotation")
        print(f"[{mode}] covariance consistency: median NEES of 10-frame motions {nees(tr, gtd, T_bc):.2f} "
              f"(6 = consistent)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
