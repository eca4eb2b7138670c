"""SIGTERM and SIGHUP are handled like Ctrl-C; nothing of ours is left behind (docs/robustness.md, "Signals").

Every case runs ``python -m slam_lcd`` in a fresh process on a small demo log and sends the
signal from outside, as ``timeout``, ``systemd`` or ``docker stop`` would: the command exits
143 (SIGTERM) with one line, the output folder holds nothing, a complete set or a set marked
partial, and no staging folder, temporary file or process of ours is left.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

from support.bad_input_files import REPO, leftovers, sha256_tree

ORB = ["--features", "orb", "--no-feature-cache", "--no-progress", "--set", "run.plots=false"]

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")


def _env(tag: str | None = None) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), *([env["PYTHONPATH"]] if env.get("PYTHONPATH") else [])])
    if tag:
        env["SLAM_LCD_TEST_TAG"] = tag
    return env


def _start(argv, tag=None, cwd=None) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "slam_lcd", *map(str, argv)], env=_env(tag), cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # a signal to it never reaches pytest


def _tagged(tag: str) -> list[int]:
    """Processes alive (not zombies) whose environment carries ``tag``."""
    found = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            if f"SLAM_LCD_TEST_TAG={tag}".encode() not in (d / "environ").read_bytes():
                continue
            if (d / "stat").read_text().rsplit(")", 1)[1].split()[0] in ("Z", "X"):
                continue
        except OSError:
            continue
        found.append(int(d.name))
    return found


def _run_names():
    from slam_lcd.outputs.write import RUN_OUTPUTS

    return set(RUN_OUTPUTS) | {"PARTIAL.txt"}


def _state(out: Path, earlier_sha: dict | None) -> str:
    """'absent', 'earlier' (byte-identical), 'complete' or 'partial'; fails on anything else."""
    assert not leftovers(out, out.parent), leftovers(out, out.parent)
    if not out.exists():
        assert earlier_sha is None, "the earlier run's folder went away"
        return "absent"
    if earlier_sha is not None and sha256_tree(out) == earlier_sha:
        return "earlier"
    present = {p.name for p in out.iterdir()}
    assert present <= _run_names() | {"notes.txt"}, present
    rep = json.loads((out / "report.json").read_text()) if (out / "report.json").exists() else None
    if "PARTIAL.txt" in present:
        assert rep is None or rep.get("interrupted") is True or "config.yaml" in present
        return "partial"
    assert {"config.yaml", "report.json", "report.md", "corrected.tum"} <= present, present
    assert rep is not None and not rep.get("interrupted")
    return "complete"


@pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="needs /proc")
def test_run_killed_by_sigterm_at_ten_instants_leaves_a_consistent_folder(small_log, tmp_path):
    """`run` stopped by SIGTERM anywhere (start-up, streaming, the back end, writing): exit 143 and one
    line, or 0 when it had finished; a new folder is absent, complete or marked partial, an earlier
    run's folder keeps its bytes or holds a complete or partial new set; no staging folder stays."""
    t0 = time.perf_counter()
    full = tmp_path / "full"
    p = _start(["run", small_log, "--out", full, *ORB])
    out, err = p.communicate(timeout=300)
    duration = time.perf_counter() - t0
    assert p.returncode == 0, err
    assert _state(full, None) == "complete"
    seen = []
    for k in range(10):
        out_dir = tmp_path / f"k{k}" / "run"
        earlier_sha = None
        if k % 2:  # into a folder holding an earlier run's set and a file of the user's
            shutil.copytree(full, out_dir)
            (out_dir / "notes.txt").write_text("mine\n")
            earlier_sha = sha256_tree(out_dir)
        p = _start(["run", small_log, "--out", out_dir, *ORB])
        time.sleep(duration * (0.1 + 0.1 * k))  # start-up, streaming, back end, writing
        p.send_signal(signal.SIGTERM)
        _, err = p.communicate(timeout=120)
        assert p.returncode in (0, 143), (k, p.returncode, err)
        assert "Traceback" not in err, err
        if p.returncode == 143:  # one line: stopped before the main pass, or the partial result's warning
            lines = [ln for ln in err.splitlines() if ln.strip()]
            assert len(lines) == 1 and ("terminated (SIGTERM)" in lines[0] or "interrupted (SIGTERM)" in lines[0]), err
        state = _state(out_dir, earlier_sha)
        if state == "partial":
            assert "SIGTERM" in (out_dir / "PARTIAL.txt").read_text()
        if earlier_sha is not None:
            assert (out_dir / "notes.txt").read_text() == "mine\n"
        seen.append((p.returncode, state))
    assert any(rc == 143 for rc, _ in seen), seen
    assert {"absent", "partial"} & {s for _, s in seen}, seen


def test_a_later_run_removes_stale_staging_folders_of_ours_only(small_log, tmp_path):
    """A run killed outright (SIGKILL) cannot clean up: the next run into that folder removes the staging
    folders whose process is gone on this host, and leaves a live process's, another host's and the user's."""
    from slam_lcd.config import load_config
    from slam_lcd.outputs.output_set import STAGING_PREFIX, _host
    from slam_lcd.run import OutputOptions, run_log

    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    out = tmp_path / "run"
    out.mkdir()
    stale = [out / f"{STAGING_PREFIX}{_host()}.{gone.pid}.abc123",
             tmp_path / f"{STAGING_PREFIX}{_host()}.{gone.pid}.x1"]
    kept = [out / f"{STAGING_PREFIX}{_host()}.{os.getpid()}.live12",
            out / f"{STAGING_PREFIX}otherhost.{gone.pid}.far12", out / ".my-own-folder"]
    for d in stale + kept:
        d.mkdir()
        (d / "corrected.tum").write_text("1 0 0 0 0 0 0 1\n")
    run_log(small_log, out, load_config("default", ["features.kind=orb", "features.feature_cache=false",
                                                    "run.plots=false"]), output=OutputOptions(progress=False))
    assert not any(d.exists() for d in stale)
    assert all(d.exists() for d in kept)
    assert (out / "report.json").exists()


STORM_CHILD = r"""
import signal, sys, time
from pathlib import Path
from slam_lcd.runtime.interrupts import install_stop_signals
from slam_lcd.files.atomic import atomic_write
from slam_lcd.io.writers import open_writer
from slam_lcd.io import message_builders as M

signal.signal(signal.SIGINT, signal.default_int_handler)
install_stop_signals()
d = Path(sys.argv[1])
data = b"x" * 200_000
counts = [0, 0]

def work(end):
    i = 0
    while time.monotonic() < end:
        try:
            i += 1
            if i % 10:
                with atomic_write(d / "t.bin", "wb") as fh:
                    fh.write(data)
            else:
                with open_writer(d / "t.mcap", "mcap") as w:
                    pass
            counts[0] += 1
        except KeyboardInterrupt:
            counts[1] += 1

# one write of each kind first: the writers' lazy imports happen before any signal (this test is about
# the writers' temporaries; a signal inside an import is the CLI's one-line case, tested elsewhere)
with atomic_write(d / "t.bin", "wb") as fh:
    fh.write(data)
with open_writer(d / "t.mcap", "mcap") as w:
    pass
end = time.monotonic() + float(sys.argv[2])
ready = False
while time.monotonic() < end:
    try:
        if not ready:  # the parent starts signalling once it reads this line: inside the try
            ready = True
            print("ready", flush=True)
        work(end)
    except KeyboardInterrupt:
        counts[1] += 1
for s in (signal.SIGINT, signal.SIGTERM):
    signal.signal(s, signal.SIG_IGN)
print(counts[0], counts[1], flush=True)
"""


def test_atomic_writers_leave_no_temporary_under_a_storm_of_signals(tmp_path):
    """Hundreds of SIGINTs and SIGTERMs during writes of a 200 kB file (and of empty logs): every
    interrupted write leaves nothing beside its target, whatever step the signal lands in."""
    import random

    d = tmp_path / "out"
    d.mkdir()
    script = tmp_path / "child.py"
    script.write_text(STORM_CHILD)
    p = subprocess.Popen([sys.executable, str(script), str(d), "4"], env=_env(), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, start_new_session=True)
    assert p.stdout.readline().strip() == "ready"
    rng = random.Random(0)
    sent = 0
    t_end = time.monotonic() + 3.0
    while time.monotonic() < t_end and p.poll() is None:
        p.send_signal(signal.SIGINT if sent % 2 else signal.SIGTERM)
        sent += 1
        time.sleep(rng.uniform(0.0005, 0.004))
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0, err
    writes, stopped = map(int, out.split())
    assert stopped > 50 and writes > 50, (writes, stopped, sent)
    assert sorted(x.name for x in d.iterdir()) <= ["t.bin", "t.mcap"], sorted(x.name for x in d.iterdir())


def _batch_started(small_log, tmp_path, tag: str):
    """`batch` of three copies of the small log on a pool of 2 workers, returned once a worker is mid-log."""
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in "abc":
        shutil.copy(small_log, logs / f"{name}.mcap")
    out = tmp_path / "out"
    p = _start(["batch", logs, "--out", out, "--workers", "2", *ORB], tag=tag)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and p.poll() is None:
        if out.is_dir() and any(x.name.startswith(".slam-lcd-staging") for x in out.iterdir()):
            return p, out
        time.sleep(0.05)
    _, err = p.communicate(timeout=60)
    pytest.fail(f"no log started (rc {p.returncode}): {err}")


def _none_alive(tag: str, within_s: float) -> list[int]:
    deadline = time.monotonic() + within_s
    while (alive := _tagged(tag)) and time.monotonic() < deadline:
        time.sleep(0.1)
    return alive


@pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="needs /proc")
def test_batch_killed_by_sigterm_stops_its_workers_and_writes_a_partial_summary(small_log, tmp_path):
    """SIGTERM to the batch's driver: exit 143, the running logs write partial sets, the summary is
    written marked partial, no staging folder stays, and 5 s later no process of the batch is alive
    (workers, fork server, resource tracker)."""
    tag = uuid.uuid4().hex
    p, out = _batch_started(small_log, tmp_path, tag)
    p.send_signal(signal.SIGTERM)
    stdout, err = p.communicate(timeout=120)
    assert p.returncode == 143, (stdout, err)
    assert "Traceback" not in err, err
    assert not _none_alive(tag, 5.0), "processes of the batch still alive 5 s after it ended"
    assert "SIGTERM" in (out / "PARTIAL.txt").read_text()
    assert (out / "summary.csv").exists()
    assert not leftovers(out), leftovers(out)
    for d in out.iterdir():  # a log's folder is complete or marked partial, never a mix
        if d.is_dir():
            assert (d / "PARTIAL.txt").exists() or (d / "report.json").exists(), sorted(x.name for x in d.iterdir())


@pytest.mark.skipif(not Path("/proc/self/environ").exists(), reason="needs /proc")
def test_batch_driver_killed_outright_stops_its_workers(small_log, tmp_path):
    """The driver killed with SIGKILL (nothing of it runs): its workers notice, stop their logs (a set
    marked partial or nothing), run nothing more and exit, and the fork server and resource tracker go
    with them; a later run into a log's folder finds no staging folder of a gone process."""
    tag = uuid.uuid4().hex
    p, out = _batch_started(small_log, tmp_path, tag)
    p.kill()
    p.communicate(timeout=60)
    assert not _none_alive(tag, 10.0), "processes of the batch still alive 10 s after its driver died"
    assert not leftovers(out), leftovers(out)
    for d in out.iterdir():  # a log's folder is complete or marked partial, never a mix
        if d.is_dir():
            assert (d / "PARTIAL.txt").exists() or (d / "report.json").exists(), sorted(x.name for x in d.iterdir())


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_signal_while_python_exits_keeps_the_commands_status(small_log, tmp_path, sig):
    """A Ctrl-C or SIGTERM sent when a command has printed its result (the interpreter returning or
    tearing down) leaves the command's status (0) or the signal's (130 / 143) with its one line:
    never a death by the signal with nothing said. Without ignoring stop signals once the command
    has a status, every one of these runs of ``python -m slam_lcd info`` died by SIGINT (exit -2)."""
    bad, sent = [], 0
    for i in range(10):
        p = subprocess.Popen([sys.executable, "-u", "-m", "slam_lcd", "info", str(small_log)], env=_env(),
                             start_new_session=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        for line in p.stdout:  # its last line: the command is returning or Python is exiting
            if line.strip().startswith("/tf_static"):
                break
        time.sleep(0.002 * (i % 5))
        if p.poll() is None:
            os.killpg(p.pid, getattr(signal, sig))
            sent += 1
        _, err = p.communicate(timeout=60)
        expected = {0, 130 if sig == "SIGINT" else 143}
        if p.returncode not in expected or (p.returncode and len(err.strip().splitlines()) != 1):
            bad.append(f"run {i}: exit {p.returncode}, stderr {err.strip()[-200:]!r}")
    assert not bad, "\n".join(bad)
    assert sent >= 5, f"only {sent} of 10 runs were still alive to be signalled"
