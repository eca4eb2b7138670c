"""The command line starts light: building the parser (every command's start, ``--help`` included)
loads none of the heavy packages; a command loads them when it runs (CONTRIBUTING.md, "Where code goes")."""
from __future__ import annotations

import os
import subprocess
import sys

from support.paths import REPO

HEAVY = ("numpy", "scipy", "cv2", "torch", "gtsam", "matplotlib", "rosbags", "mcap")

_CODE = """
import sys
from slam_lcd.cli.main import build_parser
from slam_lcd.cli.util import subparsers_of

root = build_parser()
for parser in [root, *subparsers_of(root)]:
    parser.format_help()
root.parse_args(["make-demo-log", "out.mcap", "--session", "2"])
root.parse_args(["ate", "ref.tum", "est.tum", "--ref-format", "tum", "-r", "angle_deg"])
print(" ".join(sorted(name for name in %r if name in sys.modules)))
"""


def test_building_the_parser_loads_no_heavy_package():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-c", _CODE % (HEAVY,)], capture_output=True, text=True, env=env,
                          cwd=REPO)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == [], f"loaded while the parser was built: {proc.stdout.strip()}"
