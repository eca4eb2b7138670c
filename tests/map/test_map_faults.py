"""A map folder under faults: killed appends, a full disk, concurrent writers, damaged or foreign maps.

The map's promise (slam_lcd/map/store.py): an append is committed by one rename of ``map.json``, so
whatever stops it, the folder holds the map as it was before or the complete new one; a reader
refuses a truncated, tampered or foreign map with one line naming the file, and ``localize``
never writes to the map. Every test here breaks that promise's premise and checks the result.

Cheap on purpose: two 80-frame sessions of one demo world (and a 40-frame third), ORB features
(cached per module), no plots, pictures or corrected.mcap. A map's *state* is what ``Map.open``
reads (sessions table, keyframe arrays, graph), digested; file names carry a random tag and the
manifest its times, so two equal states need not be byte-identical folders.
"""
from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from support.bad_input_files import REPO, assert_one_line, run_cli

ORB = ["--features", "orb", "--no-mcap", "--no-progress", "--set", "run.plots=false",
       "--set", "run.loop_pictures=false", "--set", "lcd.top_k=1"]


# ---------------------------------------------------------------------------- helpers
def digest(root) -> str:
    """The state of the map at ``root`` as ``Map.open`` reads it (raises MapError when it cannot)."""
    from slam_lcd.map.session_map import Map

    m = Map.open(root)
    h = hashlib.sha256()
    table = [{k: v for k, v in s.items() if k != "file"} for s in m.manifest.sessions]
    h.update(json.dumps({"features": m.manifest.features, "sessions": table,
                         "generation": m.manifest.generation}, sort_keys=True).encode())
    for s in m.sessions:
        for k in s.ARRAYS:
            a = np.ascontiguousarray(getattr(s, k))
            h.update(f"{k}{a.dtype}{a.shape}".encode() + a.tobytes())
    for k in (*m.graph.ARRAYS, *m.graph.OPTIONAL):
        if getattr(m.graph, k) is None:
            continue
        a = np.ascontiguousarray(getattr(m.graph, k))
        h.update(f"{k}{a.dtype}{a.shape}".encode() + a.tobytes())
    return h.hexdigest()


def state(root) -> str:
    """``digest``, or 'none' where the folder holds no map (the state before a new map's first append)."""
    from slam_lcd.map.store import MapError, is_map

    if not is_map(root):
        return "none"
    try:
        return digest(root)
    except MapError as e:
        return f"broken: {e}"


def files(root) -> dict[str, str]:
    """sha256 of every file under ``root`` but the writers' lock, by relative path."""
    root = Path(root)
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and p.name != ".lock"}


def assert_tidy_after_next_writer(root, features: dict | None = None) -> None:
    """The next writer (opening for writing is enough; ``features``: those of a new map) leaves only
    the files the manifest names, or an empty folder where there is no map."""
    from slam_lcd.map.session_map import Map

    Map.open(root, write=True, create=True, features=None if (Path(root) / "map.json").is_file() else features).close()
    names = set(files(root))
    if (Path(root) / "map.json").is_file():
        man = json.loads((Path(root) / "map.json").read_text())
        assert names == {"map.json", *man["files"]}, names
    else:
        assert names == set(), names


def slam(argv, env, **kw) -> subprocess.Popen:
    """``python -m slam_lcd ARGV`` in a session of its own (a terminal's Ctrl-C reaches the whole group)."""
    return subprocess.Popen([sys.executable, "-m", "slam_lcd", *map(str, argv)], env=env, start_new_session=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


# A sitecustomize that sends the process a real signal at one instant of the map's commit:
# MAPFAULT=POINT:SIGNAL:DIR. The points, in the order a commit passes them:
WRITE_POINTS = ["session-write", "session-done", "graph-write", "graph-done", "manifest-write",
                "commit-before", "commit-after"]
HOOK = textwrap.dedent('''
    import os, signal
    signal.signal(signal.SIGINT, signal.default_int_handler)  # as a terminal starts it
    _spec = os.environ.get("MAPFAULT")
    if _spec:
        _point, _sig, _root = _spec.split(":", 2)
        _sig = getattr(signal, _sig)

        def _where(path):
            p = os.path.realpath(str(path))
            if os.path.dirname(p) == os.path.join(_root, "sessions"):
                return "session"
            if os.path.dirname(p) == _root:
                return "manifest" if os.path.basename(p) in ("map.json", ".map.json.tmp") else "graph"
            return None

        def _kill(point):
            if point == _point:
                os.kill(os.getpid(), _sig)

        import slam_lcd.map.store as _store
        _write_npz = _store.write_npz
        def write_npz(file, *a, **k):
            w = _where(getattr(file, "name", file))
            if w in ("session", "graph"):
                _kill(w + "-write")
            return _write_npz(file, *a, **k)
        _store.write_npz = write_npz

        _replace = os.replace
        def replace(src, dst, *a, **k):
            w = _where(dst)
            if w == "manifest":
                _kill("commit-before")
            r = _replace(src, dst, *a, **k)
            if w in ("session", "graph"):
                _kill(w + "-done")
            elif w == "manifest":
                _kill("commit-after")
            return r
        os.replace = replace

        _fsync = os.fsync
        def fsync(fd):
            try:
                if _where(os.readlink(f"/proc/self/fd/{fd}")) == "manifest":
                    _kill("manifest-write")
            except OSError:
                pass
            return _fsync(fd)
        os.fsync = fsync
''')

# the library's commit alone, in a process of its own: the sessions of map REF that DIR lacks are
# committed to DIR (new: DIR holds no map yet) under the lock, exactly as Map.save does
COMMIT = textwrap.dedent('''
    import sys
    from pathlib import Path
    from slam_lcd.map import store
    root, ref = Path(sys.argv[1]), Path(sys.argv[2])
    rman = store.read_manifest(ref)
    with store.write_lock(root) as lock:
        man = store.read_manifest(root) if store.is_map(root) else store.MapManifest(rman.features)
        have = {s["name"] for s in man.sessions}
        new = [({k: v for k, v in meta.items() if k != "file"}, store.read_session(ref, rman, i))
               for i, meta in enumerate(rman.sessions) if meta["name"] not in have]
        store.commit(root, man, new, store.read_graph(ref, rman), rman.sessions, lock=lock)
''')


# ---------------------------------------------------------------------------- shared logs and maps
@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """Three sessions of one world, a base map of session 1, the reference append of session 2."""
    from slam_lcd.sim import make_demo_log

    root = tmp_path_factory.mktemp("map_faults")
    logs = {}
    for k, frames in ((1, 80), (2, 80), (3, 40)):
        logs[k] = root / f"s{k}.mcap"
        make_demo_log(logs[k], "mcap", frames=frames, width=320, height=240, session=k)
    hook = root / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(HOOK)
    env = dict(os.environ)
    env.pop("MAPFAULT", None)
    env["PYTHONPATH"] = os.pathsep.join([str(hook), str(REPO), *filter(None, [os.environ.get("PYTHONPATH")])])
    orb = [*ORB, "--set", f"features.cache_dir={root / 'cache'}"]
    base = root / "base"
    p = slam(["run", logs[1], "--map", base, "--out", root / "o1", *orb], env)
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    after = root / "after"
    shutil.copytree(base, after)
    t0 = time.monotonic()
    p = slam(["run", logs[2], "--map", after, "--out", root / "o2", *orb], env)
    _, err = p.communicate(timeout=300)
    run_s = time.monotonic() - t0
    assert p.returncode == 0, err
    w = SimpleNamespace(root=root, logs=logs, env=env, orb=orb, base=base, after=after, run_s=run_s,
                        before=digest(base), after_state=digest(after))
    assert w.before != w.after_state
    return w


@pytest.fixture
def mapdir(world, tmp_path):
    """A copy of the base map (one session) for one test to break."""
    d = tmp_path / "map"
    shutil.copytree(world.base, d)
    return d


def _fault_env(world, point: str, sig: str, root: Path) -> dict:
    return dict(world.env, MAPFAULT=f"{point}:{sig}:{os.path.realpath(root)}")


# ---------------------------------------------------------------------------- Ctrl-C and SIGTERM
def test_ctrl_c_and_sigterm_at_every_step_of_the_commit(world, tmp_path):
    """A real SIGINT / SIGTERM at each step of the commit (session file, graph file, manifest, rename),
    both for an append and for a new map's first session: the folder reads as the map before or the
    complete one after; before the rename it is the one before, after it the one after; a Ctrl-C
    inside the rename is held until the rename is done; the next writer leaves no stray file."""
    cases = [(p, s, new) for new in (False, True) for p in WRITE_POINTS for s in ("SIGINT", "SIGTERM")
             if not new or p in ("session-write", "graph-done", "commit-before", "commit-after")]

    def one(case):
        point, sig, new = case
        d = tmp_path / f"{point}-{sig}-{'new' if new else 'append'}"
        if not new:
            shutil.copytree(world.base, d)
        else:
            d.mkdir()
        ref = world.base if new else world.after
        p = subprocess.run([sys.executable, "-c", COMMIT, d, ref], env=_fault_env(world, point, sig, d),
                           capture_output=True, text=True, timeout=120)
        return case, d, p

    with ThreadPoolExecutor(2) as pool:
        results = list(pool.map(one, cases))
    problems = []
    for (point, sig, new), d, p in results:
        before, after = ("none", world.before) if new else (world.before, world.after_state)
        got = state(d)
        committed = WRITE_POINTS.index(point) >= WRITE_POINTS.index("commit-after")
        killed = p.returncode == -signal.SIGTERM
        expect = {after} if committed else {after} if (sig == "SIGINT" and point == "commit-before") else \
            {before} if (sig == "SIGINT" or killed) else {before, after}
        if sig == "SIGINT" and (p.returncode == 0 or "KeyboardInterrupt" not in p.stderr):
            problems.append(f"{point} {sig}: the Ctrl-C was not raised (rc {p.returncode})")
        if got not in expect:
            problems.append(f"{point} {sig} {'new' if new else 'append'}: rc {p.returncode}, state "
                            f"{'before' if got == before else 'after' if got == after else got}")
            continue
        try:
            assert_tidy_after_next_writer(d, _manifest(world.base)["features"])
        except Exception as e:  # collected, reported together
            problems.append(f"{point} {sig} {'new' if new else 'append'}: next writer: {e}")
            continue
        if got == before and new:  # a new map's first append killed: the folder takes a new map
            p2 = subprocess.run([sys.executable, "-c", COMMIT, d, world.base], env=world.env, capture_output=True,
                                text=True, timeout=120)
            if p2.returncode != 0 or state(d) != after:
                problems.append(f"{point} {sig} new: the append after it failed: {p2.stderr.strip()[-300:]}")
    assert not problems, "\n".join(problems)


def test_run_killed_at_instants_of_an_append(world, tmp_path):
    """`slam-lcd run LOG --map DIR` killed by Ctrl-C or SIGTERM at instants spread over its run
    (start-up, features and loop detection, the commit, the outputs): the map is the one before
    or the complete one after, and exactly the one after when the run finished (exit 0)."""
    instants = [(0.3, "SIGINT"), (0.45, "SIGTERM"), (0.6, "SIGINT"), (0.7, "SIGTERM"), (0.8, "SIGINT"),
                (0.9, "SIGTERM")]
    problems, seen = [], set()
    for frac, sig in instants:
        d = tmp_path / f"map-{frac}"
        shutil.copytree(world.base, d)
        p = slam(["run", world.logs[2], "--map", d, "--out", tmp_path / f"out-{frac}", *world.orb], world.env)
        time.sleep(frac * world.run_s)
        with_signal = p.poll() is None
        if with_signal:
            os.killpg(p.pid, getattr(signal, sig))
        _, err = p.communicate(timeout=120)
        got = state(d)
        seen.add("before" if got == world.before else "after" if got == world.after_state else got)
        if got not in (world.before, world.after_state) or (p.returncode == 0 and got != world.after_state):
            problems.append(f"{sig} at {frac:.2f} x {world.run_s:.1f} s: rc {p.returncode}, state {got}: {err[-500:]}")
            continue
        if sig == "SIGINT" and with_signal and p.returncode not in (0, 130):
            problems.append(f"{sig} at {frac:.2f}: exit {p.returncode}, not 130: {err[-500:]}")
        assert_tidy_after_next_writer(d)
    assert not problems, "\n".join(problems)
    assert "before" in seen, seen  # the instants reached into the run, not only past its end


@pytest.mark.parametrize("point, sig", [("commit-before", "SIGINT"), ("manifest-write", "SIGTERM")])
def test_run_signalled_inside_the_commit(world, tmp_path, point, sig):
    """The whole `run --map` with the signal at an exact instant of the commit: a Ctrl-C held during
    the rename ends in the complete map and exit 130 with one line; a SIGTERM before the rename
    leaves the map as it was."""
    d = tmp_path / "map"
    shutil.copytree(world.base, d)
    p = slam(["run", world.logs[2], "--map", d, "--out", tmp_path / "out", *world.orb],
             _fault_env(world, point, sig, d))
    _, err = p.communicate(timeout=300)
    if sig == "SIGINT":
        assert p.returncode == 130, err
        assert_one_line(err, "interrupted")
        assert state(d) == world.after_state
    else:
        assert state(d) in (world.before, world.after_state)
        if p.returncode == -signal.SIGTERM:  # killed at once: the rename never happened
            assert state(d) == world.before
    assert_tidy_after_next_writer(d)


# ---------------------------------------------------------------------------- disk full
def test_disk_full_at_every_write_of_the_commit_leaves_the_map_as_it_was(world, mapdir, tmp_path, monkeypatch):
    """The library append (`Map.open(write=True)`, `run_log(map_use=MapUse(m))`) with the disk full at the Nth
    write of the commit, for every N: a MapError naming the map, every file as before and no stray
    one; the session stays pending, and the save that finally finds room commits the complete map."""
    from slam_lcd.config import load_config
    from slam_lcd.features import load_extractor
    from slam_lcd.map import store
    from slam_lcd.map.session_map import Map, extractor_meta
    from slam_lcd.map.store import MapError
    from slam_lcd.run import MapUse, Models, OutputOptions, run_log

    root = os.path.realpath(mapdir)
    events, fail_at = [], [1]

    def inside(path) -> bool:
        return os.path.realpath(str(path)).startswith(root + os.sep)

    def event(what):
        events.append(what)
        if len(events) == fail_at[0]:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    real_write_npz, real_replace, real_fsync, real_open = store.write_npz, os.replace, os.fsync, open

    def write_npz(file, *a, **k):
        if inside(getattr(file, "name", file)):
            file.write(b"PK\x03\x04 half a zip")  # the disk filled up part way
            event("savez")
        return real_write_npz(file, *a, **k)

    def replace(src, dst, *a, **k):
        if inside(dst):
            event(f"replace {Path(dst).name}")
        return real_replace(src, dst, *a, **k)

    def fsync(fd):
        with_path = os.readlink(f"/proc/self/fd/{fd}") if os.path.exists(f"/proc/self/fd/{fd}") else ""
        if inside(with_path) and not os.path.isdir(with_path):
            event("fsync")
        return real_fsync(fd)

    class Text:
        def __init__(self, fh):
            self.fh = fh

        def write(self, s):
            event("write manifest")
            return self.fh.write(s)

        def __getattr__(self, name):
            return getattr(self.fh, name)

        def __enter__(self):
            self.fh.__enter__()
            return self

        def __exit__(self, *exc):
            return self.fh.__exit__(*exc)

    def open_(path, mode="r", *a, **k):
        fh = real_open(path, mode, *a, **k)
        return Text(fh) if "w" in mode and inside(path) and str(path).endswith(".tmp") and "b" not in mode else fh

    cfg = load_config("default", ["features.kind=orb", "run.plots=false", "run.loop_pictures=false", "lcd.top_k=1",
                                  f"features.cache_dir={world.root / 'cache'}"])
    extractor = load_extractor(cfg.features)
    before = files(mapdir)
    m = Map.open(mapdir, features=extractor_meta(extractor, cfg.map.descriptor_form), conf=cfg.map, write=True)
    try:
        monkeypatch.setattr(store, "write_npz", write_npz)
        monkeypatch.setattr(os, "replace", replace)
        monkeypatch.setattr(os, "fsync", fsync)
        monkeypatch.setattr(store, "open", open_, raising=False)
        out = tmp_path / "out"
        with pytest.raises(MapError) as e:
            run_log(world.logs[2], out, cfg, models=Models(extractor=extractor), map_use=MapUse(m),
                    output=OutputOptions(progress=False, write_mcap=False))
        assert "No space left on device" in str(e.value) and str(mapdir) in str(e.value), e.value
        assert files(mapdir) == before and not out.exists()
        while True:
            events.clear()
            fail_at[0] += 1
            try:
                m.save()
                break
            except MapError as err:
                assert "No space left on device" in str(err), err
                assert files(mapdir) == before, (fail_at[0], events)
        assert fail_at[0] >= 8, events  # two files written, synced, renamed; the manifest written, synced, renamed
    finally:
        m.close()
        monkeypatch.undo()
    assert digest(mapdir) == world.after_state
    assert_tidy_after_next_writer(mapdir)


FOLD_NOW = ["--set", "map.fold_after_appends=1"]  # a third session folds the second one's dropped keyframes


@pytest.fixture(scope="module")
def folding(world, tmp_path_factory):
    """The reference append of session 3 to the map of sessions 1+2 that folds: the map after it."""
    from slam_lcd.map.session_map import Map

    ref = tmp_path_factory.mktemp("fold") / "map"
    shutil.copytree(world.after, ref)
    p = slam(["run", world.logs[3], "--map", ref, "--out", ref.parent / "out", *world.orb, *FOLD_NOW], world.env)
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    with Map.open(ref) as m:
        assert len(m.graph.folded_ids()) > 0  # the append folded keyframes out of the graph
    return SimpleNamespace(root=ref, state=state(ref))


@pytest.mark.parametrize("point, sig", [("graph-done", "SIGINT"), ("manifest-write", "SIGTERM")])
def test_an_append_that_folds_signalled_inside_its_commit(world, folding, tmp_path, point, sig):
    """A fold changes only what the commit writes: signalled inside it, the map is the one before or the one
    after the fold; a SIGTERM before the rename leaves the one before."""
    d = tmp_path / "map"
    shutil.copytree(world.after, d)
    p = slam(["run", world.logs[3], "--map", d, "--out", tmp_path / "out", *world.orb, *FOLD_NOW],
             _fault_env(world, point, sig, d))
    _, err = p.communicate(timeout=300)
    assert state(d) in (world.after_state, folding.state), (p.returncode, err[-400:])
    if p.returncode == -signal.SIGTERM:
        assert state(d) == world.after_state
    if sig == "SIGINT" and p.returncode != 0:
        assert p.returncode == 130
    assert_tidy_after_next_writer(d)


def test_an_append_that_folds_with_the_disk_full_leaves_the_map_as_it_was(world, folding, tmp_path, monkeypatch):
    """The disk full at the first file of a folding append's commit: a MapError, every file as it was; the save
    that finds room commits the folded map."""
    from slam_lcd.config import load_config
    from slam_lcd.features import load_extractor
    from slam_lcd.map import store
    from slam_lcd.map.session_map import Map, extractor_meta
    from slam_lcd.map.store import MapError
    from slam_lcd.run import MapUse, Models, OutputOptions, run_log

    d = tmp_path / "map"
    shutil.copytree(world.after, d)
    full = [True]
    real = store.write_npz

    def write_npz(file, *a, **k):
        if full[0]:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(file, *a, **k)

    cfg = load_config("default", ["features.kind=orb", "run.plots=false", "run.loop_pictures=false", "lcd.top_k=1",
                                  f"features.cache_dir={world.root / 'cache'}", "map.fold_after_appends=1"])
    extractor = load_extractor(cfg.features)
    before = files(d)
    with Map.open(d, features=extractor_meta(extractor, cfg.map.descriptor_form), conf=cfg.map, write=True) as m:
        monkeypatch.setattr(store, "write_npz", write_npz)
        with pytest.raises(MapError, match="No space left on device"):
            run_log(world.logs[3], tmp_path / "out", cfg, models=Models(extractor=extractor), map_use=MapUse(m),
                    output=OutputOptions(progress=False, write_mcap=False))
        assert files(d) == before
        full[0] = False
        m.save()
    assert state(d) == folding.state
    assert_tidy_after_next_writer(d)


def test_a_folded_map_gives_every_session_whole_and_its_graph_to_a_users_optimiser(world, folding):
    """After the fold: every session at full rate in the map frame, as the same append without folding put it
    (within 5 cm); ``map info`` names the folded keyframes and their factors; the graph a user's
    optimiser takes has a variable per keyframe left in it, and its optimum is the map's poses."""
    import gtsam

    from slam_lcd.map.lifelong import counts
    from slam_lcd.map.session_map import Map
    from slam_lcd.map.summary import map_summary

    plain = folding.root.parent / "plain"
    shutil.copytree(world.after, plain)
    p = slam(["run", world.logs[3], "--map", plain, "--out", plain.parent / "out-plain", *world.orb,
              "--set", "map.fold_after_appends=0"], world.env)
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    with Map.open(folding.root) as m, Map.open(plain) as ref:
        c, s = counts(m.graph, m.sessions), map_summary(m)
        assert c["graph_variables"] == c["keyframes"] - len(m.graph.folded_ids()) < counts(ref.graph, ref.sessions)[
            "graph_variables"]
        assert s["folded_keyframes"] > 0 and s["folded_factors"] > 0
        for i in range(len(m.sessions)):
            a, b = m.session_trajectory(i), ref.session_trajectory(i)
            assert len(a.stamps) == len(m.sessions[i].ids)
            assert np.max(np.linalg.norm(a.poses[:, :3, 3] - b.poses[:, :3, 3], axis=1)) < 0.05
        graph, values = m.factor_graph()
        assert values.size() == c["graph_variables"]
        k0 = int(values.keys()[0])
        graph.add(gtsam.PriorFactorPose3(k0, values.atPose3(k0), gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)))
        out = gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()
        moved = max(np.linalg.norm(out.atPose3(k).translation() - values.atPose3(k).translation())
                    for k in values.keys())
        assert moved < 0.01


# ---------------------------------------------------------------------------- concurrent writers
def test_two_concurrent_appends_both_land_whole(world, mapdir, tmp_path):
    """Two `run --map` of two logs started together on one map: the second waits for the first's lock
    (map.lock_timeout_s) and appends after it; the map ends with all three sessions, each whole."""
    procs = [slam(["run", world.logs[k], "--map", mapdir, "--out", tmp_path / f"o{k}", *world.orb], world.env)
             for k in (2, 3)]
    errs = [p.communicate(timeout=300)[1] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], errs
    from slam_lcd.map.session_map import Map

    m = Map.open(mapdir)
    assert sorted(m.session_names) == ["s1", "s2", "s3"]
    assert m.manifest.generation == 3
    ids = np.concatenate([s.ids for s in m.sessions])
    assert len(np.unique(ids)) == len(ids) == m.n_keyframes
    assert set(m.graph.kf_ids.tolist()) == set(ids.tolist())
    assert_tidy_after_next_writer(mapdir)


def test_a_busy_map_is_refused_at_once_with_lock_timeout_0(world, mapdir, tmp_path, capfd):
    """With another writer holding the map and `--set map.lock_timeout_s=0`: one line naming the map,
    exit 2, at once, nothing written."""
    from slam_lcd.map import store

    before = files(mapdir)
    with store.write_lock(mapdir):
        t0 = time.monotonic()
        rc, _, err = run_cli(["run", world.logs[2], "--map", mapdir, "--out", tmp_path / "out", *world.orb,
                              "--set", "map.lock_timeout_s=0"], capfd)
        took = time.monotonic() - t0
    assert rc == 2, err
    assert_one_line(err, str(mapdir), "another slam-lcd process is writing")
    assert took < 5, took
    assert files(mapdir) == before and not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------- damaged and foreign maps
def _manifest(d) -> dict:
    return json.loads((Path(d) / "map.json").read_text())


def _write_manifest(d, man) -> None:
    (Path(d) / "map.json").write_text(json.dumps(man, indent=1))


def _session_file(d) -> Path:
    return Path(d) / _manifest(d)["sessions"][0]["file"]


def _graph_file(d) -> Path:
    return Path(d) / _manifest(d)["graph_file"]


def damage_truncated_session(d):
    p = _session_file(d)
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    return p, "truncated"


def damage_flipped_graph_byte(d):
    p = _graph_file(d)
    b = bytearray(p.read_bytes())
    b[len(b) // 2] ^= 0x01
    p.write_bytes(bytes(b))
    return p, "sha256 differs"


def damage_truncated_manifest(d):
    p = Path(d) / "map.json"
    p.write_bytes(p.read_bytes()[:200])
    return p, "cannot be read as a map manifest"


def damage_schema_2(d):
    man = _manifest(d)
    man["schema"] = 2
    _write_manifest(d, man)
    return Path(d) / "map.json", "map schema 2"


def damage_schema_0(d):
    man = _manifest(d)
    man["schema"] = 0
    _write_manifest(d, man)
    return Path(d) / "map.json", "map schema 0"


class _Touch:
    """Unpickling this creates a file: proof that a map's arrays are never unpickled."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (Path.touch, (Path(self.path),))


def damage_pickled_array(d):
    """A session file swapped for one with a pickled object array, the manifest's sha256 updated to it."""
    p = _session_file(d)
    with np.load(p, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["points_source"] = np.array([_Touch(Path(d).parent / "unpickled")] * len(arrays["ids"]), dtype=object)
    with open(p, "wb") as fh:
        np.savez(fh, **arrays)
    man = _manifest(d)
    rel = p.relative_to(d).as_posix()
    man["files"][rel] = {"sha256": hashlib.sha256(p.read_bytes()).hexdigest(), "bytes": p.stat().st_size}
    _write_manifest(d, man)
    return p, "allow_pickle=False"


FILE_DAMAGE = [damage_truncated_session, damage_flipped_graph_byte, damage_truncated_manifest, damage_schema_2,
               damage_schema_0, damage_pickled_array]


def _commands(world, d, out):
    return {"run": ["run", world.logs[2], "--map", d, "--out", out, *world.orb],
            "localize": ["localize", world.logs[2], "--map", d, "--out", out, *world.orb],
            "map info": ["map", "info", d]}


def _refused(world, d, command, argv_extra, expect_file, needle, tmp_path, capfd):
    before = files(d)
    lock_before = (Path(d) / ".lock").exists()
    out = tmp_path / "out"
    argv = _commands(world, d, out)[command] + list(argv_extra)
    rc, _, err = run_cli(argv, capfd)
    assert rc == 2, err
    line = assert_one_line(err, str(expect_file), needle)
    assert line.startswith(f"slam-lcd {command.split()[0]}: error: "), line
    assert files(d) == before, "the map was modified"
    assert (Path(d) / ".lock").exists() == lock_before
    assert not out.exists()
    assert not (Path(d).parent / "unpickled").exists(), "a pickled array of the map was unpickled"


@pytest.mark.parametrize("command", ["run", "localize", "map info"])
@pytest.mark.parametrize("damage", FILE_DAMAGE, ids=lambda f: f.__name__[len("damage_"):])
def test_damaged_map_is_one_line_naming_the_file(world, mapdir, tmp_path, capfd, damage, command):
    """A truncated or tampered map file, a map of another schema: `run --map`, `localize` and `map info`
    print one line naming the file and the problem, exit 2, and modify nothing."""
    path, needle = damage(mapdir)
    _refused(world, mapdir, command, [], path, needle, tmp_path, capfd)


def _as_superpoint_map(d, weights_sha256: str) -> None:
    man = _manifest(d)
    man["features"].update(kind="superpoint", weights_sha256=weights_sha256, descriptor_dim=256,
                           descriptor_form="int8")
    _write_manifest(d, man)


@pytest.mark.parametrize("command", ["run", "localize"])
def test_orb_map_refused_by_a_superpoint_run(world, mapdir, tmp_path, capfd, superpoint_weights, command):
    """A map of ORB features opened by a SuperPoint run (the later --features wins): refused, nothing modified."""
    _refused(world, mapdir, command, ["--features", "superpoint", "--weights", superpoint_weights, "--device", "cpu"],
             mapdir / "map.json", "the map holds orb features, this run extracts superpoint", tmp_path, capfd)


@pytest.mark.parametrize("command", ["run", "localize"])
def test_superpoint_map_refused_by_an_orb_run(world, mapdir, tmp_path, capfd, command):
    """A SuperPoint map (its manifest says so) opened by an ORB run: refused, nothing modified."""
    _as_superpoint_map(mapdir, "ab" * 32)
    _refused(world, mapdir, command, [], mapdir / "map.json",
             "the map holds superpoint features, this run extracts orb", tmp_path, capfd)


@pytest.mark.parametrize("command", ["run", "localize"])
def test_map_of_other_weights_refused(world, mapdir, tmp_path, capfd, superpoint_weights, command):
    """A SuperPoint map of other weights (the manifest's weights_sha256; the manifest itself is not
    hashed, it is what the files are checked against) opened with this checkout's weights: refused."""
    _as_superpoint_map(mapdir, "0" * 64)
    _refused(world, mapdir, command, ["--features", "superpoint", "--weights", superpoint_weights, "--device", "cpu"],
             mapdir / "map.json", "a map never mixes weights", tmp_path, capfd)


# ---------------------------------------------------------------------------- localize only reads
def test_localize_leaves_every_byte_of_the_map(world, tmp_path, capfd):
    """`localize` of a mapped log against a two-session map: it runs to the end, and every file of the map is
    byte-identical afterwards; it does not even create the writers' lock."""
    d = tmp_path / "map"
    shutil.copytree(world.after, d)
    (d / ".lock").unlink()
    before, paths = files(d), sorted(p.relative_to(d).as_posix() for p in d.rglob("*"))
    rc, out, err = run_cli(["localize", world.logs[1], "--map", d, "--out", tmp_path / "out", *world.orb], capfd)
    assert rc == 0, err
    assert (tmp_path / "out" / "report.json").is_file()
    assert files(d) == before
    assert sorted(p.relative_to(d).as_posix() for p in d.rglob("*")) == paths  # no lock, no new file


def test_a_log_already_in_the_map_is_not_appended_again(world, mapdir, tmp_path):
    """Rerunning ``run a b --map`` after an interruption resumes it: a log already in the map (same
    sha256) is skipped with one line, the rest is appended."""
    p = slam(["run", world.logs[1], world.logs[2], "--map", mapdir, "--out", tmp_path / "o", *world.orb], world.env)
    out, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    assert f"{world.logs[1]}: already in the map {mapdir} as session 's1' (same sha256)" in out, out
    assert not (tmp_path / "o" / "s1").exists()
    from slam_lcd.map.session_map import Map

    assert Map.open(mapdir).session_names == ["s1", "s2"]


def test_a_reader_racing_a_writers_commit_reads_a_whole_map(world, mapdir, monkeypatch):
    """A reader takes no lock. A commit between its manifest and its files (which removes the files
    the reader's manifest named) makes it read the new map; a commit after it opened leaves it the
    vocabulary snapshot of the map it opened."""
    from slam_lcd.config import load_config
    from slam_lcd.lcd.detector import LoopDetector
    from slam_lcd.map import store
    from slam_lcd.map.session_map import Map

    def commit():
        p = subprocess.run([sys.executable, "-c", COMMIT, mapdir, world.after], env=world.env, capture_output=True,
                           text=True, timeout=120)
        assert p.returncode == 0, p.stderr

    before = store.read_manifest(mapdir)
    m = Map.open(mapdir)  # opened before the commit: keeps its generation's snapshot
    commit()
    assert not (mapdir / before.graph_file).exists() and not (mapdir / before.vocab_file).exists()
    cfg = load_config("orb")
    det = LoopDetector(cfg.lcd, vocab_conf=cfg.vocab)
    m.load_into(det)
    # the detector holds the keyframes the map keeps (all of them without map.lifelong)
    assert len(det.db) == int(m.sessions[0].kept().sum()) and len(m.sessions) == 1
    m.close()

    shutil.rmtree(mapdir)
    shutil.copytree(world.base, mapdir)
    read_graph = store.read_graph
    calls = []

    def racing(root, manifest):  # the writer commits between the reader's manifest and its graph file
        if not calls:
            commit()
        calls.append(manifest.generation)
        return read_graph(root, manifest)

    monkeypatch.setattr(store, "read_graph", racing)
    m2 = Map.open(mapdir)
    assert m2.session_names == ["s1", "s2"] and len(calls) == 2, calls


def test_an_interrupt_inside_the_archive_writer_stays_an_interrupt(tmp_path, monkeypatch):
    """A Ctrl-C that lands while zipfile closes a member of a map file is raised as KeyboardInterrupt once the
    file is complete (not zipfile's ValueError about an open writing handle), and the half-written file goes."""
    import zipfile

    from slam_lcd.map import store

    real_close = zipfile._ZipWriteFile.close
    fired = []

    def close(self):
        if not fired:
            fired.append(True)
            os.kill(os.getpid(), signal.SIGINT)
        return real_close(self)

    monkeypatch.setattr(zipfile._ZipWriteFile, "close", close)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # what the command line runs with
    try:
        with pytest.raises(KeyboardInterrupt):
            store._write_npz(tmp_path / "a.npz", {"poses": np.zeros((4, 4, 4)), "ids": np.arange(4)})
    finally:
        signal.signal(signal.SIGINT, previous)
    assert fired and list(tmp_path.iterdir()) == []
