"""The built-in demo: a rendered demo-world log, cached in the user cache directory.

The log is rendered once per (frames, seed, generator version) and reused: rendering is
deterministic (same seed → identical bytes), so a cached file is exactly what a fresh
render would give.
"""
from __future__ import annotations

from pathlib import Path

from . import __version__


def demo_log_path(frames: int | None = None, seed: int = 0, width: int = 640, height: int = 480) -> Path:
    from .features.weights import cache_dir

    size = "" if (width, height) == (640, 480) else f"-{width}x{height}"
    tag = f"{'laps2' if frames is None else f'f{frames}'}-seed{seed}{size}-v{__version__}"
    return cache_dir() / "demo" / f"demo-{tag}.mcap"


def ensure_demo_log(frames: int | None = None, seed: int = 0, rebuild: bool = False, progress: bool = True,
                    width: int = 640, height: int = 480) -> Path:
    """Path of the demo log (RGB-D camera, odometry, ground truth), rendering it if not cached."""
    from .sim import make_demo_log

    path = demo_log_path(frames, seed, width, height)
    if rebuild or not path.exists():
        make_demo_log(path, "mcap", frames=frames, seed=seed, depth=True, progress=progress, width=width,
                      height=height)
    return path
