"""`slam-lcd demo`: run the whole pipeline on the built-in demo world (not built yet, see issue #9)."""
from __future__ import annotations

from ..errors import NotBuiltError


def register(sub) -> None:
    p = sub.add_parser("demo", help="run the whole pipeline on the built-in demo world [not built yet]")
    p.add_argument("args", nargs="*")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotBuiltError("'slam-lcd demo' is not built yet (issue #9)")
