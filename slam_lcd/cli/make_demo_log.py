"""`slam-lcd make-demo-log`: render the built-in demo world into a log file (not built yet, see issue #3)."""
from __future__ import annotations

from ..errors import NotBuiltError


def register(sub) -> None:
    p = sub.add_parser("make-demo-log", help="render the built-in demo world into a log file [not built yet]")
    p.add_argument("args", nargs="*")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotBuiltError("'slam-lcd make-demo-log' is not built yet (issue #3)")
