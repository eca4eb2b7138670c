"""Old import paths of modules that moved (into ``slam_lcd.run``, or to a name that says their job) still
import, as aliases, with a warning."""
import subprocess
import sys
from pathlib import Path

import pytest

import slam_lcd
from slam_lcd.runtime.moved_modules import MOVED


@pytest.mark.parametrize("old", sorted(MOVED))
def test_an_old_path_imports_the_moved_module_and_says_where_it_went(old):
    code = (f"import warnings, importlib\nwarnings.simplefilter('always')\n"
            f"with warnings.catch_warnings(record=True) as w:\n    m = importlib.import_module({old!r})\n"
            f"assert m is importlib.import_module({MOVED[old]!r}), m\n"
            f"assert m.__spec__.name == {MOVED[old]!r}, m.__spec__\n"
            f"assert any(issubclass(x.category, DeprecationWarning) and {MOVED[old]!r} in str(x.message)\n"
            f"           for x in w), w\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_the_old_paths_are_no_files_in_the_package():
    """The top of slam_lcd/ holds the base modules and packages only: the old paths are aliases, not files."""
    root = Path(slam_lcd.__file__).parent.parent
    assert not [old for old in MOVED if (root / (old.replace(".", "/") + ".py")).exists()]
    assert all((root / (new.replace(".", "/") + ".py")).is_file() for new in MOVED.values())
