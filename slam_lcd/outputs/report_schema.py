"""The schema of ``report.json`` (JSON Schema, draft 2020-12), versioned by ``"schema"``.

Why a schema: scripts read ``report.json`` (CI dashboards, the HTML report, comparisons of
runs); a version number and a written-down shape let them tell a changed report from a
broken one. :data:`REPORT_SCHEMA_VERSION` goes up when a key is renamed or removed or its
meaning changes; keys may be added within a version. :func:`check_report` is a small
validator of the subset of JSON Schema used here (type, required, properties, items,
enum, const, minimum), so reading a report back needs no extra package.
"""
from __future__ import annotations

from typing import Any

REPORT_SCHEMA_VERSION = 1

_NUM = {"type": "number"}
_NUM_OR_NULL = {"type": ["number", "null"]}
_STATS = {"type": "object", "required": ["rmse", "mean", "median", "std", "min", "max"],
          "properties": {k: _NUM for k in ("rmse", "mean", "median", "std", "min", "max")}}
_ERRORS = {  # one trajectory's ATE or RPE: translation (m) and rotation (deg) statistics
    "type": "object", "required": ["translation_m", "rotation_deg", "pairs"],
    "properties": {"translation_m": _STATS,
                   "rotation_deg": {**_STATS, "type": ["object", "null"]},  # null: position-only GT
                   "pairs": {"type": "integer", "minimum": 0}},
}
_BEFORE_AFTER = {
    "type": "object", "required": ["before", "after", "ratio_after_before"],
    "properties": {"before": _ERRORS, "after": _ERRORS, "ratio_after_before": _NUM_OR_NULL},
}
_LOOP = {
    "type": "object",
    "required": ["query_id", "match_id", "query_stamp_ns", "match_stamp_ns", "backend_verdict", "backend_reason",
                 "pose_inliers", "gt_distance_m", "err_trans_m", "err_rot_deg"],
    "properties": {
        "query_id": {"type": "integer"}, "match_id": {"type": "integer"},
        "query_stamp_ns": {"type": ["integer", "null"]}, "match_stamp_ns": {"type": ["integer", "null"]},
        "backend_verdict": {"type": "string"}, "backend_reason": {"type": "string"},
        "pose_inliers": {"type": ["integer", "null"]},
        "gt_distance_m": _NUM_OR_NULL, "err_trans_m": _NUM_OR_NULL, "err_rot_deg": _NUM_OR_NULL,
    },
}
_SHARP = {"type": "object", "required": ["mme", "plane_variance_m2", "plane_std_mm", "points", "evaluated", "radius_m"],
          "properties": {"mme": _NUM_OR_NULL, "plane_variance_m2": _NUM_OR_NULL, "plane_std_mm": _NUM_OR_NULL,
                         "points": {"type": "integer", "minimum": 0}, "evaluated": {"type": "integer", "minimum": 0},
                         "radius_m": _NUM}}
_TRUTH = {"type": "object", "required": ["mean_m", "median_m", "p90_m", "evaluated"],
          "properties": {"mean_m": _NUM_OR_NULL, "median_m": _NUM_OR_NULL, "p90_m": _NUM_OR_NULL}}
_MAP_CLOUD = {  # the map as a point cloud (slam_lcd.outputs.map_cloud); absent/null when not asked for
    "type": ["object", "null"], "required": ["built", "reason"],
    "properties": {
        "built": {"type": "boolean"}, "reason": {"type": ["string", "null"]},
        "points": {"type": "object", "required": ["odometry", "corrected"],
                   "properties": {"odometry": {"type": "integer"}, "corrected": {"type": "integer"}}},
        "sharpness": {"type": "object", "required": ["odometry", "corrected"],
                      "properties": {"odometry": _SHARP, "corrected": _SHARP}},
        "truth": {"type": ["object", "null"], "required": ["odometry", "corrected", "ratio_after_before"],
                  "properties": {"odometry": _TRUTH, "corrected": _TRUTH, "ratio_after_before": _NUM_OR_NULL}},
    },
}
_INT = {"type": "integer", "minimum": 0}
_SEGMENTS = {  # tracking-loss segments (slam_lcd.outputs.segments); null: no keyframe
    "type": ["object", "null"], "required": ["count", "components", "segments", "ate"],
    "properties": {
        "count": _INT, "ate": {"enum": ["one alignment", "per component, each aligned on its own"]},
        "segments": {"type": "array", "items": {
            "type": "object", "required": ["segment", "component", "keyframes", "first_keyframe", "last_keyframe",
                                           "first_stamp_ns", "last_stamp_ns", "joining_loops"],
            "properties": {k: _INT for k in ("segment", "component", "keyframes", "first_keyframe", "last_keyframe",
                                             "first_stamp_ns", "last_stamp_ns", "joining_loops")}}},
        "components": {"type": "array", "items": {
            "type": "object", "required": ["component", "segments", "keyframes", "joining_loops"],
            "properties": {"component": _INT, "segments": {"type": "array", "items": _INT}, "keyframes": _INT,
                           "joining_loops": _INT, "joined": {"type": "boolean"}, "poses": _INT,
                           "ate_before_m": _NUM_OR_NULL, "ate_after_m": _NUM_OR_NULL,
                           "not_measured": {"type": "string"}}}},
    },
}
REPORT_SCHEMA: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "slam-lcd run report",
    "type": "object",
    "required": ["schema", "slam_lcd_version", "input", "command_line", "config_overrides", "frames", "keyframes",
                 "loops", "eval", "accepted_loops", "backend_rejected_loops", "interrupted", "wall_s",
                 "log_duration_s", "stages", "outputs", "config"],
    "properties": {
        "schema": {"const": REPORT_SCHEMA_VERSION},
        "slam_lcd_version": {"type": "string"},
        "input": {"type": "object", "required": ["log", "gt_source", "topics"],
                  "properties": {"log": {"type": "string"}, "gt_source": {"type": ["string", "null"]},
                                 "topics": {"type": "object"}}},
        "command_line": {"type": ["array", "null"], "items": {"type": "string"}},
        "config_overrides": {"type": "array", "items": {"type": "string"}},
        "frames": {"type": "integer", "minimum": 0},
        "keyframes": {"type": "integer", "minimum": 0},
        "loops": {"type": "object",
                  "required": ["candidates", "verified", "accepted", "rejected_by_backend", "false_accepted"],
                  "properties": {"candidates": {"type": "integer", "minimum": 0},
                                 "verified": {"type": "integer", "minimum": 0},
                                 "accepted": {"type": "integer", "minimum": 0},
                                 "rejected_by_backend": {"type": "integer", "minimum": 0},
                                 "false_accepted": {"type": ["integer", "null"]}}},
        "eval": {"type": ["object", "null"],
                 "required": ["alignment", "t_max_diff_s", "t_offset_s", "rpe_delta", "rpe_delta_unit", "ate", "rpe",
                              "gt_position_only"],
                 "properties": {"alignment": {"enum": ["none", "se3", "sim3", "scale"]},
                                "gt_position_only": {"type": "boolean"},
                                "not_measured": {"type": ["string", "null"]},  # why no rotation error / RPE
                                "t_max_diff_s": _NUM, "t_offset_s": _NUM, "rpe_delta": _NUM,
                                "rpe_delta_unit": {"enum": ["frames", "m"]},
                                "ate": _BEFORE_AFTER, "rpe": {"type": ["object", "null"], **{
                                    k: v for k, v in _BEFORE_AFTER.items() if k != "type"}}}},
        "accepted_loops": {"type": "array", "items": _LOOP},
        "backend_rejected_loops": {"type": "array", "items": _LOOP},
        "interrupted": {"type": "boolean"},
        "wall_s": _NUM, "log_duration_s": _NUM,
        "stages": {"type": "object"},
        "outputs": {"type": "array", "items": {"type": "string"}},
        "config": {"type": "object"},
        "map_cloud": _MAP_CLOUD,
        "segments": _SEGMENTS,
        # the features used; precision: SuperPoint's encoder arithmetic (null for ORB), precision_setting: the key
        "features": {"type": ["object", "null"], "required": ["kind", "precision", "precision_setting"],
                     "properties": {"kind": {"type": ["string", "null"]}, "precision": {"type": ["string", "null"]},
                                    "precision_setting": {"type": "string"}}},
        # what to read first; "frame": "map" for a run into a map (corrected.tum, the loops and the ATE are the
        # map's), "session" otherwise
        "headline": {"type": "object", "required": ["frame", "loops_accepted", "ate_before_m", "ate_after_m"],
                     "properties": {"frame": {"enum": ["map", "session"]},
                                    "loops_accepted": {"type": "integer", "minimum": 0},
                                    "ate_before_m": _NUM_OR_NULL, "ate_after_m": _NUM_OR_NULL,
                                    "ate_ratio": _NUM_OR_NULL, "map": {"type": ["string", "null"]}}},
        # a run into a map: the session's own correction (its back end's loops, corrected_session.tum's ATE)
        "session_frame": {"type": ["object", "null"]},
    },
}

_TYPES = {"object": dict, "array": list, "string": str, "boolean": bool, "null": type(None)}


def _is(value, tname: str) -> bool:
    if tname == "integer":
        return isinstance(value, int) and not isinstance(value, bool)
    if tname == "number":
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return isinstance(value, _TYPES[tname])


def check_report(doc, schema: dict | None = None, where: str = "report") -> list[str]:
    """Problems of ``doc`` against ``schema`` (default :data:`REPORT_SCHEMA`), one line each; [] when it fits."""
    schema = REPORT_SCHEMA if schema is None else schema
    problems: list[str] = []
    if "const" in schema and doc != schema["const"]:
        problems.append(f"{where}: {doc!r} is not {schema['const']!r}")
    if "enum" in schema and doc not in schema["enum"]:
        problems.append(f"{where}: {doc!r} is not one of {schema['enum']}")
    types = schema.get("type")
    if types is not None:
        types = [types] if isinstance(types, str) else types
        if not any(_is(doc, t) for t in types):
            return problems + [f"{where}: {type(doc).__name__} where {' or '.join(types)} is expected"]
    if "minimum" in schema and _is(doc, "number") and doc < schema["minimum"]:
        problems.append(f"{where}: {doc} < {schema['minimum']}")
    if isinstance(doc, dict):
        problems += [f"{where}: key {k!r} missing" for k in schema.get("required", []) if k not in doc]
        for k, sub in schema.get("properties", {}).items():
            if k in doc:
                problems += check_report(doc[k], sub, f"{where}.{k}")
    if isinstance(doc, list) and "items" in schema:
        for i, item in enumerate(doc):
            problems += check_report(item, schema["items"], f"{where}[{i}]")
    return problems
