"""slam_lcd.run: the run layer, the hub that wires the stages together and drives a log through them.
May import: every stage, ``sensors``, ``io`` and ``outputs``; only ``cli`` and ``batch`` import it.

- :class:`Pipeline` (``pipeline``): the plugin API, odometry and images in, loops and the
  corrected trajectory out; the frames waiting for odometry (``frame_queue``) and the
  background extraction threads (``extract_ahead``) are its parts.
- :func:`run_log` (``runner``): one recorded log through the pipeline into a set of outputs;
  its inputs come grouped (``options``: :class:`Sources`, :class:`Models`, :class:`MapUse`,
  :class:`OutputOptions`); which sensor feeds what (``sources``) and the paths a run refuses
  before any work (``checks``).

Names are imported lazily, so that the command line can check a run's paths
(``slam_lcd.run.checks``) before it pays for torch and GTSAM.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from ..runtime.lazy_names import lazy_getattr

if TYPE_CHECKING:
    from ..outputs.result import RunResult
    from .options import MapUse, Models, OutputOptions, Sources
    from .pipeline import Pipeline
    from .runner import run_log

_EXPORTS = {
    "Pipeline": ".pipeline",
    "run_log": ".runner",
    "RunResult": ".runner",
    "Sources": ".options",
    "Models": ".options",
    "MapUse": ".options",
    "OutputOptions": ".options",
}

__all__ = ["MapUse", "Models", "OutputOptions", "Pipeline", "RunResult", "Sources", "run_log"]

__getattr__ = lazy_getattr(__name__, _EXPORTS, globals())
