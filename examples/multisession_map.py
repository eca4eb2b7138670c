"""Example: a multi-session map from Python — build it, query it, and hand it to your own iSAM2.

1. Two sessions of the demo world (laps of one block from two start points, each odometry in its own frame)
   are fed through :class:`~slam_lcd.Pipeline` with a :class:`~slam_lcd.map.Map`
   given at construction: the map's keyframes are loop candidates, ``add_session`` joins the
   finished session into the map's joint graph, ``save`` commits it (one atomic step).
2. A camera frame is queried against the saved map with the map's own loop detector
   (``insert=False``: the map is not changed): the verified match gives the frame's pose in
   the map frame.
3. The map's joint graph goes into a user's own ``gtsam.ISAM2`` under the user's keys.

    python examples/multisession_map.py [--work DIR] [--features orb|superpoint] [--weights W.pth]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from slam_lcd import Keyframe, Map, Pipeline, load_config, open_log
from slam_lcd.features import load_extractor
from slam_lcd.io.decode import decode_camera_info, decode_image, decode_pose
from slam_lcd.io.tf import TfBuffer
from slam_lcd.map import extractor_meta
from slam_lcd.sim import make_demo_log


def feed(pipe: Pipeline, log_path: Path) -> None:
    """Stream a demo log into the pipeline: odometry, camera, depth (metres)."""
    with open_log(log_path) as reader:
        tf = TfBuffer.from_log(reader)
        camera_set = False
        for m in reader.messages():
            if m.topic == "/odom":
                T, cov = decode_pose(m.msg)
                pipe.add_odometry(m.stamp, T, cov)
            elif m.topic == "/camera/camera_info" and not camera_set:
                pipe.set_camera(decode_camera_info(m.msg), tf.lookup("base_link", "camera_optical_frame", m.stamp))
                camera_set = True
            elif m.topic == "/camera/image_raw":
                pipe.add_image(m.stamp, decode_image(m.msg))
            elif m.topic == "/camera/depth":
                pipe.add_depth(m.stamp, decode_image(m.msg).astype(np.float32))


def first_frame(log_path: Path, frame: int = 30):
    """A camera frame (stamp, image, depth, camera) of a log, to query the map with."""
    cam, depth, images = None, {}, {}
    with open_log(log_path) as reader:
        for m in reader.messages(["/camera/camera_info", "/camera/image_raw", "/camera/depth"]):
            if m.topic == "/camera/camera_info" and cam is None:
                cam = decode_camera_info(m.msg)
            elif m.topic == "/camera/depth":
                depth[m.stamp] = decode_image(m.msg).astype(np.float32)
            elif m.topic == "/camera/image_raw":
                images[m.stamp] = decode_image(m.msg)
            ready = sorted(set(images) & set(depth))
            if len(ready) > frame:
                st = ready[frame]
                return st, images[st], depth[st], cam
    raise SystemExit(f"{log_path}: fewer than {frame} frames")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", default=None, help="folder for the logs and the map (default: a temporary one)")
    ap.add_argument("--features", choices=["orb", "superpoint"], default="orb")
    ap.add_argument("--weights", default=None)
    ap.add_argument("--frames", type=int, default=200)
    args = ap.parse_args(argv)
    work = Path(args.work or tempfile.mkdtemp(prefix="slam-lcd-map-example-"))
    sets = [f"features.kind={args.features}", "run.extract_ahead=0"]
    if args.weights:
        sets.append(f"features.weights={args.weights}")
    cfg = load_config("default", sets)
    extractor = load_extractor(cfg.features)

    # 1. two sessions into one map
    logs = []
    # session presets 1 and 5 (laps of block A, other noise and days), the second started 12 m along the
    # block so that the two share about half their route
    for k, start in ((1, None), (5, 12.0)):
        path = work / f"session{k}.mcap"
        if not path.exists():
            make_demo_log(path, "mcap", frames=args.frames, width=320, height=240, session=k, start_at=start)
        logs.append(path)
    root = work / "map"
    if root.exists():
        raise SystemExit(f"{root} exists: give another --work (the example builds a new map)")
    for k, path in zip((1, 5), logs, strict=True):
        with Map.open(root, features=extractor_meta(extractor), conf=cfg.map, write=True, create=True) as m:
            pipe = Pipeline(cfg, extractor=extractor, map=m, expect_depth=True)
            feed(pipe, path)
            pipe.finalize()
            joined = m.add_session(pipe, name=f"session{k}", log_path=path)
            m.save()
            n_inter = sum(1 for lp in joined.loops if lp.inter and lp.accepted)
            print(f"session{k}: {len(pipe.keyframes)} keyframes, {len(pipe.map_closures)} matches to earlier "
                  f"sessions, {n_inter} loops between sessions in the map, components {m.components()}")

    # 2. query the saved map with one frame of session 1 (read only)
    m = Map.open(root, features=extractor_meta(extractor))
    det = m.loop_detector(cfg.lcd, cfg.vocab, extractor=extractor)
    stamp, image, depth, cam = first_frame(logs[0])
    kf = Keyframe(id=m.next_kf_id(), stamp=stamp, T_world_body=np.eye(4), image=image, camera=cam, depth=depth,
                  T_body_camera=np.asarray(m.manifest.sessions[0]["T_body_camera"]))
    closures = det.add(kf, insert=False)
    if closures:
        c = closures[0]
        T_map_body = m.poses()[c.match_id] @ c.T_match_query
        print(f"query frame: matched map keyframe {c.match_id} ({c.evidence['inliers']} inliers); position in the "
              f"map frame {np.round(T_map_body[:3, 3], 3).tolist()}")
    else:
        print("query frame: no verified match in the map")

    # 3. the map's joint graph in the user's own iSAM2 (user's keys, user's gauge prior)
    graph, values = m.factor_graph(key=lambda k: X(k))
    first = int(m.sessions[0].ids[0])
    graph.add(gtsam.PriorFactorPose3(X(first), values.atPose3(X(first)), gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))
    isam = gtsam.ISAM2()
    isam.update(graph, values)
    est = isam.calculateEstimate()
    diff = max(float(np.linalg.norm(est.atPose3(X(k)).translation() - T[:3, 3])) for k, T in m.poses().items())
    print(f"user iSAM2: {graph.size()} factors, {values.size()} poses; largest difference from the map's poses "
          f"{diff:.4f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
