"""`slam-lcd eval-lcd`: evaluate loop-closure detection against ground truth (not built yet, see issue #6)."""
from __future__ import annotations

from ..errors import NotBuiltError


def register(sub) -> None:
    p = sub.add_parser("eval-lcd", help="evaluate loop-closure detection against ground truth [not built yet]")
    p.add_argument("args", nargs="*")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotBuiltError("'slam-lcd eval-lcd' is not built yet (issue #6)")
