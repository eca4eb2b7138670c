"""``map.ply``, ``map_odometry.ply``, their top views and sharpness figures: the map before and after the correction.

Why both maps: most users have no ground truth, and ATE needs one. The same keyframes' points
merged with the odometry poses and with the corrected poses show what the correction did to the
world: a wall seen twice is two walls before and one after. The figures (mean map entropy and
plane variance, :func:`slam_lcd.cloud.sharpness`) put a number on it; on a world whose surfaces
are known (the demo world: ``surfaces``), the points' distance to them checks those numbers
against the truth, each map put into the world frame by its own trajectory's ATE alignment.

Written from the run's :class:`~slam_lcd.cloud.MapCloudBuilder` (``pipe.map_cloud``), which kept
every keyframe's points on disk while the log streamed; it is closed here.
"""
from __future__ import annotations

import logging
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from ..cloud import write_cloud
from ..cloud.sharpness import sharpness  # not from ..cloud: once the submodule is imported, that name is it
from ..cloud.topview import common_bounds, height_band, top_view_png
from ..cloud.truth import aligned, truth_figures
from ..eval.metrics import ratio_or_none
from ..files.atomic import atomic_write

log = logging.getLogger(__name__)

MAP_FILE, MAP_ODOMETRY_FILE = "map.ply", "map_odometry.ply"
TOP_FILE, TOP_ODOMETRY_FILE = "map_top.png", "map_top_odometry.png"
MAP_CLOUD_FILES = (MAP_FILE, MAP_ODOMETRY_FILE, TOP_FILE, TOP_ODOMETRY_FILE)


def camera_facts(camera, T_body_camera) -> dict | None:
    """The camera the cloud was built with (``export-map`` rebuilds it from the log with these)."""
    if camera is None:
        return None
    return {"width": int(camera.width), "height": int(camera.height), "fx": float(camera.fx), "fy": float(camera.fy),
            "cx": float(camera.cx), "cy": float(camera.cy), "distortion_model": camera.distortion_model,
            "D": [float(x) for x in np.asarray(camera.D).ravel()],
            "baseline": None if camera.baseline is None else float(camera.baseline),
            "T_body_camera": np.asarray(T_body_camera, float).tolist()}


def cloud_sharpness(cloud, conf) -> dict:
    """:func:`slam_lcd.cloud.sharpness` with the settings of a ``map_cloud`` config section."""
    return sharpness(cloud.points, conf.metric_radius_m, conf.metric_points, conf.metric_min_neighbours,
                     conf.metric_min_std_voxels * conf.voxel_m)


def not_built(reason: str) -> dict:
    return {"built": False, "reason": reason}


def keyframe_poses(pipe, kf_corrected=None) -> tuple[dict, dict]:
    """``(odometry, corrected)``: keyframe id -> 4x4 pose; ``kf_corrected``: the corrected keyframe
    trajectory to use (a map run's, in the map frame; default the run's own)."""
    odo = {k.id: k.T_world_body for k in pipe.keyframes}
    kf_corr = pipe.keyframe_trajectory() if kf_corrected is None else kf_corrected
    by_stamp = {int(s): T for s, T in zip(kf_corr.stamps, kf_corr.poses, strict=True)}
    corr = {k.id: by_stamp[int(k.stamp)] for k in pipe.keyframes if int(k.stamp) in by_stamp}
    return odo, corr


def write_map_clouds(out_dir: Path, pipe, conf, ate_before=None, ate_after=None, surfaces=None,
                     surfaces_name: str = "", sensor: dict | None = None,
                     kf_corrected=None) -> tuple[dict, object | None]:
    """Write :data:`MAP_CLOUD_FILES` into ``out_dir``; ``(facts for report.json, the corrected cloud)``.

    ``kf_corrected``: the corrected keyframe poses (a map run's in the map frame; default the run's own)."""
    builder = pipe.map_cloud
    try:
        if builder.n_keyframes == 0:
            reasons = "; ".join(f"{n} keyframe(s): {r}" for r, n in builder.skipped.items()) or "no keyframe"
            return not_built(f"no keyframe gave points ({reasons})"), None
        t0 = time.perf_counter()
        odo_poses, corr_poses = keyframe_poses(pipe, kf_corrected)
        clouds = {"odometry": builder.cloud(odo_poses)}
        with_truth = surfaces is not None and ate_before is not None and ate_after is not None
        # the odometry map's figures on a second core while the corrected map is merged (numpy and scipy's
        # k-d tree release the GIL); not both merges at once: measured, two threads of many small numpy
        # calls contend for the GIL and cost more CPU than they overlap (docs/map_cloud.md)
        with ThreadPoolExecutor(1, thread_name_prefix="slam-lcd-map-figures") as pool:
            odo_figures = pool.submit(_figures, clouds["odometry"], conf, ate_before if with_truth else None,
                                      surfaces)
            clouds["corrected"] = builder.cloud(corr_poses)
            t1 = time.perf_counter()
            corr_figures = _figures(clouds["corrected"], conf, ate_after if with_truth else None, surfaces)
            t2 = time.perf_counter()
            write_cloud(out_dir / MAP_FILE, clouds["corrected"], "slam-lcd map: keyframe points, corrected poses")
            write_cloud(out_dir / MAP_ODOMETRY_FILE, clouds["odometry"],
                        "slam-lcd map: keyframe points, odometry poses")
            bounds, band = common_bounds(clouds.values()), height_band(clouds.values())
            for name, key, label in ((TOP_ODOMETRY_FILE, "odometry", "odometry poses"),
                                     (TOP_FILE, "corrected", "corrected poses")):
                png = top_view_png(clouds[key].points, bounds, conf.top_view_px, band, label)
                with atomic_write(out_dir / name, "wb") as fh:
                    fh.write(png)
            t3 = time.perf_counter()
            figures = {"odometry": odo_figures.result(), "corrected": corr_figures}
        sharp = {k: f[0] for k, f in figures.items()}
        truth: dict[str, Any] | None = None
        if with_truth:
            truth = {k: f[1] for k, f in figures.items()}
            truth["ratio_after_before"] = ratio_or_none(truth["corrected"]["mean_m"], truth["odometry"]["mean_m"])
            truth["surfaces"] = surfaces_name
            truth["alignment"] = ate_after.alignment.label
        t4 = time.perf_counter()
        facts = {
            "built": True, "reason": None,
            "voxel_m": conf.voxel_m, "min_depth_m": conf.min_depth_m, "max_depth_m": conf.max_depth_m,
            "pixel_step": conf.pixel_step, "min_keyframes_per_voxel": conf.min_keyframes_per_voxel,
            "keyframes_used": builder.n_keyframes, "keyframes_skipped": dict(builder.skipped),
            "points": {k: len(c) for k, c in clouds.items()},
            "sharpness": sharp,
            "after_vs_before": {"mme_difference": _diff(sharp, "mme"),
                                "plane_variance_ratio": _ratio(sharp, "plane_variance_m2")},
            "truth": truth,
            # in the run's thread (keyframes: handing them over), and in the builder's own (taking them in)
            "seconds": {"keyframes": round(builder.wait_seconds, 3), "keyframes_thread": round(builder.seconds, 3),
                        "merge": round(t1 - t0, 3), "files": round(t3 - t2, 3),
                        "figures": round(t2 - t1 + t4 - t3, 3)},
            "store_mb": round(builder.store.nbytes / 1e6, 2),
            "sensor": sensor,
            "files": list(MAP_CLOUD_FILES),
        }
        return facts, clouds["corrected"]
    finally:
        builder.close()


def _figures(cloud, conf, ate, surfaces) -> tuple[dict, dict | None]:
    """``(sharpness, distance to the true surfaces or None)`` of one map; ``ate``: its trajectory's ATE, whose
    alignment puts the map into the surfaces' frame (None: no truth figures)."""
    truth = None
    if ate is not None:
        a = ate.alignment
        truth = truth_figures(aligned(cloud.points, a.R, a.t, a.scale), surfaces, conf.metric_points)
    return cloud_sharpness(cloud, conf), truth


def _ratio(sharp: dict, key: str) -> float | None:
    a, b = sharp["corrected"][key], sharp["odometry"][key]
    return None if a is None or not b else float(a / b)


def _diff(sharp: dict, key: str) -> float | None:
    a, b = sharp["corrected"][key], sharp["odometry"][key]
    return None if a is None or b is None else float(a - b)


def cloud_summary_line(facts: dict) -> str:
    """One line for the run's summary: the map's size and how its sharpness changed."""
    if not facts.get("built"):
        return f"map cloud: not built ({facts.get('reason')})"
    s, t = facts["sharpness"], facts.get("truth")
    a, b = s["odometry"]["mme"], s["corrected"]["mme"]
    text = f"map cloud: {facts['points']['corrected']} points, mean map entropy " + (
        f"{a:.3f} -> {b:.3f}" if a is not None and b is not None else "n/a")
    if t and t["ratio_after_before"] is not None:
        text += f", distance to the true surfaces {100 * t['ratio_after_before']:.1f}% of odometry's"
    return text


def cloud_lines(facts: dict | None) -> list[str]:
    """report.md's lines on the map cloud (also the summary of ``export-map``)."""
    if not facts:
        return []
    if not facts.get("built"):
        return [f"map cloud: not built ({facts.get('reason')})"]
    s, p = facts["sharpness"], facts["points"]
    lines = [f"map cloud: {p['corrected']} points (odometry poses: {p['odometry']}), voxel {facts['voxel_m']:g} m, "
             f"{facts['keyframes_used']} keyframes"]

    def fmt(x, f):
        return "n/a" if x is None else format(x, f)

    lines.append(f"mean map entropy: {fmt(s['odometry']['mme'], '.3f')} -> {fmt(s['corrected']['mme'], '.3f')} "
                 f"(lower is sharper)")
    lines.append(f"plane std: {fmt(s['odometry']['plane_std_mm'], '.1f')} mm -> "
                 f"{fmt(s['corrected']['plane_std_mm'], '.1f')} mm")
    t = facts.get("truth")
    if t:
        r = t["ratio_after_before"]
        lines.append(f"distance to the true surfaces ({t['surfaces']}): {fmt(t['odometry']['mean_m'], '.3f')} m -> "
                     f"{fmt(t['corrected']['mean_m'], '.3f')} m" + (f" ({100 * r:.1f}%)" if r is not None else ""))
    return lines
