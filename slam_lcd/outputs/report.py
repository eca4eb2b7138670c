"""``report.json`` (versioned: :mod:`.report_schema`), ``report.md`` and the figures of a run.

One function, :func:`report_facts`, gathers what a run says about itself (where it came
from, the counts, ATE and RPE before and after, the loops, the time per stage, the
resolved config); ``report.json``, ``report.md`` and ``report.html`` all print those facts,
so they cannot disagree.
"""
from __future__ import annotations

import json
import shlex
from pathlib import Path

from ..backend.pose_graph import ACCEPTED
from ..config import config_to_dict
from ..eval.metrics import ratio_or_none
from ..files.atomic import write_text
from ..map.summary import localisation_lines, summary_lines
from ..sensors.ground_truth import POSITION_ONLY_REASON
from ..version import __version__
from .map_cloud import cloud_lines
from .report_schema import REPORT_SCHEMA_VERSION
from .result import RunResult


def _errors_dict(translation, rotation, n: int) -> dict:
    """``rotation`` None: not measured (position-only ground truth), null in report.json."""
    return {"translation_m": translation.to_dict(),
            "rotation_deg": rotation.to_dict() if rotation is not None else None,
            "pairs": int(n)}


def _before_after(before, after, rotation: bool = True) -> dict:
    return {"before": _errors_dict(before.translation, before.rotation if rotation else None, len(before.errors)),
            "after": _errors_dict(after.translation, after.rotation if rotation else None, len(after.errors)),
            "ratio_after_before": ratio_or_none(after.rmse, before.rmse)}


def _num(text):
    return None if text in ("", None) else float(text)


def _int(text):
    return None if text in ("", None) else int(text)


def _loop_entry(row: dict) -> dict:
    return {"query_id": int(row["query_id"]), "match_id": int(row["match_id"]),
            "query_stamp_ns": _int(row["query_stamp_ns"]), "match_stamp_ns": _int(row["match_stamp_ns"]),
            "backend_verdict": row["backend_verdict"], "backend_reason": row["backend_reason"],
            "pose_inliers": _int(row.get("pose_inliers")), "gt_distance_m": _num(row["gt_distance_m"]),
            "err_trans_m": _num(row["err_trans_m"]), "err_rot_deg": _num(row["err_rot_deg"])}


def report_facts(result: RunResult, cfg, rows: list[dict], ate_before, ate_after, rpe_before=None,
                 rpe_after=None) -> dict:
    """Everything ``report.json`` holds (the shape is :data:`~.report_schema.REPORT_SCHEMA`)."""
    ev = None
    if ate_before is not None:
        e = cfg.eval
        position_only = result.gt_position_only  # PointStamped: no rotation error, no RPE (the rotations are not known)
        ev = {"alignment": e.align, "t_max_diff_s": float(e.t_max_diff), "t_offset_s": float(e.t_offset),
              "rpe_delta": float(e.rpe_delta), "rpe_delta_unit": e.rpe_delta_unit,
              "ate": _before_after(ate_before, ate_after, rotation=not position_only),
              "rpe": (_before_after(rpe_before, rpe_after) if rpe_before is not None and not position_only else None),
              "gt_position_only": position_only,
              "not_measured": POSITION_ONLY_REASON if position_only else None}
    return {
        "schema": REPORT_SCHEMA_VERSION,
        "slam_lcd_version": __version__,
        # what to read first: a run into a map gives the map's result (corrected.tum in the map frame, this
        # session's loops accepted by the joint graph); session_frame then holds the session's own figures
        "headline": result.headline(),
        "session_frame": result.session_frame,
        "input": {"log": result.log_path, "gt_source": result.gt_source, "topics": dict(result.topics)},
        "command_line": result.command_line,
        "config_overrides": list(result.overrides),
        "frames": result.n_frames, "keyframes": result.n_keyframes,
        "loops": {"candidates": result.loops_proposed, "verified": result.loops_verified,
                  "accepted": result.loops_accepted, "rejected_by_backend": result.loops_rejected_backend,
                  "false_accepted": result.false_loops_accepted},
        "eval": ev,
        "accepted_loops": [_loop_entry(r) for r in rows if r["backend_verdict"] == ACCEPTED],
        "backend_rejected_loops": [_loop_entry(r) for r in rows if r["backend_verdict"] not in ("", ACCEPTED)],
        "interrupted": result.interrupted,
        "wall_s": round(result.wall_s, 3), "log_duration_s": round(result.log_duration_s, 3),
        "stages": result.stages, "outputs": result.outputs,
        "config": config_to_dict(cfg),
        # run --map: the map after this session (sessions, components, loops between sessions, ATE per session)
        "map": result.map,
        # localize: share of keyframes localised, reasons, errors against ground truth
        "localization": ({k: v for k, v in result.localization.items() if not k.startswith("_")}
                         if result.localization is not None else None),
        # the features used: kind and, for SuperPoint, the encoder's arithmetic (features.precision resolved)
        "features": result.features,
        # tracking-loss segments: keyframes in each, components joined by loops, ATE per component (docs/outputs.md)
        "segments": result.segments,
        # the map as a point cloud: sharpness before/after, distance to true surfaces (docs/map_cloud.md)
        "map_cloud": result.map_cloud,
    }


def command_text(command_line) -> str:
    return shlex.join(command_line) if command_line else "(not run from the command line)"


def _stats_line(name: str, ba: dict, unit_t="m", unit_r="deg") -> list[str]:
    b, a = ba["before"], ba["after"]
    ratio = ba["ratio_after_before"]
    lines = [f"| {name} translation RMSE ({unit_t}) | {b['translation_m']['rmse']:.4f} | "
             f"{a['translation_m']['rmse']:.4f} | "
             + (f"{100 * ratio:.1f}% |" if ratio is not None else "(odometry error ~0) |")]
    if b["rotation_deg"] is not None:  # None: position-only ground truth
        lines.append(f"| {name} rotation RMSE ({unit_r}) | {b['rotation_deg']['rmse']:.3f} | "
                     f"{a['rotation_deg']['rmse']:.3f} | |")
    return lines


def write_report(out_dir: Path, facts: dict, summary_lines: list[str]) -> None:
    """``report.json`` (the facts) and ``report.md`` (the same, for a person)."""
    write_text(out_dir / "report.json", json.dumps(facts, indent=2))
    inp = facts["input"]
    md = ["# slam-lcd run report", ""] + [f"- {line}" for line in summary_lines]
    md += ["", f"- log: `{inp['log']}`", f"- ground truth: {inp['gt_source'] or 'none'}",
           f"- slam-lcd {facts['slam_lcd_version']}; command: `{command_text(facts['command_line'])}`",
           f"- overrides: {', '.join(f'`{o}`' for o in facts['config_overrides']) or 'none'}"]
    ev = facts["eval"]
    if ev is not None:
        md += ["", f"## Error against ground truth (alignment {ev['alignment']}, t_max_diff {ev['t_max_diff_s']} s)",
               "", "| metric | odometry | corrected | ratio |", "|---|---|---|---|"]
        md += _stats_line("ATE", ev["ate"])
        if ev["rpe"] is not None:
            md += _stats_line(f"RPE ({ev['rpe_delta']:g} {ev['rpe_delta_unit']})", ev["rpe"])
        if ev.get("not_measured"):
            md += ["", f"Position only (PointStamped ground truth): {ev['not_measured']}."]
    if facts["accepted_loops"]:
        md += ["", "## Accepted loops", "", "| query | match | inliers | GT distance (m) | error (m / deg) |",
               "|---|---|---|---|---|"]
        for lp in facts["accepted_loops"]:
            err = "" if lp["err_trans_m"] is None else (  # position-only ground truth: no rotation error
                f"{lp['err_trans_m']:.3f} / " + (f"{lp['err_rot_deg']:.2f}" if lp["err_rot_deg"] is not None else "-"))
            gd = f"{lp['gt_distance_m']:.2f}" if lp["gt_distance_m"] is not None else ""
            md.append(f"| {lp['query_id']} | {lp['match_id']} | {lp['pose_inliers'] or ''} | {gd} | {err} |")
    md += _map_section(facts.get("map"), facts.get("localization"))
    md += _cloud_section(facts.get("map_cloud"))
    md += ["", "## Time per stage", "", "| stage | seconds | calls |", "|---|---|---|"]
    md += [f"| {k} | {v['seconds']:.2f} | {v['calls']} |" for k, v in facts["stages"].items()]
    md += ["", "## Outputs", ""] + [f"- `{o}`" for o in facts["outputs"]]
    write_text(out_dir / "report.md", "\n".join(md) + "\n")


def _cloud_section(cloud: dict | None) -> list[str]:
    """report.md's table of the map cloud's figures, odometry poses against corrected poses."""
    if not cloud:
        return []
    if not cloud.get("built"):
        return ["", "## Map cloud", "", f"- {cloud_lines(cloud)[0]}"]
    s, t = cloud["sharpness"], cloud.get("truth")

    def cell(x, f):
        return "" if x is None else format(x, f)

    md = ["", "## Map cloud (map.ply, map_odometry.ply)", "", f"- {cloud_lines(cloud)[0]}",
          f"- neighbourhoods of {s['corrected']['radius_m']:g} m at {s['corrected']['evaluated']} points; lower is "
          "sharper", "", "| figure | odometry poses | corrected poses |", "|---|---|---|",
          f"| points | {cloud['points']['odometry']} | {cloud['points']['corrected']} |",
          f"| mean map entropy | {cell(s['odometry']['mme'], '.3f')} | {cell(s['corrected']['mme'], '.3f')} |",
          f"| mean plane variance (mm²) | {cell(_mm2(s['odometry']['plane_variance_m2']), '.2f')} | "
          f"{cell(_mm2(s['corrected']['plane_variance_m2']), '.2f')} |"]
    if t:
        md.append(f"| mean distance to the true surfaces (m) | {cell(t['odometry']['mean_m'], '.4f')} | "
                  f"{cell(t['corrected']['mean_m'], '.4f')} |")
    return md


def _mm2(x):
    return None if x is None else 1e6 * x


def _map_section(summary: dict | None, localization: dict | None) -> list[str]:
    """report.md's part on the map this run appended to or was localised against."""
    md: list[str] = []
    if summary is not None:
        md += ["", "## Map", ""] + [f"- {line.strip()}" for line in summary_lines(summary)]
        if summary.get("sessions"):
            md += ["", "| session | keyframes | component | loops to other sessions | ATE odometry (m) | "
                   "ATE in the map (m) |", "|---|---|---|---|---|---|"]
            for srow in summary["sessions"]:
                a, b = srow.get("ate_odometry"), srow.get("ate_map")
                md.append(f"| {srow['name']} | {srow['keyframes']} | {srow['component']} | "
                          f"{srow['inter_session_loops']} | {'' if a is None else f'{a:.3f}'} | "
                          f"{'' if b is None else f'{b:.3f}'} |")
    if localization is not None:
        md += ["", "## Localisation against the map", ""] + [f"- {line.strip()}" for line in
                                                               localisation_lines(localization)]
    return md
