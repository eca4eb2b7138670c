"""A saved map is never lost and a map run says what it did (docs/robustness.md, docs/multisession.md).

Every command line here would have changed or destroyed a map, written into one, left a lock file or
an empty folder behind, appended a log twice, or led with the session's own figures instead of the
map's. Refused commands must end before any write: exit 2, one line naming both paths, every file of
the map (and of every input) byte-identical, nothing new on disk.

Cheap on purpose: two 80-frame sessions of one demo world and 40 frames of another world, ORB
features, no plots, pictures or corrected.mcap; the map is built once per module.
"""
from __future__ import annotations

import csv
import hashlib
import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest

from slam_lcd.map.locks import creation_lock_path

from support.bad_input_files import assert_one_line, run_cli

ORB = ["--features", "orb", "--no-mcap", "--no-progress", "--set", "run.plots=false",
       "--set", "run.loop_pictures=false", "--set", "lcd.top_k=1"]


def tree(root) -> dict[str, str]:
    """Every file and folder under ``root`` (folders as ``'dir'``, files by sha256), lock files included."""
    root = Path(root)
    if not root.exists():
        return {}
    return {p.relative_to(root).as_posix(): "dir" if p.is_dir() else hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*"))}


@pytest.fixture(scope="module")
def world(tmp_path_factory, visit_logs):
    """Logs s1, s2 (a second visit of s1's route: another seed) and s4 (another world); map ``m1`` of s1,
    map ``m2`` of s1 + s2 with s2's run."""
    root = tmp_path_factory.mktemp("map_rules")
    logs = visit_logs
    orb = [*ORB, "--set", f"features.cache_dir={root / 'cache'}"]
    from slam_lcd.cli.main import main

    assert main(["run", str(logs[1]), "--map", str(root / "m1"), "--out", str(root / "r1"), *orb]) == 0
    shutil.copytree(root / "m1", root / "m2")
    assert main(["run", str(logs[2]), "--map", str(root / "m2"), "--out", str(root / "r2"), *orb]) == 0
    return SimpleNamespace(root=root, logs=logs, orb=orb, m1=root / "m1", m2=root / "m2", r1=root / "r1",
                           r2=root / "r2")


@pytest.fixture
def place(world, tmp_path):
    """A private folder holding a copy of map ``m1`` as ``map``."""
    shutil.copytree(world.m1, tmp_path / "map")
    return tmp_path


def refused(argv, capfd, *needles, watch=()) -> str:
    """Run ``argv``: exit 2, one line with every needle, and nothing under ``watch`` changed."""
    before = {str(w): tree(w) for w in watch}
    rc, _, err = run_cli([str(a) for a in argv], capfd)
    assert rc == 2, err
    line = assert_one_line(err, *map(str, needles))
    for w in watch:
        assert tree(w) == before[str(w)], f"{w} changed"
    return line


# ---------------------------------------------------------------------------- the map against --out
def test_run_whose_out_holds_the_map_is_refused_and_the_map_kept(world, place, capfd):
    """`run s2 --out OUT --map OUT/map`: the run's own map/ output would replace the map."""
    out = place
    line = refused(["run", world.logs[2], "--out", out, "--map", out / "map", *world.orb], capfd,
                   f"--out {out}", f"--map ({out / 'map'})", watch=[out])
    assert "holds the map folder" in line


@pytest.mark.parametrize("where", ["equal", "inside", "new-equal", "around-new"])
def test_run_out_equal_to_inside_or_around_the_map_is_refused(world, place, capfd, where):
    """`--out M`, `--out M/run`, a new map `--map NEW --out NEW`, `--map OUT/new --out OUT`: refused, nothing made."""
    m = place / "map"
    new = place / "new"
    mapdir, out = {"equal": (m, m), "inside": (m, m / "run"), "new-equal": (new, new),
                   "around-new": (place / "o" / "new", place / "o")}[where]
    refused(["run", world.logs[2], "--map", mapdir, "--out", out, *world.orb], capfd, str(out), str(mapdir),
            watch=[place])
    assert not new.exists() and not (place / "o").exists()


@pytest.mark.parametrize("where", ["equal", "inside", "around"])
def test_localize_and_batch_keep_out_apart_from_the_map(world, place, capfd, where):
    m = place / "map"
    out = {"equal": m, "inside": m / "loc", "around": place}[where]
    refused(["localize", world.logs[2], "--map", m, "--out", out, *world.orb], capfd, str(m), watch=[place])
    refused(["batch", world.logs[2], "--map", m, "--out", out, "--workers", "1", *world.orb], capfd, str(m),
            watch=[place])


@pytest.mark.parametrize("where", ["equal", "inside", "around"])
def test_map_export_keeps_out_apart_from_the_map(world, place, capfd, where):
    m = place / "map"
    out = {"equal": m, "inside": m / "tum", "around": place}[where]
    refused(["map", "export", m, "--to", "tum", out], capfd, str(m), watch=[place])


def test_map_export_onto_an_existing_file_names_out(world, place, capfd):
    """A folder export onto an existing file: one line naming OUT (never a temporary name)."""
    notes = place / "notes.txt"
    notes.write_text("mine\n")
    line = refused(["map", "export", place / "map", "--to", "tum", notes], capfd, str(notes), watch=[place])
    assert ".notes" not in line and "XXXX" not in line


# ---------------------------------------------------------------------------- every folder input against --out
def _walk_cases(world, d: Path) -> list[tuple[str, list, Path]]:
    """(name, argv with {OUT}, the input folder) for every command taking a folder input and an output."""
    from slam_lcd.sim import make_demo_log

    make_demo_log(d / "bag2", "rosbag2", frames=10, width=64, height=48)
    (d / "images").mkdir()
    for i in range(3):
        shutil.copy(world.logs[4], d / "images" / f"{i}.png")  # never read: refused first
    (d / "gt").mkdir()
    shutil.copytree(world.m1, d / "map")
    shutil.copytree(world.r1, d / "run")
    topic = "/ground_truth/pose"
    return [
        ("run log folder", ["run", d / "bag2", "--out", "{OUT}", *world.orb], d / "bag2"),
        ("run --map", ["run", world.logs[2], "--map", d / "map", "--out", "{OUT}", *world.orb], d / "map"),
        ("localize log folder", ["localize", d / "bag2", "--map", world.m1, "--out", "{OUT}", *world.orb], d / "bag2"),
        ("localize --map", ["localize", world.logs[2], "--map", d / "map", "--out", "{OUT}", *world.orb], d / "map"),
        ("batch log folder", ["batch", d / "bag2", "--out", "{OUT}", "--workers", "1", *world.orb], d / "bag2"),
        ("batch --gt-dir", ["batch", world.logs[2], "--gt-dir", d / "gt", "--out", "{OUT}", "--workers", "1",
                            *world.orb], d / "gt"),
        ("batch --map", ["batch", world.logs[2], "--map", d / "map", "--out", "{OUT}", "--workers", "1", *world.orb],
         d / "map"),
        ("eval-lcd", ["eval-lcd", d / "images", "--out", "{OUT}", "--features", "orb", "--no-progress"], d / "images"),
        ("vocab train", ["vocab", "train", d / "images", "--out", "{OUT}", "--features", "orb", "--no-progress"],
         d / "images"),
        ("export-map", ["export-map", d / "run", "{OUT}"], d / "run"),
        ("export rosbag2 log", ["export", f"{d / 'bag2'}:{topic}", "--to", "rosbag2", "{OUT}"], d / "bag2"),
        ("map export", ["map", "export", d / "map", "--to", "tum", "{OUT}"], d / "map"),
    ]


def test_every_command_keeps_out_apart_from_its_input_folders(world, tmp_path, capfd):
    """Each command taking a folder input, with --out (or OUT) equal to, inside and around that folder:
    refused before any write (exit 2, one line), every input byte-identical, nothing new on disk."""
    d = tmp_path / "in"
    d.mkdir()
    cases = _walk_cases(world, d)
    problems = []
    for name, argv, folder in cases:
        for where, out in (("equal", folder), ("inside", folder / "out"), ("around", folder.parent)):
            args = [out if a == "{OUT}" else a for a in argv]
            before = tree(tmp_path)
            rc, _, err = run_cli([str(a) for a in args], capfd)
            if rc != 2 or "Traceback" in err or len(err.strip().splitlines()) != 1:
                problems.append(f"{name}, out {where}: exit {rc}: {err.strip()[-300:]}")
            elif tree(tmp_path) != before:
                problems.append(f"{name}, out {where}: something was written")
    assert not problems, "\n".join(problems)


# ---------------------------------------------------------------------------- nothing left behind
def test_refused_or_failed_runs_leave_no_lock_and_no_new_folder(world, tmp_path, capfd):
    """A non-empty folder that is not a map, a missing log, a missing topic: no `.lock`, no new map folder."""
    user = tmp_path / "user_folder"
    user.mkdir()
    (user / "notes.txt").write_text("mine\n")
    refused(["run", world.logs[2], "--map", user, "--out", tmp_path / "o1", *world.orb], capfd,
            str(user), "holds no map", watch=[tmp_path])
    new = tmp_path / "new_map"
    refused(["run", tmp_path / "missing.mcap", "--map", new, "--out", tmp_path / "o2", *world.orb], capfd,
            "missing.mcap", watch=[tmp_path])
    refused(["run", world.logs[2], "--map", new, "--out", tmp_path / "o3", "--image-topic", "/nope", *world.orb],
            capfd, "/nope", watch=[tmp_path])
    assert not new.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["user_folder"]
    assert not creation_lock_path(new).exists(), "the creation lock's file stayed in the temporary folder"


def test_a_new_maps_first_append_makes_the_folder_and_its_lock(world, tmp_path, capfd):
    """The folder and its lock file appear with the first commit (not before the run), and the map works."""
    m = tmp_path / "a" / "new_map"
    rc, _, err = run_cli(["run", world.logs[1], "--map", m, "--out", tmp_path / "o", *world.orb], capfd)
    assert rc == 0, err
    assert (m / "map.json").is_file() and (m / ".lock").is_file()
    assert not creation_lock_path(m).exists(), "the creation lock's file stayed in the temporary folder"
    from slam_lcd.map.session_map import Map

    assert Map.open(m).session_names == ["s1"]


# ---------------------------------------------------------------------------- one duplicate rule
def test_batch_map_twice_adds_no_session(world, tmp_path, capfd):
    """`batch LOGS --map BM --out BO` run twice: the second appends nothing and says which session holds each log."""
    bm, bo = tmp_path / "bm", tmp_path / "bo"
    argv = ["batch", world.logs[1], world.logs[2], "--map", bm, "--out", bo, "--workers", "1", *world.orb]
    rc, _, err = run_cli(argv, capfd)
    assert rc == 0, err
    before = tree(bm)
    rc, out, err = run_cli(argv, capfd)
    assert rc == 0, err
    from slam_lcd.map.session_map import Map

    assert Map.open(bm).session_names == ["s1", "s2"]
    assert tree(bm) == before
    assert f"{world.logs[1]}: already in the map {bm} as session 's1' (same sha256)" in out, out
    assert f"{world.logs[2]}: already in the map {bm} as session 's2' (same sha256)" in out, out


@pytest.mark.slow
def test_batch_map_twice_with_ray_adds_no_session(world, tmp_path, capfd):
    pytest.importorskip("ray")
    bm, bo = tmp_path / "bm", tmp_path / "bo"
    shutil.copytree(world.m2, bm)
    before = tree(bm)
    rc, out, err = run_cli(["batch", world.logs[1], world.logs[2], "--map", bm, "--out", bo, "--ray", "local",
                            "--workers", "1", *world.orb], capfd)
    assert rc == 0, err
    assert tree(bm) == before
    assert "nothing appended" in out, out


def test_the_map_api_refuses_a_log_it_holds(world, tmp_path):
    """`Map.add_session` with a log the map holds (same sha256): LogAlreadyInMapError naming the session."""
    from slam_lcd.map.session_map import LogAlreadyInMapError, Map

    d = tmp_path / "map"
    shutil.copytree(world.m1, d)
    with Map.open(d, write=True) as m:
        assert m.session_of_log(world.logs[1]) == "s1"
        assert m.session_of_log(world.logs[1], "/camera/image_raw") == "s1"
        assert m.session_of_log(world.logs[2]) is None
        with pytest.raises(LogAlreadyInMapError, match="as session 's1'"):
            m.add_session(SimpleNamespace(keyframes=[object()]), log_path=world.logs[1])


# ---------------------------------------------------------------------------- errors and localize
def test_localize_against_another_world_writes_its_report_and_exits_1(world, tmp_path, capfd):
    """Nothing matched: report and localization.csv still written (0 %, a reason per keyframe), exit 1,
    and the printed line names the map."""
    out = tmp_path / "loc"
    rc, printed, err = run_cli(["localize", world.logs[4], "--map", world.m2, "--out", out, *world.orb], capfd)
    assert rc == 1, err
    assert "localised 0 of" in printed and str(world.m2) in printed, printed
    rep = json.loads((out / "report.json").read_text())
    assert rep["localization"]["localised"] == 0 and rep["localization"]["share_localised"] == 0.0
    with open(out / "localization.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert rows and all(r["localised"] == "False" and r["reason"] for r in rows)
    assert not (out / "localized.tum").exists()


def test_localize_against_an_empty_map_exits_1_with_a_report(world, tmp_path, capfd):
    d = tmp_path / "empty"
    shutil.copytree(world.m1, d)
    man = json.loads((d / "map.json").read_text())
    man.update(sessions=[], graph_file=None, vocab_file=None, files={})
    (d / "map.json").write_text(json.dumps(man))
    rc, printed, err = run_cli(["localize", world.logs[2], "--map", d, "--out", tmp_path / "loc", *world.orb], capfd)
    assert rc == 1, err
    assert "localised 0 of" in printed and str(d) in printed, printed


# ---------------------------------------------------------------------------- a map run leads with the map
def test_a_map_run_leads_with_the_maps_result(world):
    """s2 appended to the map of s1: the first summary line, report.json's headline and the top of
    report.html give the loops the joint graph accepted and the ATE in the map frame; corrected.tum is
    the map-frame trajectory and corrected_session.tum the session's own."""
    r = world.r2
    rep = json.loads((r / "report.json").read_text())
    head = rep["headline"]
    cur = rep["map"]["current"]
    assert head["frame"] == "map" and head["map"] == str(world.m2)
    assert head["loops_accepted"] == cur["loops_accepted"] == rep["loops"]["accepted"]
    assert cur["inter_session_loops"] >= 3 and cur["joined"]
    assert head["ate_after_m"] < 0.5 * head["ate_before_m"], head
    assert len(rep["accepted_loops"]) == cur["loops_accepted"]  # the loop table agrees with the headline
    assert rep["session_frame"]["ate_after"] is not None
    md_first = (r / "report.md").read_text().splitlines()[2]
    assert md_first.startswith(f"- map {world.m2}: session s2 joined, {cur['loops_accepted']} loops accepted by "
                               "the joint graph"), md_first
    assert "in the map frame" in md_first and f"{head['ate_after_m']:.3f} m" in md_first
    html = (r / "report.html").read_text()
    first_li = html.split("<ul id='summary'><li>", 1)[1].split("</li>", 1)[0]
    assert first_li.startswith(f"map {world.m2}: session s2 joined") and "in the map frame" in first_li
    assert html.index("<h2>Map</h2>") < html.index("<h2>Loops</h2>")
    # corrected.tum: the map frame (the map's own trajectory of s2 at full rate); corrected_session.tum: the session's
    corrected = (r / "corrected.tum").read_text()
    assert corrected == (r / "map" / "s2_full_rate.tum").read_text()
    assert (r / "corrected_session.tum").read_text() != corrected


def test_a_log_without_depth_says_no_map_cloud_in_its_summary_not_as_a_warning(tmp_path, capfd):
    """docs/map_cloud.md: one line in the run's summary (stdout) and report, nothing on stderr."""
    from slam_lcd.sim import make_demo_log

    log = tmp_path / "nodepth.mcap"
    make_demo_log(log, "mcap", frames=40, width=160, height=120, depth=False)
    rc, printed, err = run_cli(["run", log, "--out", tmp_path / "o", *ORB, "--no-feature-cache"], capfd)
    assert rc == 0, err
    assert "map cloud: not built (the log has no depth image and no stereo pair with a baseline)" in printed
    assert "map cloud" not in err and "map.ply" not in err, err
    rep = json.loads((tmp_path / "o" / "report.json").read_text())
    assert rep["map_cloud"]["built"] is False


@pytest.mark.parametrize("existing", [False, True], ids=["absent", "empty"])
def test_a_first_commit_that_fails_leaves_the_folder_as_it_was(world, tmp_path, monkeypatch, existing):
    """A full disk at a new map's first commit: MapError naming the map; the folder absent again (or
    empty again when the user had made it), no `.lock`, no `sessions/`; the session stays pending."""
    import errno

    from slam_lcd.map import store
    from slam_lcd.map.session_map import Map, MapError

    src = Map.open(world.m1)
    d = tmp_path / "new" / "map"
    if existing:
        d.mkdir(parents=True)
    m = Map.open(d, features=src.manifest.features, write=True, create=True)
    m._unsaved = [(dict(src.manifest.sessions[0]), src.sessions[0])]
    m.manifest.sessions = [dict(src.manifest.sessions[0])]
    m.graph = src.graph

    def full(path, arrays):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(store, "_write_npz", full)
    with pytest.raises(MapError, match="cannot write the map"):
        m.save()
    assert tree(tmp_path) == ({"new": "dir", "new/map": "dir"} if existing else {})
    monkeypatch.undo()
    m.save()  # room again: the pending session commits
    m.close()
    assert Map.open(d).session_names == ["s1"]


def test_two_first_appends_to_one_new_map_both_land(world, tmp_path):
    """Two `run --map NEW` started together on a folder that does not exist yet: the second waits for the
    first's creation lock (outside the folder), then appends to the map the first made."""
    import subprocess
    import sys

    from support.bad_input_files import REPO

    env = dict(__import__("os").environ, PYTHONPATH=str(REPO))
    new = tmp_path / "new"
    procs = [subprocess.Popen([sys.executable, "-m", "slam_lcd", "run", str(world.logs[k]), "--map", str(new),
                               "--out", str(tmp_path / f"o{k}"), *world.orb], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for k in (1, 2)]
    for p in procs:
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
    from slam_lcd.map.session_map import Map

    assert sorted(Map.open(new).session_names) == ["s1", "s2"]
    assert not creation_lock_path(new).exists()


def test_a_creation_lock_whose_file_was_removed_is_taken_again(tmp_path):
    """A waiter that locked the creation lock's file after its holder removed it opens the path again: it
    never holds a lock on a nameless file while another process locks a new file of that name."""
    import fcntl
    import os
    import threading
    import time

    from slam_lcd.map.locks import WriterLock

    new = tmp_path / "new"
    path = creation_lock_path(new)
    held = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(held, fcntl.LOCK_EX)  # another creator holds the lock
    got = {}

    def waiter():
        lock = WriterLock(new, timeout_s=10).acquire()
        got["ino"] = os.fstat(lock._new_fd).st_ino
        got["named"] = os.stat(path).st_ino
        lock.release()

    t = threading.Thread(target=waiter)
    t.start()
    time.sleep(0.5)  # the waiter has opened the old file and waits on it
    path.unlink()  # its holder removes the file, then lets go
    os.close(held)
    t.join(timeout=10)
    assert got["ino"] == got["named"], "the waiter kept a lock on the removed file"
    assert not path.exists(), "the waiter's own lock file stayed behind"

