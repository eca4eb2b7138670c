"""`slam-lcd vocab`: train or inspect a Bag of SuperPoints vocabulary (not built yet, see issue #5)."""
from __future__ import annotations

from ..errors import NotBuiltError


def register(sub) -> None:
    p = sub.add_parser("vocab", help="train or inspect a Bag of SuperPoints vocabulary [not built yet]")
    p.add_argument("args", nargs="*")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotBuiltError("'slam-lcd vocab' is not built yet (issue #5)")
