"""`slam-lcd view`: a recording built from a run folder or a map folder (and a localisation), then shown or saved.

Why everything is read and every path checked before a stream opens: bad input is one line and
exit status 2 with nothing written (no ``.rrd``, no viewer window, no server). Reading the folders
needs no rerun; the layout (a Rerun blueprint) is made only when asked for, so a wrong folder is
reported as such whether or not the ``viewer`` extra is installed.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from . import record
from .folders import folder_kind, read_localization, read_map, read_run
from .layout import blueprint


@dataclass
class Plan:
    name: str  # the recording's name (the folder's)
    build: Callable  # build(rec): logs everything
    layout: Callable[[], object]  # layout(): the first view (a Rerun blueprint; needs rerun)
    inputs: dict  # what each input is -> its path (no output may land on them)
    summary: str
    warnings: list[str] = field(default_factory=list)  # one line each, said once the input is known good


def plan(folder: str | Path, localization: str | Path | None = None, log: str | Path | None = None) -> Plan:
    """Read ``folder`` (a run or a map; ``localization``: a ``localize`` output folder, with a map only;
    ``log``: the run's log where report.json's path no longer leads, with a run only)."""
    folder = Path(folder)
    kind = folder_kind(folder)
    inputs: dict = {f"the {kind} folder": folder}
    if kind == "run":
        if localization is not None:
            raise InputError("--localization goes with a map folder, not a run folder", folder)
        run = read_run(folder, images=True, log_path=log)
        if run.log is not None:
            inputs["the run's log"] = run.log
        n_acc = sum(r.get("backend_verdict") == "accepted" for r in run.loops)
        return Plan(folder.name or str(folder), lambda rec: record.log_run(rec, run),
                    lambda: blueprint(images=bool(run.images), ate=bool(run.ate), image_origin=record.KEYFRAME_CAMERA),
                    inputs,
                    f"{folder}: run, {len(run.keyframes)} keyframes ({len(run.images)} with images), "
                    f"{len(run.loops)} loops ({n_acc} accepted), {sum(len(c) for c in run.clouds.values())} map points"
                    + "".join(f"; {n}" for n in run.notes), [run.moved_log] if run.moved_log else [])
    if log is not None:
        raise InputError("--log goes with a run folder, not a map folder", folder)
    m = read_map(folder)
    loc = read_localization(localization) if localization is not None else None
    if loc is not None:
        inputs["--localization"] = loc.root

    def build(rec) -> None:
        record.log_map(rec, m)
        if loc is not None:
            record.log_localization(rec, loc)

    return Plan(folder.name or str(folder), build, lambda: blueprint(images=False, ate=False, map_folder=True), inputs,
                f"{folder}: map, {len(m.sessions)} sessions ({', '.join(s.name for s in m.sessions)}), "
                f"{len(m.loops)} loops" + (f"; localisation {loc.name}" if loc is not None else ""))
