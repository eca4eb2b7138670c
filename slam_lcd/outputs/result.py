"""What a run returns: counts, ATE before and after, timings, the files written and where it came from."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..eval.metrics import ratio_or_none
from ..types import Trajectory


@dataclass
class RunResult:
    out_dir: Path
    n_frames: int = 0
    n_keyframes: int = 0
    loops_proposed: int = 0
    loops_verified: int = 0
    loops_accepted: int = 0
    loops_rejected_backend: int = 0
    false_loops_accepted: int | None = None
    ate_before: float | None = None
    ate_after: float | None = None
    alignment: str = ""
    interrupted: bool = False
    wall_s: float = 0.0
    log_duration_s: float = 0.0
    stages: dict = field(default_factory=dict)
    outputs: list[str] = field(default_factory=list)
    loop_pictures: list[str] = field(default_factory=list)  # names under loops/
    # per keyframe: loop detection (and its parts) and back end seconds, resident kB (benchmarks)
    keyframe_seconds: list = field(default_factory=list, repr=False)
    # where the run came from (report.json / report.html say it): the input log, the ground
    # truth's source ("file PATH" / "topic NAME" / None), the topics used, the command line
    # and the --set overrides as the user typed them
    log_path: str = ""
    gt_source: str | None = None
    topics: dict = field(default_factory=dict)
    # frame names of the log: the odometry's frame_id ("odom") and child_frame_id ("body"), the ground truth's ("gt")
    frames: dict = field(default_factory=dict)
    command_line: list[str] | None = None
    overrides: list[str] = field(default_factory=list)
    # run --map: the map after this session was added (slam_lcd.map.summary.map_summary), else None
    map: dict | None = None
    # run --map: the session's own correction (its back end's loops, ATE of corrected_session.tum); the
    # counts and ATE above are then the map's (the joint graph's loops of this session, corrected.tum in the map frame)
    session_frame: dict | None = None
    # localize: slam_lcd.map.summary.localisation_report (with the Localisation under "_loc"), else None
    localization: dict | None = None
    # the map as a point cloud (slam_lcd.outputs.map_cloud): its figures, or why it was not built; None: not asked
    map_cloud: dict | None = None
    # the sensor the cloud was built from (kind, topics, camera, mounting, rectification): export-map rebuilds it
    map_cloud_sensor: dict | None = field(default=None, repr=False)
    # the features the run used: kind, and for SuperPoint the encoder's arithmetic ('auto' resolved on this device)
    features: dict | None = None
    # tracking-loss segments of the pose graph (slam_lcd.outputs.segments.segment_facts), None: no keyframe
    segments: dict | None = None
    # the ground truth the run evaluated against (a Trajectory), or None; what a viewer of the run reuses
    ground_truth: Trajectory | None = field(default=None, repr=False)

    @property
    def gt_position_only(self) -> bool:
        """The ground truth has positions only (PointStamped): no rotation error, no RPE."""
        return "position-only" in (self.alignment or "")

    @property
    def ate_ratio(self) -> float | None:
        return ratio_or_none(self.ate_after, self.ate_before)

    @property
    def in_map_frame(self) -> bool:
        """A run into a map: the result (corrected.tum, the counts, the ATE) is the map's."""
        return self.session_frame is not None and bool(self.map and self.map.get("current"))

    def headline(self) -> dict:
        """The result a user looks at first (report.json's ``headline``): frame, loops accepted, ATE before/after."""
        return {"frame": "map" if self.in_map_frame else "session", "loops_accepted": self.loops_accepted,
                "ate_before_m": self.ate_before, "ate_after_m": self.ate_after, "ate_ratio": self.ate_ratio,
                "map": self.map["root"] if self.in_map_frame and self.map else None}

    def _ate_text(self, after: float | None) -> str:
        ratio = ratio_or_none(after, self.ate_before)
        return (f"{self.ate_before:.3f} m -> {after:.3f} m"
                + (f" ({100 * ratio:.1f}% of odometry)" if ratio is not None else " (odometry error ~0: no ratio)"))

    def summary_lines(self) -> list[str]:
        lines = []
        if self.in_map_frame:  # the map's result first: the session's own figures follow, labelled
            assert self.map is not None  # in_map_frame: there is a map
            cur = self.map["current"]
            ate = f", ATE ({self.alignment}) {self._ate_text(self.ate_after)}" if self.ate_before is not None else ""
            lines.append(f"map {self.map['root']}: session {cur['name']} "
                         + ("joined" if cur["joined"] else "not joined (kept in its own frame)")
                         + f", {cur['loops_accepted']} loops accepted by the joint graph ({cur['inter_session_loops']} "
                           f"to other sessions, {cur['within_session_loops']} within it){ate} in the map frame")
        lines.append(f"frames: {self.n_frames}, keyframes: {self.n_keyframes}")
        if self.in_map_frame:
            own = self.session_frame
            assert own is not None  # in_map_frame: the session's own frame is there
            lines.append(f"this session on its own (its odometry frame, corrected_session.tum): "
                         f"{self.loops_proposed} loop candidates, {self.loops_verified} verified, "
                         f"{own['loops_accepted']} accepted by its back end, {own['loops_rejected_by_backend']} "
                         "rejected by it" + (f", ATE {self._ate_text(own['ate_after'])}"
                                             if own.get("ate_after") is not None else ""))
        else:
            lines.append(f"loops: {self.loops_proposed} candidates, {self.loops_verified} verified, "
                         f"{self.loops_accepted} accepted by the back end, {self.loops_rejected_backend} rejected by it"
                         + (f", {self.false_loops_accepted} false loops accepted"
                            if self.false_loops_accepted is not None else ""))
            if self.ate_before is not None:
                lines.append(f"ATE ({self.alignment}): {self._ate_text(self.ate_after)}")
        if self.segments is not None and self.segments["count"] > 1:
            from .segments import segments_line  # lazy: numpy and the evaluation

            lines.append(segments_line(self.segments["segments"], self.segments["components"]))
        if self.features is not None and self.features.get("precision"):
            lines.append(f"features: {self.features['kind']}, encoder in {self.features['precision']} "
                         f"(features.precision {self.features['precision_setting']})")
        if self.map_cloud is not None:
            from .map_cloud import cloud_summary_line  # lazy: OpenCV

            lines.append(cloud_summary_line(self.map_cloud))
        lines.append(f"time: {self.wall_s:.1f} s wall for {self.log_duration_s:.1f} s of log"
                     + (" (interrupted: partial result)" if self.interrupted else ""))
        return lines
