"""Configuration section `eval` (owned by :mod:`slam_lcd.eval`): how ``slam-lcd run`` measures ATE against ground truth.

(``slam-lcd ate`` takes evo's flags instead, with evo's defaults.)
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..value_range import ANY, ranged


@dataclass
class EvalConfig:
    # max |t_ref - t_est| (s) for two poses to be associated (evo's --t_max_diff; evo's default is 0.01)
    t_max_diff: float = ranged(0.02, "[0, inf)")
    # constant offset (s) added to the estimate's stamps before association (evo's --t_offset)
    t_offset: float = ranged(0.0, ANY)
    # alignment before ATE: none, SE(3) or Sim(3) Umeyama (sim3 for monocular/scale-free estimates), scale only
    align: Literal["none", "se3", "sim3", "scale"] = "se3"
    # fit the alignment on the first N matched poses only (null: all of them)
    n_to_align: int | None = ranged(None, "[3, inf)")  # Umeyama needs three points
    # RPE pair spacing, in rpe_delta_unit
    rpe_delta: float = ranged(1.0, "(0, inf)")
    # RPE spacing unit: frames (matched poses) or metres travelled along the reference
    rpe_delta_unit: Literal["frames", "m"] = "m"
