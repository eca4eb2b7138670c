"""`slam-lcd export`: convert a trajectory to TUM / KITTI / EuRoC / MCAP (not built yet, see issue #9)."""
from __future__ import annotations

from ..errors import NotBuiltError


def register(sub) -> None:
    p = sub.add_parser("export", help="convert a trajectory to TUM / KITTI / EuRoC / MCAP [not built yet]")
    p.add_argument("args", nargs="*")
    p.set_defaults(func=run)


def run(args) -> int:
    raise NotBuiltError("'slam-lcd export' is not built yet (issue #9)")
