"""A machine with no weights and no network, for first-run tests: a closed loopback port and the environment."""
from __future__ import annotations

import os
import socket
from pathlib import Path

from support.paths import REPO


def free_port() -> int:
    """A loopback port nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def offline_env(cache: Path) -> dict:
    """Environment of a machine with no SuperPoint weights anywhere and no network: an empty
    cache, no $SLAM_LCD_SUPERPOINT_WEIGHTS, the download pointed at a closed loopback port."""
    env = {k: v for k, v in os.environ.items() if k != "SLAM_LCD_SUPERPOINT_WEIGHTS"}
    env["SLAM_LCD_CACHE_DIR"] = str(cache)
    env["SLAM_LCD_SUPERPOINT_URL"] = f"http://127.0.0.1:{free_port()}/superpoint_v1.pth"
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env
