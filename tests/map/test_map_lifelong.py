"""A map that grows with the place, not with the days (docs/multisession.md, "Places and variants").

Synthetic keyframes for the judging rule (new place / redundant / new appearance, a full place's
oldest variant evicted), then small demo maps: a second visit of one route adds poses, not
candidates; a session of another world adds its own places; ``map compact`` reduces a map built
without the rule, keeps a lifelong map's records, and leaves the map before or after under signals.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from slam_lcd.map.config import MapConfig
from slam_lcd.map.places import (
    NEW_PLACE,
    REDUNDANT,
    VARIANT,
    Kept,
    Ratios,
    appearance_of,
    familiarity,
    judge,
    match_ratio,
)

from support.bad_input_files import REPO, run_cli

ORB = ["--features", "orb", "--no-mcap", "--no-progress", "--set", "run.plots=false",
       "--set", "run.loop_pictures=false", "--set", "lcd.top_k=1"]


def _pose(x: float, yaw_deg: float = 0.0) -> np.ndarray:
    """A camera looking along +z rotated about y (yaw), at (x, 0, 0)."""
    a = np.radians(yaw_deg)
    T = np.eye(4)
    T[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
    T[0, 3] = x
    return T


def _desc(seed: int, n: int = 200) -> np.ndarray:
    d = np.random.default_rng(seed).normal(size=(n, 64)).astype(np.float32)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _noisy(d: np.ndarray, keep: float, seed: int) -> np.ndarray:
    """``d`` with a share ``1 - keep`` of its rows replaced (another appearance of the same view)."""
    out = d.copy()
    rng = np.random.default_rng(seed)
    swap = rng.random(len(d)) > keep
    out[swap] = _desc(seed + 1000, int(swap.sum()))
    return out


def test_match_ratio_separates_the_same_view_from_another():
    a = _desc(1)
    assert match_ratio(a, _noisy(a, 0.9, 2)) > 0.8
    assert match_ratio(a, _desc(3)) < 0.05
    bits = np.random.default_rng(4).integers(0, 256, (100, 32), dtype=np.uint8)
    assert match_ratio(bits, bits) == 1.0


def _route(kind: str, first_id: int, shift_m: float = 0.0) -> list:
    """A route of six views 0.4 m apart along a wall of 300 points; each view sees 100 of them, 30 on from
    the last. ``day`` and ``night`` describe each point differently except for 45 % of the points (what
    lighting leaves alike): night against day at one pose shares 0.45, night against night 0.4 m on 0.7."""
    rng = np.random.default_rng(7)
    day = rng.normal(size=(300, 64)).astype(np.float32)
    night = np.where(rng.random((300, 1)) < 0.45, day, rng.normal(size=(300, 64)).astype(np.float32))
    pts = {"day": day, "night": night}[kind]
    pts = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    return [(first_id + i, _pose(0.4 * i + shift_m), (lambda d: (lambda: d))(pts[30 * i: 30 * i + 100]))
            for i in range(6)]


def _judged(route, kept, conf, now):
    ratios = Ratios()
    known, own = familiarity(route, 0, kept, conf, ratios)
    look, fresh = appearance_of(known, own, kept, conf)
    return look, fresh, judge(route, 0, kept, conf, now, max((k.place for k in kept), default=-1) + 1, look, ratios)


def test_a_session_in_another_appearance_keeps_variants_the_next_one_matches():
    """Night in a map of days: each night view shares 0.45 with the day view at its pose (a keyframe alone
    looks redundant at map.redundant_match_ratio 0.3), but the session as a whole matches the days far
    less than its own views match each other: it founds appearance 1 and keeps night variants, which
    the next night matches; judged against the days, as a keyframe-by-keyframe rule would, it keeps none."""
    conf = MapConfig()
    kept: list[Kept] = []
    look, fresh, v = _judged(_route("day", 0), kept, conf, 1)
    assert (look, fresh) == (0, False) and NEW_PLACE in v.status.values()
    days = {k.kf_id for k in kept}
    without = judge(_route("night", 100), 0, list(kept), conf, 2, 10, appearance=0)
    assert {without.matched.get(100), without.matched.get(103)} == days  # the day views' places: no night variant
    look, fresh, v = _judged(_route("night", 100), kept, conf, 2)
    assert (look, fresh) == (1, True)
    assert v.status[100] == v.status[103] == VARIANT and not set(v.matched.values()) & days
    nights = {k.kf_id for k in kept if k.appearance == 1}
    assert nights and nights <= set(range(100, 106))
    look, fresh, v = _judged(_route("night", 200, shift_m=0.1), kept, conf, 3)
    assert (look, fresh) == (1, False)
    assert list(v.status.values()).count(REDUNDANT) >= 4 and set(v.matched.values()) <= nights
    look, fresh, v = _judged(_route("day", 300, shift_m=0.1), kept, conf, 4)
    assert (look, fresh) == (0, False) and set(v.matched.values()) <= days


def test_a_full_place_keeps_a_view_of_each_appearance():
    """A full place (days 1-3, the night 4 matched longest ago) takes a variant of a third appearance: an
    older day view goes, not the place's only night view; a day variant replaces the oldest day view."""
    conf = MapConfig(max_variants=4)
    d = {k: _desc(40 + k) for k in range(1, 5)}
    kept = [Kept(k, _pose(0.1 * k), 0, 0, used, (lambda x: (lambda: x))(d[k]), look)
            for k, used, look in ((1, 5, 0), (2, 3, 0), (3, 6, 0), (4, 1, 1))]
    v = judge([(10, _pose(0.0), lambda: _desc(50))], 0, kept, conf, now=7, next_place=1, appearance=2)
    assert v.status[10] == VARIANT and v.evicted == [2]
    v = judge([(11, _pose(0.05), lambda: _desc(51))], 0, kept, conf, now=8, next_place=1, appearance=0)
    assert v.status[11] == VARIANT and v.evicted == [1]
    assert {k.kf_id: k.appearance for k in kept} == {3: 0, 4: 1, 10: 2, 11: 0}


def test_judge_new_place_redundant_variant_and_eviction():
    conf = MapConfig(max_variants=2)
    d0 = _desc(10)
    kept = [Kept(1, _pose(0.0), 0, 0, 1, lambda: d0)]
    new = [(10, _pose(5.0), lambda: _desc(11)),  # nothing within 1 m: a new place
           (11, _pose(0.3), lambda: _noisy(d0, 0.9, 12)),  # near and alike: redundant
           (12, _pose(0.2, 60.0), lambda: _noisy(d0, 0.9, 13)),  # near but looking elsewhere: a new place
           (13, _pose(-0.2), lambda: _noisy(d0, 0.1, 14)),  # near, another appearance: a variant of place 0
           (14, _pose(0.1), lambda: _desc(15))]  # a third appearance: place 0 full, its oldest variant goes
    v = judge(new, 0, kept, conf, now=2, next_place=1)
    assert v.status[10] == NEW_PLACE and v.status[11] == REDUNDANT and v.matched[11] == 1
    assert v.status[12] == NEW_PLACE and v.status[13] == VARIANT and v.place[13] == 0
    assert v.evicted == [1] and 1 in v.used  # keyframe 1 was matched by 11 at 2, as 13 was added: the id decides
    assert {k.kf_id for k in kept} == {10, 12, 13, 14}
    # another component is never the same place
    v2 = judge([(20, _pose(0.0), lambda: _noisy(d0, 0.9, 16))], 1, kept, conf, now=3, next_place=5)
    assert v2.status[20] == NEW_PLACE


@pytest.fixture(scope="module")
def world(tmp_path_factory, visit_logs):
    """s1, s2 (a second visit of s1's route) and s4 (another world); map ``life`` of s1+s2 (default: lifelong)
    and map ``full`` of the same with ``map.lifelong=false``."""
    from slam_lcd.cli.main import main


    root = tmp_path_factory.mktemp("lifelong")
    logs = visit_logs
    orb = [*ORB, "--set", f"features.cache_dir={root / 'cache'}"]
    for name, extra in (("life", []), ("full", ["--set", "map.lifelong=false"])):
        for k in (1, 2):
            assert main(["run", str(logs[k]), "--map", str(root / name), "--out", str(root / f"o-{name}{k}"),
                         *orb, *extra]) == 0
    return SimpleNamespace(root=root, logs=logs, orb=orb, life=root / "life", full=root / "full")


def _info(capfd, d) -> dict:
    rc, out, err = run_cli(["map", "info", d, "--json"], capfd)
    assert rc == 0, err
    return json.loads(out)


def test_a_second_visit_adds_poses_not_candidates(world, capfd, tmp_path):
    """The second visit of a route keeps every pose (its session in the map frame at full rate) and few
    candidates; the unreduced map keeps all; the report of the append says so; the growth is plotted."""
    life, full = _info(capfd, world.life), _info(capfd, world.full)
    assert life["n_keyframes"] == full["n_keyframes"]
    s1, s2 = life["sessions"]
    assert s2["kept_keyframes"] < 0.5 * s2["keyframes"], s2
    assert life["kept_keyframes"] < full["kept_keyframes"] == full["n_keyframes"]
    assert life["bytes"] < full["bytes"]
    assert [g["keyframes"] for g in life["growth"]] == [s1["keyframes"], s1["keyframes"] + s2["keyframes"]]
    from slam_lcd.map.session_map import Map

    m = Map.open(world.life)
    assert len(m.session_trajectory(1)) == s2["keyframes"]
    from slam_lcd.config import load_config

    c = load_config("orb")
    det = m.loop_detector(c.lcd, c.vocab)
    assert len(det.db) == life["kept_keyframes"]
    rc, _, err = run_cli(["map", "info", world.life, "--plot", tmp_path / "growth.png"], capfd)
    assert rc == 0, err
    assert (tmp_path / "growth.png").read_bytes()[:4] == b"\x89PNG"


def test_localisation_uses_the_kept_variants(world, capfd, tmp_path):
    """Localised against the reduced map about as well as against the map of every keyframe (the short ORB
    logs here localise about half their keyframes against either)."""
    share = {}
    for name in ("life", "full"):
        rc, _, err = run_cli(["localize", world.logs[1], "--map", getattr(world, name), "--out", tmp_path / name,
                              *world.orb], capfd)
        assert rc == 0, err
        rep = json.loads((tmp_path / name / "report.json").read_text())["localization"]
        assert rep["errors"]["over_1m"] == 0, rep
        share[name] = rep["share_localised"]
    assert share["life"] >= share["full"] - 0.1, share


def test_a_session_of_another_world_adds_its_own_places(world, capfd, tmp_path):
    d = tmp_path / "map"
    shutil.copytree(world.life, d)
    before = _info(capfd, d)
    rc, _, err = run_cli(["run", world.logs[4], "--map", d, "--out", tmp_path / "o", *world.orb], capfd)
    assert rc == 0, err
    after = _info(capfd, d)
    s4 = after["sessions"][-1]
    assert not s4["joined"]
    assert after["places"] > before["places"]
    assert s4["kept_keyframes"] >= 0.4 * s4["keyframes"], s4  # nothing of the map's world is near it


def test_a_third_append_folds_the_second_visit_out_of_the_graph(world, capfd, tmp_path):
    """With one append to wait (``map.fold_after_appends=1``), the append of another world folds the second
    visit's dropped keyframes: the graph loses their variables and raw loops, the pair keeps its verdict (with
    its folded loops counted), both visits stay where they were (5 cm), and localisation is as good as before."""
    from slam_lcd.map.session_map import Map

    d = tmp_path / "map"
    shutil.copytree(world.life, d)
    before = _info(capfd, d)
    rc, _, err = run_cli(["run", world.logs[4], "--map", d, "--out", tmp_path / "o", *world.orb,
                          "--set", "map.fold_after_appends=1"], capfd)
    assert rc == 0, err
    after = _info(capfd, d)
    assert after["folded_keyframes"] > 0.3 * before["sessions"][1]["keyframes"], after["folded_keyframes"]
    assert after["graph_variables"] < before["graph_variables"]
    (pair,) = [r for r in after["pairs"] if set(r["sessions"]) == {"s1", "s2"}]
    assert pair["decision"] == "joined" and pair["status"] == "judged" and pair["folded"] > 0, pair
    with Map.open(world.life) as m0, Map.open(d) as m1:
        for i in (0, 1):
            a, b = m0.session_trajectory(i), m1.session_trajectory(i)
            assert np.max(np.linalg.norm(a.poses[:, :3, 3] - b.poses[:, :3, 3], axis=1)) < 0.05
    share = {}
    for name, root in (("before", world.life), ("folded", d)):
        rc, _, err = run_cli(["localize", world.logs[1], "--map", root, "--out", tmp_path / name, *world.orb], capfd)
        assert rc == 0, err
        share[name] = json.loads((tmp_path / name / "report.json").read_text())["localization"]["share_localised"]
    assert share["folded"] >= share["before"] - 0.05, share


def test_map_compact_reduces_a_full_map_like_appending_with_the_rule(world, capfd, tmp_path):
    d = tmp_path / "map"
    shutil.copytree(world.full, d)
    rc, printed, err = run_cli(["map", "compact", d], capfd)
    assert rc == 0, err
    c, life = _info(capfd, d), _info(capfd, world.life)
    assert c["n_keyframes"] == life["n_keyframes"]
    assert abs(c["kept_keyframes"] - life["kept_keyframes"]) <= 0.25 * life["kept_keyframes"], (c, life)
    rc, _, err = run_cli(["localize", world.logs[2], "--map", d, "--out", tmp_path / "loc", *world.orb], capfd)
    assert rc == 0, err


def test_map_compact_of_a_lifelong_map_keeps_its_records(world, capfd, tmp_path):
    """A map appended with the rule, compacted twice: every keyframe's place, last use and appearance, the
    counts, and the session files stay as they are."""
    from slam_lcd.map.session_map import Map

    d = tmp_path / "map"
    shutil.copytree(world.life, d)

    def records():
        with Map.open(d) as m:
            g = m.graph
            return [a.tolist() for a in (g.kf_place, g.kf_last_used, g.kf_appearance)]

    before, info = records(), _info(capfd, d)
    files = sorted(p.name for p in (d / "sessions").iterdir())
    for _ in range(2):
        rc, _, err = run_cli(["map", "compact", d], capfd)
        assert rc == 0, err
        after = _info(capfd, d)
        assert records() == before
        assert [after[k] for k in ("places", "variants", "appearances", "kept_keyframes")] == \
            [info[k] for k in ("places", "variants", "appearances", "kept_keyframes")]
        assert sorted(p.name for p in (d / "sessions").iterdir()) == files


@pytest.mark.parametrize("point, sig", [("session-write", "SIGTERM"), ("graph-done", "SIGINT"),
                                        ("manifest-write", "SIGTERM"), ("commit-before", "SIGINT")])
def test_map_compact_under_signals_leaves_the_map_before_or_after(world, tmp_path, point, sig):
    """`map compact` signalled at an instant of its commit: the map before it, or the compacted one."""
    from test_map_faults import HOOK, state

    hook = tmp_path / "hook"
    hook.mkdir()
    (hook / "sitecustomize.py").write_text(HOOK)
    d = tmp_path / "map"
    shutil.copytree(world.full, d)
    before = state(d)
    ref = tmp_path / "ref"
    shutil.copytree(world.full, ref)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(hook), str(REPO)]))
    assert subprocess.run([sys.executable, "-m", "slam_lcd", "map", "compact", str(ref)], env=env,
                          capture_output=True).returncode == 0
    after = state(ref)
    p = subprocess.run([sys.executable, "-m", "slam_lcd", "map", "compact", str(d)], capture_output=True, text=True,
                       env=dict(env, MAPFAULT=f"{point}:{sig}:{os.path.realpath(d)}"), timeout=120)
    got = state(d)
    assert got in (before, after), (p.returncode, p.stderr[-400:])
    if p.returncode == 0:
        assert got == after
    if sig == "SIGINT" and p.returncode != 0:
        assert p.returncode == 130 and len(p.stderr.strip().splitlines()) == 1, p.stderr
    if p.returncode == -signal.SIGTERM:
        assert got == before
    # the next compaction finishes the job from whichever map is there
    assert subprocess.run([sys.executable, "-m", "slam_lcd", "map", "compact", str(d)], env=env,
                          capture_output=True).returncode == 0
    assert Path(d, "map.json").is_file()
