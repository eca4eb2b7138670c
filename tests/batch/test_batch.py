"""`slam-lcd batch`: many logs on a local process pool and on a local Ray.

Three short demo logs (different seeds; MCAP, ROS1 bag, rosbag2) and one corrupt log (a
truncated copy of the ROS1 bag), made once per session. Every figure in the summary is
compared with a direct ``run_log`` of the same log and configuration; a re-run is shown to
do no work by its "skipped" rows and by the unchanged inode and mtime of every output file.
ORB features and short logs keep the whole file cheap; the feature cache is on (one cache
folder for the session: the batch shares it between its tasks).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from slam_lcd.config import load_config

from support.paths import REPO

# many keyframes and loops on a 3-second log (as tests/cli/test_bad_input.py): every figure is non-zero
LOOPY = ["features.kind=orb", "frontend.kf_min_translation=0.05", "lcd.exclude_recent_n=1", "lcd.top_k=1",
         "lcd.pnp_min_inliers=12", "backend.gnc_every_n_loops=2"]
GOOD = ("demo_mcap", "demo_ros1", "demo_ros2")
FIGURES = ("frames", "keyframes", "loops_proposed", "loops_verified", "loops_accepted", "loops_rejected",
           "false_loops", "ate_before_m", "ate_after_m")


@pytest.fixture(scope="session")
def batch_inputs(tmp_path_factory):
    """(folder of the 4 logs, config): demo logs of seeds 1-3 in three formats, and a corrupt bag."""
    from slam_lcd.sim import make_demo_log

    root = tmp_path_factory.mktemp("batch")
    logs = root / "logs"
    logs.mkdir()
    for (name, fmt, suffix), seed in zip((("demo_mcap", "mcap", ".mcap"), ("demo_ros1", "rosbag1", ".bag"),
                                          ("demo_ros2", "rosbag2", "")), (1, 2, 3), strict=True):
        make_demo_log(logs / f"{name}{suffix}", fmt, frames=30, seed=seed, width=160, height=120)
    data = (logs / "demo_ros1.bag").read_bytes()
    (logs / "corrupt.bag").write_bytes(data[: int(len(data) * 0.4)])
    cfg = load_config("default", [*LOOPY, f"features.cache_dir={root / 'cache'}"])
    return logs, cfg


def log_path(logs: Path, name: str) -> Path:
    return {"demo_mcap": logs / "demo_mcap.mcap", "demo_ros1": logs / "demo_ros1.bag",
            "demo_ros2": logs / "demo_ros2", "corrupt": logs / "corrupt.bag"}[name]


@pytest.fixture(scope="session")
def reference(batch_inputs, tmp_path_factory):
    """What `slam-lcd run` gives on each good log with the same configuration: {name: RunResult}."""
    from slam_lcd.run import OutputOptions, run_log

    logs, cfg = batch_inputs
    out = tmp_path_factory.mktemp("batch_reference")
    return {n: run_log(log_path(logs, n), out / n, cfg, output=OutputOptions(progress=False)) for n in GOOD}


def file_states(folder: Path) -> dict:
    """Every file below ``folder`` with its inode and mtime: a rewrite changes one of them."""
    return {str(p.relative_to(folder)): (p.stat().st_ino, p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def check_batch(res, out: Path, logs: Path, cfg, reference) -> None:
    """3 complete result folders, 1 error row naming the corrupt file, figures equal to `run`'s."""
    from slam_lcd.batch.done import completed_report
    from slam_lcd.batch.summary import read_summary_csv

    by_name = {r["name"]: r for r in res.rows}
    assert sorted(by_name) == sorted([*GOOD, "corrupt"])
    assert by_name["corrupt"]["status"] == "error"
    msg = by_name["corrupt"]["message"]
    assert "corrupt.bag" in msg and "\n" not in msg and "rosbag1" in msg, msg
    assert not (out / "corrupt").exists()
    for name in GOOD:
        row = by_name[name]
        assert row["status"] in ("ok", "skipped"), row
        report, why = completed_report(out / name, cfg, log_path(logs, name))
        assert report is not None, why
        assert not (out / name / "PARTIAL.txt").exists()
        ref = reference[name]
        expected = dict(frames=ref.n_frames, keyframes=ref.n_keyframes, loops_proposed=ref.loops_proposed,
                        loops_verified=ref.loops_verified, loops_accepted=ref.loops_accepted,
                        loops_rejected=ref.loops_proposed - ref.loops_accepted,
                        false_loops=ref.false_loops_accepted, ate_before_m=ref.ate_before, ate_after_m=ref.ate_after)
        assert {k: row[k] for k in FIGURES} == expected, name
        assert ref.loops_accepted > 0 and ref.ate_before is not None  # figures that say something
        # the per-log folder holds what `run` writes, with the same contents where they are deterministic
        assert sorted(report["outputs"]) == sorted(ref.outputs)
        for f in ("loops.csv", "corrected.tum", "config.yaml"):
            assert (out / name / f).read_bytes() == (ref.out_dir / f).read_bytes(), (name, f)
    # summary.csv carries the same numbers, at full precision
    csv_rows = {r["name"]: r for r in read_summary_csv(out / "summary.csv")}
    for name in GOOD:
        assert {k: csv_rows[name][k] for k in FIGURES} == {k: by_name[name][k] for k in FIGURES}
    assert csv_rows["corrupt"]["status"] == "error" and csv_rows["corrupt"]["message"] == msg
    md = (out / "summary.md").read_text()
    assert "| corrupt | error |" in md and "corrupt.bag" in md
    assert (out / "ate_before_after.png").stat().st_size > 1000
    assert not (out / "PARTIAL.txt").exists()
    assert res.failed and not res.interrupted


def test_batch_on_local_pool_then_rerun_does_no_work(batch_inputs, reference, tmp_path):
    from slam_lcd.batch import run_batch

    logs, cfg = batch_inputs
    out = tmp_path / "out"
    res = run_batch([logs], out, cfg, workers=2, progress=False)
    assert res.engine == "local"
    check_batch(res, out, logs, cfg, reference)
    assert all(r["status"] == "ok" for r in res.rows if r["name"] != "corrupt")
    # one feature cache for all tasks: every log's features are in it
    fp_dirs = list((Path(cfg.features.cache_dir) / "features").iterdir())
    assert len(fp_dirs) == 1
    assert len([d for d in fp_dirs[0].iterdir() if d.name.startswith("demo_")]) >= 3

    before = {n: file_states(out / n) for n in GOOD}
    again = run_batch([logs], out, cfg, workers=2, progress=False)
    assert {r["name"]: r["status"] for r in again.rows} == {**dict.fromkeys(GOOD, "skipped"), "corrupt": "error"}
    check_batch(again, out, logs, cfg, reference)
    assert {n: file_states(out / n) for n in GOOD} == before  # not a file rewritten, none added

    # --force redoes a log; a changed configuration redoes it too (its outputs are of another config)
    one = [log_path(logs, "demo_mcap")]
    forced = run_batch(one, out, cfg, workers=1, force=True, progress=False)
    assert [r["status"] for r in forced.rows] == ["ok"] and not forced.failed
    assert file_states(out / "demo_mcap")["report.json"] != before["demo_mcap"]["report.json"]
    other = load_config("default", [*LOOPY, f"features.cache_dir={cfg.features.cache_dir}", "lcd.top_k=2"])
    from slam_lcd.batch.done import completed_report

    assert completed_report(out / "demo_mcap", other, one[0]) == (None, "earlier outputs are of another configuration")


def _ray_temp_dir(tmp_path: Path) -> tuple[Path, bool]:
    """Ray's session folder: under tmp_path when short enough for its Unix sockets (107 bytes)."""
    if len(str(tmp_path)) <= 40:
        return tmp_path / "ray", False
    return Path(tempfile.mkdtemp(prefix="slray", dir="/tmp")), True


def test_batch_on_local_ray_and_ctrl_c(batch_inputs, reference, tmp_path, monkeypatch):
    ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'slam-lcd[ray]')")
    import shutil

    from slam_lcd.batch import run_batch

    logs, cfg = batch_inputs
    temp, remove = _ray_temp_dir(tmp_path)
    monkeypatch.setenv("RAY_USAGE_STATS_ENABLED", "0")
    # Ray's workers import this checkout's slam_lcd, as the test does
    ray.init(num_cpus=2, include_dashboard=False, _temp_dir=str(temp), _node_ip_address="127.0.0.1",
             log_to_driver=False, configure_logging=False,
             runtime_env={"env_vars": {"PYTHONPATH": str(REPO)}})
    try:
        out = tmp_path / "out"
        res = run_batch([logs], out, cfg, ray="local", progress=False)
        assert res.engine == "ray"
        check_batch(res, out, logs, cfg, reference)
        before = {n: file_states(out / n) for n in GOOD}
        again = run_batch([logs], out, cfg, ray="local", progress=False)
        assert {r["name"]: r["status"] for r in again.rows} == {**dict.fromkeys(GOOD, "skipped"), "corrupt": "error"}
        assert {n: file_states(out / n) for n in GOOD} == before

        # Ctrl-C after the first result: the running tasks are cancelled and write partial sets
        stopped = tmp_path / "stopped"
        res = run_batch([log_path(logs, n) for n in GOOD], stopped, cfg, ray="local", workers=2, progress=False,
                        on_row=_interrupt_after_first())
        _check_interrupted(res, stopped, cfg, logs)
    finally:
        ray.shutdown()
        if remove:
            shutil.rmtree(temp, ignore_errors=True)


def _interrupt_after_first():
    seen = []

    def on_row(row):
        seen.append(row)
        if len(seen) == 1:
            raise KeyboardInterrupt

    return on_row


def _check_interrupted(res, out: Path, cfg, logs: Path) -> None:
    """Finished logs kept, the others interrupted (partial set or nothing) or cancelled, summary partial."""
    from slam_lcd.batch.done import completed_report

    assert res.interrupted
    statuses = [r["status"] for r in res.rows]
    assert statuses.count("ok") >= 1 and set(statuses) <= {"ok", "interrupted", "cancelled"}, statuses
    assert len(res.rows) == 3
    for r in res.rows:
        folder = out / r["name"]
        if r["status"] == "ok":
            assert completed_report(folder, cfg, r["log"])[0] is not None
        elif folder.exists():  # a set marked partial, never a mix
            assert (folder / "PARTIAL.txt").exists()
            assert completed_report(folder, cfg, r["log"])[0] is None
    assert (out / "PARTIAL.txt").exists()
    assert "Interrupted (Ctrl-C)" in (out / "summary.md").read_text()


def test_ctrl_c_on_the_first_of_two_logs_finished_together_keeps_both(batch_inputs, tmp_path, monkeypatch):
    """Two logs that finish within one wait of the pool, a Ctrl-C while the first row is handed on: the
    second log's finished set is reported ``ok``, not lost as ``cancelled`` beside its complete folder."""
    import concurrent.futures as cf

    from slam_lcd.batch import run_batch

    real_wait = cf.wait
    monkeypatch.setattr(cf, "wait", lambda fs, return_when=None: real_wait(fs, return_when=cf.ALL_COMPLETED))
    logs, cfg = batch_inputs
    out = tmp_path / "out"
    names = GOOD[:2]
    res = run_batch([log_path(logs, n) for n in names], out, cfg, workers=2, progress=False,
                    on_row=_interrupt_after_first())
    assert res.interrupted
    assert [r["status"] for r in res.rows] == ["ok", "ok"], [(r["name"], r["status"]) for r in res.rows]


def test_ctrl_c_on_local_pool_keeps_finished_logs(batch_inputs, tmp_path):
    from slam_lcd.batch import run_batch

    logs, cfg = batch_inputs
    out = tmp_path / "out"
    res = run_batch([log_path(logs, n) for n in GOOD], out, cfg, workers=2, progress=False,
                    on_row=_interrupt_after_first())
    _check_interrupted(res, out, cfg, logs)
    # the same command again finishes the batch: the finished log is skipped, the others run
    done_before = [r["name"] for r in res.rows if r["status"] == "ok"]
    again = run_batch([log_path(logs, n) for n in GOOD], out, cfg, workers=1, progress=False)
    assert {r["name"]: r["status"] for r in again.rows} == {n: "skipped" if n in done_before else "ok" for n in GOOD}
    assert not again.interrupted and not (out / "PARTIAL.txt").exists()


@pytest.mark.parametrize("workers", [1, 2])
def test_cli_exit_status_and_real_ctrl_c(batch_inputs, tmp_path, workers):
    """`slam-lcd batch`: a Ctrl-C as a terminal sends it (SIGINT to the whole process group) after the
    first log: exit 130, finished logs kept, the others partial, the summary partial, no traceback.
    With 1 worker the run in the driver takes it; with 2 the pool's workers get it from the driver.
    Then: exit 2 when a log fails."""
    logs, cfg = batch_inputs
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    sets = [a for s in [*LOOPY, f"features.cache_dir={cfg.features.cache_dir}"] for a in ("--set", s)]
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "slam_lcd", "batch", str(log_path(logs, "demo_mcap")),
            str(log_path(logs, "demo_ros1")), str(log_path(logs, "demo_ros2")), "--out", str(out),
            "--workers", str(workers), "--no-progress", *sets]
    # SIG_DFL in the child, as a terminal gives it: a shell that starts the tests in the background
    # hands them SIGINT ignored, which Python would keep
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    first = proc.stdout.readline()
    assert first.startswith("[1/3] ok"), (first, proc.stderr.read() if proc.poll() is not None else "")
    os.killpg(proc.pid, signal.SIGINT)
    rest, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, (rest, err)
    assert "Traceback" not in err
    assert (out / "PARTIAL.txt").exists()
    done = first.split()[2].rstrip(":")
    assert (out / done / "report.json").exists() and not (out / done / "PARTIAL.txt").exists()
    assert "interrupted" in rest
    if workers == 2:
        return

    bad = subprocess.run([sys.executable, "-m", "slam_lcd", "batch", str(log_path(logs, "corrupt")), "--out",
                          str(tmp_path / "bad"), "--no-progress", *sets], env=env, capture_output=True, text=True,
                         timeout=120)
    assert bad.returncode == 2, bad.stderr
    assert "[1/1] error" in bad.stdout and "corrupt.bag" in bad.stdout


def test_weights_and_vocabulary_loaded_once_per_worker(batch_inputs, tmp_path, monkeypatch):
    """Two logs in one worker (the inline engine: this process): one extractor load, one vocabulary load,
    and the vocabulary is the one every run's loop detector quantises with."""
    import numpy as np

    from slam_lcd.batch import run_batch, worker
    from slam_lcd.vocab import Vocabulary, train_hkmeans

    logs, cfg = batch_inputs
    rng = np.random.default_rng(0)
    vocab_file = tmp_path / "orb_vocab.npz"
    train_hkmeans([rng.integers(0, 256, size=(60, 32), dtype=np.uint8) for _ in range(8)], 4, 2).save(vocab_file)
    monkeypatch.setattr(worker, "_EXTRACTORS", {})
    monkeypatch.setattr(worker, "_VOCABS", {})
    monkeypatch.setattr(worker, "LOADS", {"extractor": 0, "vocabulary": 0})
    quantized = []
    real = Vocabulary.quantize

    def counting(self, d):
        quantized.append(id(self))
        return real(self, d)

    monkeypatch.setattr(Vocabulary, "quantize", counting)
    res = run_batch([log_path(logs, "demo_mcap"), log_path(logs, "demo_ros1")], tmp_path / "out", cfg, workers=1,
                    vocab=vocab_file, progress=False)
    assert [r["status"] for r in res.rows] == ["ok", "ok"]
    assert worker.LOADS == {"extractor": 1, "vocabulary": 1}
    assert len(set(quantized)) == 1 and len(quantized) > 10


def test_discovery_names_globs_and_ground_truth_folder(tmp_path):
    from slam_lcd.batch.discovery import discover_logs, ground_truth_in
    from slam_lcd.errors import InputError

    for rel in ("day1/log.bag", "day2/log.bag", "day2/other.mcap", "day2/notes.txt", "day2/ros2/metadata.yaml"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text("x")
    entries = discover_logs([tmp_path / "day1" / "log.bag", tmp_path / "day2", str(tmp_path / "day*" / "log.bag")])
    assert [(e.path.relative_to(tmp_path).as_posix(), e.name) for e in entries] == [
        ("day1/log.bag", "day1__log"), ("day2/log.bag", "day2__log"), ("day2/other.mcap", "other"),
        ("day2/ros2", "ros2")]
    with pytest.raises(InputError, match="pattern matches 1 entries, none a log"):
        discover_logs([str(tmp_path / "day2" / "*.txt")])
    with pytest.raises(InputError, match="matches nothing"):
        discover_logs([str(tmp_path / "nope" / "*.bag")])
    gt = tmp_path / "gt"
    gt.mkdir()
    (gt / "other.tum").write_text("")
    assert ground_truth_in(gt, entries[2]) == gt / "other.tum"
    assert ground_truth_in(gt, entries[3]) is None
    (gt / "other.txt").write_text("")
    with pytest.raises(InputError, match="several ground-truth files"):
        ground_truth_in(gt, entries[2])


def test_missing_ground_truth_in_gt_dir_is_an_error_row(batch_inputs, tmp_path):
    from slam_lcd.batch import run_batch

    logs, cfg = batch_inputs
    (tmp_path / "gt").mkdir()
    res = run_batch([log_path(logs, "demo_mcap")], tmp_path / "out", cfg, workers=1, gt_dir=tmp_path / "gt",
                    progress=False)
    (row,) = res.rows
    assert row["status"] == "error" and "no ground-truth file" in row["message"] and "demo_mcap" in row["message"]


def test_ray_missing_is_a_one_line_error(monkeypatch, tmp_path, batch_inputs):
    import builtins

    from slam_lcd.batch import run_batch
    from slam_lcd.errors import InputError

    real_import = builtins.__import__

    def no_ray(name, *a, **k):
        if name == "ray" or name.startswith("ray."):
            raise ImportError("no ray")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_ray)
    logs, cfg = batch_inputs
    with pytest.raises(InputError, match=r"pip install 'slam-lcd\[ray\]'"):
        run_batch([log_path(logs, "demo_mcap")], tmp_path / "out", cfg, ray="local", progress=False)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("when", ["after_publish", "before_any_output"])
def test_ctrl_c_around_publish_is_reported_by_what_the_folder_holds(batch_inputs, tmp_path, monkeypatch, when):
    """A Ctrl-C that lands after run_log published its complete set (the race CI met on Ray) is an
    ``ok`` row from that set's report; one that lands before any output is ``interrupted``, nothing written."""
    import slam_lcd.run.runner as runner
    from slam_lcd.batch.done import completed_report
    from slam_lcd.batch.worker import LogTask, SharedWork, run_task

    logs, cfg = batch_inputs
    real = runner.run_log

    def run_then_ctrl_c(*args, **kwargs):
        if when == "after_publish":
            real(*args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "run_log", run_then_ctrl_c)
    out = tmp_path / "demo_ros1"
    task = LogTask(log=str(log_path(logs, "demo_ros1")), name="demo_ros1", out_dir=str(out))
    row = run_task(task, SharedWork(config=cfg))
    if when == "after_publish":
        assert row["status"] == "ok" and "interrupted" in row["message"], row
        report, why = completed_report(out, cfg, task.log)
        assert report is not None, why
        assert row["keyframes"] == report["keyframes"] > 0
    else:
        assert row["status"] == "interrupted" and "no new outputs" in row["message"], row
        assert not out.exists()
