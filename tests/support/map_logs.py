"""The small demo logs the map tests append: two visits of one route and a log of another world."""
from __future__ import annotations

from pathlib import Path


def visits(root: Path) -> dict[int, Path]:
    """``s1.mcap`` (session 1, 80 frames), ``s2.mcap`` (a second visit of s1's route: another seed) and
    ``s4.mcap`` (40 frames of another world), 320x240, written into ``root``."""
    from slam_lcd.sim import make_demo_log

    logs = {k: root / f"s{k}.mcap" for k in (1, 2, 4)}
    make_demo_log(logs[1], "mcap", frames=80, width=320, height=240, session=1)
    make_demo_log(logs[2], "mcap", frames=80, width=320, height=240, session=1, seed=9)
    make_demo_log(logs[4], "mcap", frames=40, width=320, height=240, session=4)
    return logs
