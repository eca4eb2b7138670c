"""The built-in demo: a rendered demo-world log, cached in the user cache directory.

The log is rendered once per (frames, seed, generator version) and reused: rendering is
deterministic (same seed → identical bytes), so a cached file is exactly what a fresh
render would give.
"""
from __future__ import annotations

from pathlib import Path

from ..features.weights import cache_dir
from ..version import __version__
from . import make_demo_log


def demo_log_path(frames: int | None = None, seed: int = 0, width: int = 640, height: int = 480,
                  session: int | None = None) -> Path:
    size = "" if (width, height) == (640, 480) else f"-{width}x{height}"
    route = f"session{session}" if session is not None else ("laps2" if frames is None else "")
    frames_tag = "" if frames is None else f"f{frames}"
    tag = f"{route}{'-' if route and frames_tag else ''}{frames_tag}-seed{seed}{size}-v{__version__}"
    return cache_dir() / "demo" / f"demo-{tag}.mcap"


def ensure_demo_log(frames: int | None = None, seed: int = 0, rebuild: bool = False, progress: bool = True,
                    width: int = 640, height: int = 480, session: int | None = None) -> Path:
    """Path of the demo log (RGB-D camera, odometry, ground truth), rendering it if not cached.

    ``session``: one of the demo world's session presets (``make-demo-log --session K``) instead
    of the two laps; its own seed then (``seed`` is ignored).
    """
    path = demo_log_path(frames, seed if session is None else 0, width, height, session)
    if rebuild or not path.exists():
        make_demo_log(path, "mcap", frames=frames, depth=True, progress=progress, width=width,
                      height=height, session=session, seed=seed if session is None else None)
    return path
