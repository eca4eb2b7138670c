"""The inputs of :func:`slam_lcd.run.runner.run_log`, grouped by what they are about.

Why grouped: a run takes a log and an output folder, then some twenty choices that fall into
four kinds, each used by a different part of the run: where the data comes from
(:class:`Sources`), the models a caller loads once for many logs (:class:`Models`), what the
run does with a persistent map (:class:`MapUse`), and how it reports and what it writes
besides the result (:class:`OutputOptions`). Every field has the default of a plain
``slam-lcd run``, so a caller names only what it changes. This module imports nothing heavy:
the command line builds these before it loads a model.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

if TYPE_CHECKING:
    from ..features.extract import Extractor
    from ..map.session_map import Map
    from ..sensors.calibration import Calibration
    from ..types import Rectangles
    from ..viewer.live import LiveRecorder
    from ..vocab.vocabulary import Vocabulary

MapMode = Literal["append", "localize"]


@dataclass(frozen=True)
class Sources:
    """Where a run's data comes from; every topic left None is chosen from the log.

    The topics are those of ``--image-topic``, ``--odom-topic``, ``--gt-topic``,
    ``--depth-topic`` and ``--right-topic`` (the second camera of a stereo pair). ``gt_file``:
    a ground-truth trajectory file (``--gt``), which wins over a ground-truth topic. ``calib``:
    calibration file(s) (Kalibr camchain.yaml or EuRoC sensor.yaml, see
    :mod:`slam_lcd.sensors.calibration`) or a loaded ``Calibration``; its camera and mounting
    win over the log's CameraInfo and ``/tf_static``.
    """

    image_topic: str | None = None
    odom_topic: str | None = None
    gt_topic: str | None = None
    depth_topic: str | None = None
    right_topic: str | None = None
    gt_file: str | Path | None = None
    calib: str | Path | Sequence[str | Path] | Calibration | None = None


@dataclass(frozen=True)
class Models:
    """The models a run uses as given, so that a caller running many logs loads each once.

    ``extractor``: None loads the one ``features`` of the config names. ``vocab``: a trained
    vocabulary; None grows the online vocabulary as the run goes.
    """

    extractor: Extractor | None = None
    vocab: Vocabulary | None = None


@dataclass(frozen=True)
class MapUse:
    """What a run does with a persistent map (:class:`slam_lcd.map.Map`).

    ``mode='append'``: the map, opened for writing, offers its keyframes as loop candidates and
    the log is appended to it as session ``session_name`` (default: the log's file name),
    committed before the outputs are written; an interrupted run leaves the map as it was.
    ``mode='localize'``: the map, opened read-only, is not changed; each keyframe is localised
    against it (``result.localization``).
    """

    session_map: Map
    mode: MapMode = "append"
    session_name: str | None = None


@dataclass(frozen=True)
class OutputOptions:
    """How a run reports, and what it writes besides the result.

    ``progress``: a progress bar on stderr. ``write_mcap``: write ``corrected.mcap`` (when the
    config does too). ``input_paths``: inputs named by the caller's flags besides the log and
    the ground truth (e.g. ``{"--config": path}``): no output may land on one. ``command_line``
    and ``overrides`` (the ``--set`` assignments) are only reported. ``surfaces``:
    ``(name, {ground-truth frame: Rectangles})``, the true surfaces of the world the log was
    rendered in (the demo world: :func:`slam_lcd.sim.demo_surfaces`): the map cloud's points
    are measured against those. ``live`` (a :class:`slam_lcd.viewer.live.LiveRecorder`) sees
    each keyframe and verified loop as the run goes.
    """

    progress: bool = True
    write_mcap: bool = True
    input_paths: dict[str, str | Path | None] = field(default_factory=dict)
    command_line: list[str] | None = None
    overrides: Sequence[str] = ()
    surfaces: tuple[str, dict[str, Rectangles]] | None = None
    live: LiveRecorder | None = None
