"""`slam-lcd info`: list topics, types, counts, duration and rates of a log (not built yet, see issue #2)."""
from __future__ import annotations

from ..errors import NotBuiltError


def register(sub) -> None:
    p = sub.add_parser("info", help="list topics, types, counts, duration and rates of a log [not built yet]")
    p.add_argument("args", nargs="*")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotBuiltError("'slam-lcd info' is not built yet (issue #2)")
