"""`slam-lcd view` without the viewer extra: the folder is checked first, and a wrong one is named as such.

Run in a subprocess where ``import rerun`` fails (a ``sitecustomize`` on PYTHONPATH sets
``sys.modules['rerun'] = None``), so it holds whether or not rerun-sdk is installed here.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from support.bad_input_files import assert_one_line
from support.paths import REPO

INSTALL = "pip install 'slam-lcd[viewer]'"


@pytest.fixture
def no_rerun_env(tmp_path) -> dict:
    shim = tmp_path / "shim"
    shim.mkdir()
    (shim / "sitecustomize.py").write_text("import sys\nsys.modules['rerun'] = None\n", encoding="utf-8")
    path = [str(shim), str(REPO), os.environ.get("PYTHONPATH", "")]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in path if p)}


def slam_lcd(argv, env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slam_lcd", *argv], capture_output=True, text=True, env=env,
                          cwd=REPO, timeout=120)


def test_the_shim_makes_rerun_unimportable(no_rerun_env):
    proc = subprocess.run([sys.executable, "-c", "import rerun"], capture_output=True, text=True, env=no_rerun_env)
    assert proc.returncode != 0 and "import of rerun halted" in proc.stderr, proc.stderr


@pytest.mark.parametrize("case", ["neither", "no-such-folder", "incomplete-run", "port-without-web"])
def test_view_names_the_bad_folder_before_the_missing_extra(case, tmp_path, no_rerun_env):
    folder = tmp_path / "folder"
    extra: list[str] = ["--save", str(tmp_path / "x.rrd")]
    if case == "neither":
        folder.mkdir()
        needle = "neither a slam-lcd run folder (no report.json) nor a map folder (no map.json)"
    elif case == "no-such-folder":
        needle = "no such folder"
    elif case == "incomplete-run":
        folder.mkdir()
        (folder / "report.json").write_text(json.dumps({"schema": 1}), encoding="utf-8")
        needle = "not a complete slam-lcd run folder (no odometry.tum"
    else:
        folder.mkdir()
        extra = ["--port", "9000"]
        needle = "--port is the web viewer's: give it with --web"
    proc = slam_lcd(["view", str(folder), *extra], no_rerun_env)
    assert proc.returncode == 2, proc.stderr
    line = assert_one_line(proc.stderr, needle)
    assert INSTALL not in line and "rerun" not in line, line
    assert case == "port-without-web" or str(folder) in line
    assert not (tmp_path / "x.rrd").exists()
