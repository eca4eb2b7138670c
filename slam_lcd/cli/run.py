"""`slam-lcd run`: correct a recorded log's trajectory with loop closures (not built yet, see issue #9)."""
from __future__ import annotations

from ..errors import NotBuiltError


def register(sub) -> None:
    p = sub.add_parser("run", help="correct a recorded log's trajectory with loop closures [not built yet]")
    p.add_argument("args", nargs="*")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotBuiltError("'slam-lcd run' is not built yet (issue #9)")
