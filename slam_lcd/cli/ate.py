"""`slam-lcd ate`: absolute trajectory error between two trajectories (not built yet, see issue #9)."""
from __future__ import annotations

from ..errors import NotBuiltError


def register(sub) -> None:
    p = sub.add_parser("ate", help="absolute trajectory error between two trajectories [not built yet]")
    p.add_argument("args", nargs="*")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotBuiltError("'slam-lcd ate' is not built yet (issue #9)")
