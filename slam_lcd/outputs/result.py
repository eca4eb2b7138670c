"""What a run returns: counts, ATE before and after, timings and the files written."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path


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
    # per keyframe: loop detection (and its parts) and back end seconds, resident kB (benchmarks)
    keyframe_seconds: list = field(default_factory=list, repr=False)

    def summary_lines(self) -> list[str]:
        lines = [
            f"frames: {self.n_frames}, keyframes: {self.n_keyframes}",
            f"loops: {self.loops_proposed} candidates, {self.loops_verified} verified, "
            f"{self.loops_accepted} accepted by the back end, {self.loops_rejected_backend} rejected by it"
            + (f", {self.false_loops_accepted} false loops accepted" if self.false_loops_accepted is not None else ""),
        ]
        if self.ate_before is not None:
            ratio = self.ate_after / self.ate_before if self.ate_before else float("nan")
            lines.append(f"ATE ({self.alignment}): {self.ate_before:.3f} m -> {self.ate_after:.3f} m ({100 * ratio:.1f}% of odometry)")
        lines.append(f"time: {self.wall_s:.1f} s wall for {self.log_duration_s:.1f} s of log"
                     + (" (interrupted: partial result)" if self.interrupted else ""))
        return lines
