"""Every output of ``slam-lcd run``, written as one set (:class:`~slam_lcd.outputs.output_set.OutputSet`).

:data:`RUN_OUTPUTS`: config.yaml, odometry.tum, corrected.tum, keyframes_corrected.tum,
loops.csv, graph.g2o, keyframe_keypoints.npz, corrected.mcap, report.json, report.md, report.html, trajectory.png,
ate_over_time.png, loops/ (pictures), map.ply, map_odometry.ply and their top views (docs/map_cloud.md);
``PARTIAL.txt`` when the run was interrupted.
"""
from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..backend.pose_graph import ACCEPTED
from ..config import save_config
from ..errors import InputError, SlamLcdError
from ..eval import ate_with_config
from ..eval.metrics import rpe_with_config
from ..runtime.interrupts import defer_sigint, interrupted_word, signal_name
from ..types import Trajectory
from .figures import write_plots
from .html_report import THUMB_WIDTH, write_html_report
from .keypoints import KEYPOINTS_FILE, keyframe_keypoints, write_keyframe_keypoints
from .loop_pictures import LOOPS_DIR
from .loops import VERIFIED, add_map_verdicts, count_false_accepted, loop_rows, write_loops_csv
from .map_cloud import MAP_CLOUD_FILES, not_built, write_map_clouds
from .map_outputs import (
    LOCALIZATION_FILES,
    MAP_DIR,
    current_in_map_frame,
    session_layer,
    write_localization_outputs,
    write_map_outputs,
)
from .output_set import PARTIAL_MARKER, OutputSet
from .report import report_facts, write_report
from .result import RunResult
from .segments import SEGMENTS_FILE, segment_facts, tum_notes, write_segments_csv

log = logging.getLogger(__name__)

# every name `run` may write into --out (the set is published as a whole: slam_lcd.outputs.output_set)
# a run into a map: corrected.tum and keyframes_corrected.tum are in the map frame, these the session's own
SESSION_FRAME_FILES = ("corrected_session.tum", "keyframes_corrected_session.tum")
RUN_OUTPUTS = ("config.yaml", "odometry.tum", "corrected.tum", "keyframes_corrected.tum", *SESSION_FRAME_FILES,
               "graph.g2o", "loops.csv", SEGMENTS_FILE, KEYPOINTS_FILE,
               "corrected.mcap", "trajectory.png", "ate_over_time.png", "report.json", "report.md", "report.html",
               LOOPS_DIR, MAP_DIR, *LOCALIZATION_FILES, *MAP_CLOUD_FILES)


def partial_text(result: RunResult, notes=(), *, read_to_end: bool, while_writing: bool = False) -> str:
    """What PARTIAL.txt says: why the set is incomplete, and what is missing from it."""
    lines = []
    if not read_to_end:
        lines += [f"This run was interrupted ({signal_name()}) after {result.n_frames} frames: the files here hold the",
                  "result up to that point and agree with each other, but the log was not processed to its end."]
    lines += list(notes)
    if while_writing:
        lines.append(f"This run was {interrupted_word()}{' again' if lines else ''} while the outputs were written: "
                     "only the files present here were written.")
    return "\n".join(lines)


def write_set(outputs: OutputSet, pipe, result: RunResult, gt, mcap_source, copy_topics, notes=None,
              read_to_end: bool = True, album=None, spool=None, surfaces=None) -> None:
    """Write every output into the staging folder, then publish the set (partial when interrupted).

    ``spool``: the run's :class:`~slam_lcd.io.raw_spool.RawSpool` of the copied topics (removed here).
    ``surfaces``: ``(name, {frame: Rectangles})``, the true surfaces of a simulated world in the frames its
    ground truth may be given in (the map cloud's check)."""
    notes = list(notes or [])
    partial = result.interrupted
    try:
        if partial:  # said first: a second Ctrl-C may stop the writing at any file
            outputs.mark_partial(partial_text(result, notes, read_to_end=read_to_end))
        try:
            write_outputs(pipe, outputs.staging, result, gt, mcap_source, copy_topics,
                          skipped=notes if partial else None, album=album, spool=spool, surfaces=surfaces)
        finally:
            if spool is not None:  # a working file inside the staging folder: never published
                spool.discard()
        if partial:
            outputs.mark_partial(partial_text(result, notes, read_to_end=read_to_end))
    except KeyboardInterrupt:
        try:
            with defer_sigint():
                result.interrupted = True
                outputs.mark_partial(partial_text(result, notes, read_to_end=read_to_end, while_writing=True))
                result.outputs = outputs.publish()
        except OSError as e:
            outputs.discard()
            raise _write_error(e, outputs) from None

        log.warning(f"{interrupted_word()} while writing the outputs: %s holds a partial set (see %s)",
                    outputs.target, PARTIAL_MARKER)
        return
    except OSError as e:
        outputs.discard()
        raise _write_error(e, outputs) from None
    except BaseException:
        outputs.discard()
        raise
    try:
        outputs.publish()
    except OSError as e:
        outputs.discard()
        raise _write_error(e, outputs) from None


def _write_error(e: OSError, outputs: OutputSet) -> InputError:
    name = Path(e.filename).name if getattr(e, "filename", None) else ""
    target = outputs.target / name if name in outputs.names else outputs.target
    return InputError(f"cannot write the outputs ({e.strerror or e}); nothing was written there", target)


def write_outputs(pipe, out_dir: Path, result: RunResult, gt: Trajectory | None,
                  mcap_source: Path | None, copy_topics: list[str] | None = None,
                  skipped: list[str] | None = None, album=None, spool=None, surfaces=None) -> None:
    """Write every output of a run into ``out_dir`` (normally an :class:`OutputSet` staging folder).

    ``album``: the run's :class:`~.loop_pictures.KeyframeAlbum` (loop pictures), removed here.
    ``skipped`` (a list) means a partial result: outputs that have nothing to hold yet
    (no odometry, no keyframe) are left out and said so in ``skipped`` instead of failing.
    """
    from ..io.trajectory_files import write_tum  # at call time: tests patch it on trajectory_files

    cfg = pipe.config
    out_dir.mkdir(parents=True, exist_ok=True)
    save_config(cfg, out_dir / "config.yaml")
    outputs = ["config.yaml"]
    odom = pipe.odometry_trajectory()
    corrected = pipe.corrected_trajectory()
    kf_corr = pipe.keyframe_trajectory() if pipe.keyframes else Trajectory(np.zeros(0, np.int64), np.zeros((0, 4, 4)))
    kf_session, corrected_session = kf_corr, None  # the session's own correction (a map run's is the map's)
    files = [("odometry.tum", odom), ("corrected.tum", corrected), ("keyframes_corrected.tum", kf_corr)]
    if _appended_to_map(pipe, result):  # the result is the map's: this log in the map frame
        assert result.map is not None  # _appended_to_map
        corrected_session = corrected
        corrected, kf_corr = current_in_map_frame(pipe, pipe.map, result.map["current_session"])
        files = [("odometry.tum", odom), ("corrected.tum", corrected), ("keyframes_corrected.tum", kf_corr),
                 (SESSION_FRAME_FILES[0], corrected_session), (SESSION_FRAME_FILES[1], kf_session)]
    seg_rows = [r.as_dict() for r in pipe.graph.segment_rows()]
    for name, traj in files:
        if len(traj) == 0 and skipped is not None:
            skipped.append(f"{name}: not written (no poses yet)")
            continue
        write_tum(out_dir / name, traj, tum_notes(traj, seg_rows))
        outputs.append(name)
    if len(seg_rows) > 1:  # tracking was lost: which poses belong to which segment (docs/outputs.md)
        write_segments_csv(out_dir / SEGMENTS_FILE, seg_rows)
        outputs.append(SEGMENTS_FILE)
    if pipe.keyframes or skipped is None:
        pipe.graph.write_g2o(out_dir / "graph.g2o")
        outputs.append("graph.g2o")
    else:
        skipped.append("graph.g2o: not written (no keyframe yet)")
    if pipe.keyframes:  # for `slam-lcd view`: keypoints cannot be read back from the log (slam_lcd.outputs.keypoints)
        write_keyframe_keypoints(out_dir / KEYPOINTS_FILE, *keyframe_keypoints(pipe))
        outputs.append(KEYPOINTS_FILE)

    rows = loop_rows(pipe.candidate_records, pipe.loop_records, pipe.keyframes, gt,
                     position_only=result.gt_position_only, keyframe_poses=kf_session)
    if _appended_to_map(pipe, result):
        assert result.map is not None  # _appended_to_map
        add_map_verdicts(rows, pipe.candidate_records, pipe.map, result.map["inter_session_loops"])
    write_loops_csv(out_dir / "loops.csv", rows)
    outputs.append("loops.csv")

    result.n_keyframes = len(pipe.keyframes)
    result.loops_proposed = len(rows)
    result.loops_verified = sum(1 for r in rows if r["verdict"] == VERIFIED)
    result.loops_accepted = sum(1 for r in pipe.loop_records if r.verdict == ACCEPTED)
    result.loops_rejected_backend = sum(1 for r in pipe.loop_records if r.verdict != ACCEPTED)
    if corrected_session is not None:  # a map run: its headline is the joint graph's (this session's loops in it)
        assert result.map is not None  # a map run (_appended_to_map above)
        result.session_frame = {"loops_accepted": result.loops_accepted,
                                "loops_rejected_by_backend": result.loops_rejected_backend, "ate_after": None}
        result.loops_accepted = int(result.map["current"]["loops_accepted"])
    result.stages = pipe.timer.as_dict()
    result.keyframe_seconds = list(pipe.keyframe_seconds)

    # ---- evaluation against ground truth
    ate_before = ate_after = rpe_before = rpe_after = None
    if gt is not None and len(gt) > 1 and len(odom) > 1:
        try:
            ate_before = ate_with_config(gt, odom, cfg.eval)
            ate_after = ate_with_config(gt, corrected, cfg.eval)
        except SlamLcdError as e:  # the trajectories are still worth having
            ate_before = ate_after = None
            log.warning("ATE against the ground truth not computed: %s", e.problem)
    if ate_before is not None and not result.gt_position_only:  # RPE needs the ground truth's orientation
        try:
            assert gt is not None  # the ATE was computed against it
            rpe_before, rpe_after = (rpe_with_config(gt, t, cfg.eval) for t in (odom, corrected))
        except SlamLcdError as e:  # e.g. a log shorter than one RPE step
            rpe_before = rpe_after = None
            log.warning("RPE against the ground truth not computed: %s", e.problem)
    if ate_before is not None and corrected_session is not None:  # the same ATE of the session's own correction
        assert result.session_frame is not None  # set above for a map run
        try:
            result.session_frame["ate_after"] = ate_with_config(gt, corrected_session, cfg.eval).rmse
        except SlamLcdError:
            pass
    if ate_before is not None:
        assert ate_after is not None  # computed together with ate_before
        result.ate_before, result.ate_after = ate_before.rmse, ate_after.rmse
        result.alignment = result.alignment or cfg.eval.align  # the runner may add a note (position-only ground truth)
        result.false_loops_accepted = count_false_accepted(rows, cfg.run.loop_true_max_distance)
    # a run into a map keeps the map's one alignment (its joint graph links a session's segments itself)
    per_component = ate_before is not None and corrected_session is None
    result.segments = segment_facts(seg_rows, gt if per_component else None, odom, corrected, cfg.eval, result)

    # ---- the map as a point cloud, before and after the correction (corrected.mcap carries it)
    cloud = None
    if getattr(pipe, "map_cloud", None) is not None:
        name, by_frame = surfaces if surfaces is not None else ("", {})
        rects = by_frame.get(result.frames.get("gt") or "world")  # the surfaces in the ground truth's frame
        try:
            result.map_cloud, cloud = write_map_clouds(out_dir, pipe, cfg.map_cloud, ate_before, ate_after, rects,
                                                       name, result.map_cloud_sensor, kf_corrected=kf_corr)
        except OSError:
            raise
        except Exception as e:  # the map must never cost the user the trajectory
            log.warning("map cloud not written: %s", e)
            result.map_cloud = not_built(f"failed: {e}")
        if result.map_cloud.get("built"):
            outputs += list(MAP_CLOUD_FILES)

    # ---- loop pictures (need the verdicts and the ground-truth errors of the rows): drawn in a
    # thread while the corrected MCAP and the plots are written (their image coding, drawing and
    # file reads run outside the GIL; at this point no stage of the run holds a core)
    result.loop_pictures = []
    pictures = _PictureThread(out_dir, album, rows, cfg) if album is not None else None
    try:
        _write_mcap_and_plots(pipe, out_dir, result, gt, mcap_source, copy_topics, skipped, outputs, odom, corrected,
                              kf_corr, ate_before, ate_after, spool, cloud)
    except BaseException:  # an error or Ctrl-C: the pictures stop between two, nothing is written after we leave
        if pictures is not None:
            pictures.join(stop=True)
        raise
    if pictures is not None:
        result.loop_pictures = pictures.join()
    if result.loop_pictures:  # listed where it always was: after corrected.mcap (or loops.csv), before the plots
        after = "corrected.mcap" if "corrected.mcap" in outputs else "loops.csv"
        outputs.insert(outputs.index(after) + 1, LOOPS_DIR + "/")
    if _appended_to_map(pipe, result):
        outputs += write_map_outputs(out_dir, pipe, result, pipe.map)
    if result.localization is not None:
        outputs += write_localization_outputs(out_dir, pipe, result)
    outputs += ["report.json", "report.md", "report.html"]
    result.outputs = outputs
    facts = report_facts(result, cfg, rows, ate_before, ate_after, rpe_before, rpe_after)
    write_report(out_dir, facts, result.summary_lines())
    try:
        write_html_report(out_dir, facts, result.summary_lines(), rows,
                          [f for f in outputs if f.endswith(".png") and f not in MAP_CLOUD_FILES], result.loop_pictures,
                          (out_dir / "config.yaml").read_text(encoding="utf-8"),
                          pictures.thumbs if pictures is not None else None)
    except OSError:
        raise
    except Exception as e:  # the page must never cost the user the numbers
        outputs.remove("report.html")
        log.warning("report.html not written: %s", e)
        write_report(out_dir, facts, result.summary_lines())


class _PictureThread:
    """``write_loop_pictures`` in a background thread; :meth:`join` waits (an interrupt stops it between pictures)."""

    def __init__(self, out_dir: Path, album, rows, cfg):
        import threading

        self.album, self.stop = album, threading.Event()
        self.names: list[str] = []
        self.thumbs: dict[str, bytes] = {}  # the HTML report's thumbnails
        self.thread = threading.Thread(target=self._run, args=(out_dir, rows, cfg), name="slam-lcd-loop-pictures",
                                       daemon=True)
        self.thread.start()

    def _run(self, out_dir, rows, cfg) -> None:
        try:
            from .loop_pictures import write_loop_pictures  # at call time: tests patch it on loop_pictures

            self.names = write_loop_pictures(out_dir, self.album, rows, cfg.lcd, cfg.run.loop_pictures_rejected,
                                             stop=self.stop, thumbnails=self.thumbs, thumb_width=THUMB_WIDTH)
        except Exception as e:  # a picture must never cost the user the numbers
            log.warning("loop pictures not written: %s", e)
            self.names = []

    def join(self, stop: bool = False) -> list[str]:
        if stop:
            self.stop.set()
        try:
            self.thread.join()
        except BaseException:  # Ctrl-C while waiting: the thread stops after its current picture
            self.stop.set()
            self.thread.join()
            raise
        finally:
            self.album.close()
        return [] if self.stop.is_set() else self.names


def _appended_to_map(pipe, result) -> bool:
    """The run appended its log to a map as a new session (``run --map``, not ``localize``)."""
    return (result.map is not None and bool(result.map.get("appended"))
            and result.map.get("current_session") is not None
            and getattr(pipe, "map", None) is not None)


def _write_mcap_and_plots(pipe, out_dir, result, gt, mcap_source, copy_topics, skipped, outputs, odom, corrected,
                          kf_corr, ate_before, ate_after, spool=None, cloud=None) -> None:
    cfg = pipe.config
    # ---- corrected MCAP (input topics + corrected trajectory)
    if mcap_source is not None and len(corrected) == 0 and skipped is not None:
        skipped.append("corrected.mcap: not written (no poses yet)")
    elif mcap_source is not None:
        from .corrected_log import GT_FILE_FRAME, write_corrected_log  # at call time: tests patch it on corrected_log

        gt_file = gt if (gt is not None and (result.gt_source or "").startswith("file ")) else None
        frames = dict(result.frames, gt=GT_FILE_FRAME) if gt_file is not None else result.frames

        kf_stamp = {k.id: int(k.stamp) for k in pipe.keyframes}
        accepted = [(r.query_id, r.match_id, kf_stamp[r.query_id]) for r in pipe.loop_records
                    if r.verdict == ACCEPTED and r.query_id in kf_stamp]
        alignment = ate_after.alignment if ate_after is not None else None
        layer = None
        if _appended_to_map(pipe, result):  # the log among the map's sessions (corrected is in the map frame)
            layer, alignment = session_layer(pipe.map, result.map["current_session"],
                                             result.map["inter_session_loops"])
        write_corrected_log(out_dir / "corrected.mcap", odom=odom, corrected=corrected,
                            kf_ids=[k.id for k in pipe.keyframes], kf_corrected=kf_corr, loops=accepted,
                            log_frame_ids=frames, run_conf=cfg.run, copy_from=mcap_source,
                            copy_topics=copy_topics or [], io_conf=cfg.io, gt_poses=gt_file,
                            gt_alignment=alignment, spooled=spool, sessions=layer,
                            cloud=cloud, cloud_topic=cfg.map_cloud.mcap_topic)
        outputs.append("corrected.mcap")

    # ---- plots
    if cfg.run.plots:
        try:
            write_plots(out_dir, odom, corrected, gt, pipe.keyframes, kf_corr, pipe.loop_records,
                        ate_before, ate_after, mode=cfg.run.plot_mode)
            outputs += ["trajectory.png", "ate_over_time.png"] if ate_before is not None else ["trajectory.png"]
        except Exception as e:  # a plot must never cost the user the numbers
            log.warning("plots not written: %s", e)
