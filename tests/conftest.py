"""Shared fixtures: where the real data lives (``../shared`` or ``$SLAM_LCD_SHARED``)."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest

from support.map_logs import visits
from support.offline import offline_env
from support.paths import REPO
from support.slow_files import SLOW_FILES


def pytest_configure(config):
    """With several xdist workers, each worker's numerical libraries get one thread.

    Why: the suite runs two workers on a two-core machine; torch, numpy's BLAS and faiss each
    start a thread per core in both workers, so four or more busy threads share two cores and
    OpenMP's spinning workers wait on each other. A test that needs more threads sets them
    itself (and restores them).
    """
    if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) < 2:
        return
    import faiss  # noqa: F401 - loaded first, so that its OpenMP runtime is among those limited
    import torch
    from threadpoolctl import threadpool_limits

    torch.set_num_threads(1)
    threadpool_limits(1)




def pytest_collection_modifyitems(session, config, items):
    """The slow files first (``SLOW_FILES``); the others keep their order."""
    rank = {name: i for i, name in enumerate(SLOW_FILES)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0].removeprefix("tests/"), len(rank)))


def shared_root() -> Path | None:
    env = os.environ.get("SLAM_LCD_SHARED")
    cand = Path(env) if env else REPO.parent / "shared"
    return cand if (cand / "data").is_dir() else None


@pytest.fixture(scope="session")
def shared() -> Path:
    root = shared_root()
    if root is None:
        pytest.skip("real data folder ../shared (or $SLAM_LCD_SHARED) is absent")
    return root


@pytest.fixture(scope="session")
def shared_data(shared) -> Path:
    return shared / "data"


@pytest.fixture(scope="session")
def superpoint_weights(shared) -> Path:
    p = shared / "weights" / "superpoint_community.pth"
    if not p.is_file():
        pytest.skip(f"SuperPoint test checkpoint not found at {p}")
    return p


def once_per_run(tmp_path_factory, name: str, build):
    """``build(folder)``'s JSON-able result, built once per test run and shared by pytest-xdist's workers.

    Why: a session fixture runs once per *worker*; the expensive read-only ones (a rendered demo
    log, a run's outputs) are built by the first worker that needs them, under a file lock, in the
    run's common temporary folder, and the others wait and read the result. Without xdist it is an
    ordinary session folder. Tests must treat the folder as read-only.
    """
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return build(tmp_path_factory.mktemp(name))
    from filelock import FileLock

    folder = tmp_path_factory.getbasetemp().parent / f"once-{name}"
    with FileLock(f"{folder}.lock"):
        done = folder.with_name(folder.name + ".json")
        if done.is_file():
            return json.loads(done.read_text())
        shutil.rmtree(folder, ignore_errors=True)  # what a worker that failed to build left
        folder.mkdir()
        value = build(folder)
        done.write_text(json.dumps(value))
        return value


# --------------------------------------------------------------------------- offline first run
OFFLINE_DEMO_ARGS = ["--frames", "470", "--size", "320x240"]  # a little more than one lap: loops close


@pytest.fixture(scope="session")
def offline_demo(tmp_path_factory):
    """`slam-lcd demo` run once as a user's first run offline: (completed process, out dir, demo log, env).

    Shared by the offline-fallback test and the evo comparison on a demo run (one render,
    one pipeline run for both)."""
    import subprocess
    import sys

    def build(root: Path) -> dict:
        cache = root / "cache"
        cache.mkdir()
        env = offline_env(cache)
        out = root / "demo_out"
        # progress on (the default): stderr is a pipe, so the demo prints one line per stage, no bar
        proc = subprocess.run([sys.executable, "-m", "slam_lcd", "demo", *OFFLINE_DEMO_ARGS, "--out", str(out)],
                              env=env, capture_output=True, text=True, timeout=1200)
        logs = sorted((cache / "demo").glob("*.mcap")) if (cache / "demo").is_dir() else []
        return {"args": proc.args, "returncode": proc.returncode, "stdout": proc.stdout, "stderr": proc.stderr,
                "out": str(out), "log": str(logs[0]) if logs else None, "env": env}

    r = once_per_run(tmp_path_factory, "offline", build)
    proc = subprocess.CompletedProcess(r["args"], r["returncode"], r["stdout"], r["stderr"])
    return proc, Path(r["out"]), (Path(r["log"]) if r["log"] else None), r["env"]


# --------------------------------------------------------------------------- the short demo log
# 470 frames: a little more than one lap of the demo block, so the start is revisited and loops close
DEMO_LOG = dict(frames=470, seed=1, depth=True, width=320, height=240)


@pytest.fixture(scope="session")
def demo_log_settings() -> dict:
    """make_demo_log's arguments of the short demo log (for a copy in another format)."""
    return dict(DEMO_LOG)


@pytest.fixture(scope="session")
def demo_log_mcap(tmp_path_factory) -> Path:
    """The short RGB-D demo log as MCAP, rendered once per session (~11 s on two cores).

    Read-only for every user: the runs on it write elsewhere, and tests that edit a log copy it."""
    from slam_lcd.sim import make_demo_log

    def build(folder: Path) -> str:
        make_demo_log(folder / "demo.mcap", "mcap", **DEMO_LOG)
        return str(folder / "demo.mcap")

    return Path(once_per_run(tmp_path_factory, "demo_log", build))


@pytest.fixture(scope="session")
def small_log(tmp_path_factory) -> Path:
    """A 120-frame RGB-D demo log (320x240, seed 1) for tests that start, stop and kill runs on it
    (signals, the live viewer), rendered once per test run. Read-only: tests that edit a log copy it."""
    from slam_lcd.sim import make_demo_log

    def build(folder: Path) -> str:
        make_demo_log(folder / "small.mcap", "mcap", frames=120, seed=1, width=320, height=240)
        return str(folder / "small.mcap")

    return Path(once_per_run(tmp_path_factory, "small_log", build))


# --------------------------------------------------------------------------- a run's outputs
@pytest.fixture(scope="session")
def report_run(tmp_path_factory, demo_log_mcap):
    """`slam-lcd run` (ORB, in-process through the CLI) on the short demo log: (exit status, out dir, log).

    One run shared by the tests of what a run writes (report.json/html, corrected.mcap,
    loop pictures, plots): ORB keeps it under a minute on two cores."""
    from slam_lcd.cli.main import main

    log = demo_log_mcap

    def build(folder: Path) -> list:
        out = folder / "out"
        rc = main(["run", str(log), "--out", str(out), "--features", "orb", "--no-feature-cache", "--no-progress",
                   "--set", "eval.rpe_delta=2.0", "--truth-world", str(DEMO_LOG["seed"])])
        return [rc, str(out)]

    rc, out = once_per_run(tmp_path_factory, "report_run", build)
    return rc, Path(out), log


# --------------------------------------------------------------------------- the map tests' logs
@pytest.fixture(scope="session")
def visit_logs(tmp_path_factory) -> dict[int, Path]:
    """Two visits of one route and a log of another world (:func:`support.map_logs.visits`), rendered
    once per test run for the map, map-rule and viewer tests. Read-only: the runs on them write elsewhere."""

    def build(folder: Path) -> dict:
        return {str(k): str(v) for k, v in visits(folder).items()}

    return {int(k): Path(v) for k, v in once_per_run(tmp_path_factory, "visit_logs", build).items()}
