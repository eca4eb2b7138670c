"""slam-lcd: Bag of SuperPoints loop-closure detection with graph verification, as a GTSAM back end.

The names a user needs come from here: the plugin (:class:`Pipeline`), one recorded log end
to end (:func:`run_log` with its input groups, :class:`RunResult`), the stages usable alone
(:class:`LoopDetector`, :class:`PoseGraph`, :class:`Map`), :func:`load_config`,
:func:`open_log` and the shared types of :mod:`slam_lcd.types`. Each is imported on first use,
so that ``import slam_lcd`` (which the command line and every subpackage's configuration
pay for) stays cheap: torch, GTSAM and numpy load only with the name that needs them.
"""
from __future__ import annotations

from .runtime import moved_modules
from .runtime.lazy_names import lazy_getattr
from .version import __version__  # the package face re-exports it (slam_lcd.__version__)

moved_modules.install()  # the old paths of moved modules (slam_lcd.pipeline, slam_lcd.runner, ...)

# typing.TYPE_CHECKING without importing typing (as long again as the rest of this import);
# type checkers take a name TYPE_CHECKING as true
TYPE_CHECKING = False

if TYPE_CHECKING:
    from .backend.pose_graph import PoseGraph
    from .config import load_config
    from .io import open_log
    from .lcd.detector import LoopDetector
    from .map.session_map import Map
    from .outputs.result import RunResult
    from .run.options import MapUse, Models, OutputOptions, Sources
    from .run.pipeline import Pipeline
    from .run.runner import run_log
    from .types import CameraModel, Features, Keyframe, LoopCandidate, LoopClosure, Rectangles, Stamp, Trajectory

_EXPORTS = {
    "Pipeline": ".run.pipeline",
    "run_log": ".run.runner",
    "RunResult": ".outputs.result",
    "Sources": ".run.options",
    "Models": ".run.options",
    "MapUse": ".run.options",
    "OutputOptions": ".run.options",
    "LoopDetector": ".lcd.detector",
    "PoseGraph": ".backend.pose_graph",
    "Map": ".map.session_map",
    "load_config": ".config",
    "open_log": ".io",
    "CameraModel": ".types",
    "Features": ".types",
    "Keyframe": ".types",
    "LoopCandidate": ".types",
    "LoopClosure": ".types",
    "Rectangles": ".types",
    "Stamp": ".types",
    "Trajectory": ".types",
}

__all__ = [
    "CameraModel",
    "Features",
    "Keyframe",
    "LoopCandidate",
    "LoopClosure",
    "LoopDetector",
    "Map",
    "MapUse",
    "Models",
    "OutputOptions",
    "Pipeline",
    "PoseGraph",
    "Rectangles",
    "RunResult",
    "Sources",
    "Stamp",
    "Trajectory",
    "__version__",
    "load_config",
    "open_log",
    "run_log",
]

__getattr__ = lazy_getattr(__name__, _EXPORTS, globals())
