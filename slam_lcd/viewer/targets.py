"""Where a recording goes: an ``.rrd`` file (written atomically), the native viewer, or the web viewer.

Why the file is built in a temporary folder beside the target and renamed into place: Rerun's
file sink writes as data is logged and adds its footer (the chunk manifest) only when the
stream closes, so a reader, or a run that fails half-way, must never find a half-written file
under the final name. Why the web viewer's data server binds loopback: ``--web`` is for a
remote or headless machine reached through an SSH tunnel; the recording is not published to the
network (the page itself is served by Rerun's web server on the port given).
"""
from __future__ import annotations

import os
import shutil
import socket
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from urllib.parse import quote

from ..errors import InputError
from ..files.atomic import check_no_clash, check_writable_target, replace_path
from ..runtime.interrupts import defer_sigint, finish
from . import APPLICATION_ID, require_rerun

RRD_SUFFIX = ".rrd"
WEB_PORT = 9090


def check_rrd_target(out: str | Path, inputs: dict) -> Path:
    """Refuse, before anything is logged, an ``.rrd`` output with another suffix, on or inside an input
    (``inputs``: what each input is -> its path), or in a place that cannot be written."""
    out = Path(out)
    if out.suffix.lower() != RRD_SUFFIX:
        raise InputError(f"a Rerun recording is a {RRD_SUFFIX} file; give a name ending in {RRD_SUFFIX}", out)
    check_no_clash({"the recording": out}, inputs)
    check_writable_target(out)
    return out


def has_display() -> bool:
    """Can a native window open here? (Linux without X11 or Wayland cannot; macOS and Windows can.)"""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


class AtomicRrd:
    """A temporary ``.rrd`` path beside ``target``; :meth:`commit` renames it into place, :meth:`discard`
    removes it (and its folder). Both are safe to call more than once."""

    def __init__(self, target: str | Path):
        self.target = Path(target)
        self.target.parent.mkdir(parents=True, exist_ok=True)
        with defer_sigint():
            self._folder: Path | None = Path(tempfile.mkdtemp(prefix=f".{self.target.name}.", dir=self.target.parent))
        self.tmp = self._folder / self.target.name

    def commit(self) -> Path:
        if self._folder is not None:
            with defer_sigint():
                replace_path(self.tmp, self.target)
            self.discard()
        return self.target

    def discard(self) -> None:
        if self._folder is not None:
            finish(shutil.rmtree, self._folder, True)
            self._folder = None


def new_stream(recording_name: str):
    rr = require_rerun()
    rec = rr.RecordingStream(APPLICATION_ID)
    rec.send_recording_name(recording_name)
    return rec


def close(rec) -> None:
    """Flush and close ``rec``: its file sink writes its footer here."""
    rec.flush()
    rec.disconnect()


def save(out: str | Path, build: Callable, blueprint, name: str) -> Path:
    """``build(rec)`` logged into ``out`` (atomically)."""
    rr = require_rerun()
    target = AtomicRrd(out)
    try:
        rec = new_stream(name)
        rec.set_sinks(rr.FileSink(target.tmp), default_blueprint=blueprint)
        build(rec)
        close(rec)
        return target.commit()
    finally:
        target.discard()


def spawn(build: Callable, blueprint, name: str) -> None:
    """``build(rec)`` streamed to a native viewer started for it (needs a display)."""
    check_display()
    rec = new_stream(name)
    rec.spawn(default_blueprint=blueprint)
    build(rec)
    close(rec)


def check_display() -> None:
    if not has_display():
        raise InputError("no display to open the native viewer on (no DISPLAY or WAYLAND_DISPLAY): use --web and "
                         "open the printed address (through an SSH tunnel), or --save OUT.rrd")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def serve_web(build: Callable, blueprint, name: str, web_port: int | None = None):
    """``build(rec)`` held by a gRPC server on loopback and the bundled web viewer on ``web_port``.

    Returns ``(recording stream, address)``: the servers live as long as the stream (and the process)."""
    rr = require_rerun()
    rec = new_stream(name)
    sink = rr.GrpcServerSink("127.0.0.1", free_port())
    rec.set_sinks(sink, default_blueprint=blueprint)
    build(rec)
    rec.flush()
    port = int(web_port or WEB_PORT)
    try:
        rr.serve_web_viewer(web_port=port, open_browser=False, connect_to=sink.uri)
    except Exception as e:  # rerun's bindings raise their own error type for a port in use
        raise InputError(f"cannot serve the web viewer on port {port} ({e}); choose another with --port") from None
    return rec, f"http://127.0.0.1:{port}/?url={quote(sink.uri, safe='')}"


def wait_for_interrupt() -> None:
    """Keep the servers up until Ctrl-C (or SIGTERM, which takes Ctrl-C's path)."""
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        return
