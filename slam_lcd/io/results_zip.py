"""evo's result archive (``--save_results res.zip``), so ``evo_res`` and ``evo.tools.file_interface.load_res_file``
read ours.

Layout (evo's ``save_res_file``): ``info.json`` (title, ref_name, est_name, label), ``stats.json``
(rmse, mean, median, std, min, max, sse), one ``.npy`` per array (``error_array``,
``timestamps`` and ``seconds_from_start`` in seconds, ``alignment_transformation_sim3``) and
the two trajectories as TUM text. Arrays are saved with ``allow_pickle=False``; the archive is
written atomically.
"""
from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path

import numpy as np

from ..files.atomic import atomic_path
from ..types import Trajectory
from .trajectory_files import write_tum


def _npy(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.asarray(array), allow_pickle=False)
    return buf.getvalue()


def _tum_text(traj: Trajectory, tmpdir: Path) -> str:
    path = tmpdir / "traj.tum"
    write_tum(path, traj)
    return path.read_text(encoding="utf-8")


def _safe_name(name: str) -> str:
    return "".join(c if c.isalnum() or c in "._-" else "_" for c in name) or "trajectory"


def write_evo_results(out: str | Path, result, *, ref_name: str = "reference", est_name: str = "estimate") -> Path:
    """Write ``result`` (a :class:`slam_lcd.eval.relations.PoseErrorResult`, or anything with its fields)
    as an evo result zip."""
    out = Path(out)
    unit = result.unit or "none"
    info = {"title": result.title(), "ref_name": ref_name, "est_name": est_name,
            "label": f"{result.metric.upper()} ({unit})"}
    if result.metric == "rpe":
        info.update(delta=result.delta, delta_unit=result.delta_unit, all_pairs=result.all_pairs,
                    pairs_from_reference=result.pairs_from_reference)
    arrays = {"error_array": np.asarray(result.errors, dtype=np.float64)}
    if len(result.stamps):
        seconds = np.asarray(result.stamps, dtype=np.float64) * 1e-9
        first = result.ref_matched.stamps[0] * 1e-9 if result.ref_matched is not None else seconds[0]
        arrays["timestamps"] = seconds
        arrays["seconds_from_start"] = seconds - first
    A = np.eye(4)
    A[:3, :3] = result.alignment.scale * result.alignment.R
    A[:3, 3] = result.alignment.t
    arrays["alignment_transformation_sim3"] = A
    with atomic_path(out) as tmp:
        with zipfile.ZipFile(tmp, "w") as archive:
            archive.writestr("info.json", json.dumps(info))
            archive.writestr("stats.json", json.dumps(result.stats))
            for name, array in arrays.items():
                archive.writestr(f"{name}.npy", _npy(array))
            names = {}
            for name, traj in ((ref_name, result.ref_matched), (est_name, result.est_aligned)):
                if traj is not None:
                    fname = _safe_name(name)
                    fname = fname if fname not in names else f"{fname}_est"
                    names[fname] = True
                    archive.writestr(f"{fname}.tum", _tum_text(traj, tmp.parent))
    return out
